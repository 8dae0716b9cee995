"""Building blocks of the preset tables: the GridBoard and lens distortion most presets share, a cheap
webcam's effects and the fast-pan tuning twin's scene."""

from __future__ import annotations

BOARD = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
         "marker_length": 0.04, "separation": 0.01, "first_id": 0}
MILD_DIST = [-0.08, 0.04, 0.0005, -0.0005, 0.0]


# What a cheap USB webcam does (camera_effects.py): ~2000-4000 e- full well, rolling shutter read out in
# ~20-30 ms, auto-exposure and auto white balance that drift, YUYV link, MJPEG at a varying quality.
def webcam_effects(**kw) -> dict:
    fx = {"sensor": {"full_well": 3000, "read_noise": 1.5}, "rolling_shutter": 0.025,
          "auto_exposure": {"target": 115, "speed": 0.15, "initial_gain": 1.0},
          "white_balance": {"amplitude": 0.04, "period": 3.5}, "defocus": 0.6, "vignette": 0.2,
          "chroma_422": True, "jpeg_quality": [70, 90]}
    fx.update(kw)
    return fx


# Tuning twins of the test recordings: the same kinds of webcam effects and motions, from other seeds
# (scene 301-307, desk 401-407) and other geometry. They are tuning data: looked at freely while
# choosing parameters, so that the test recordings above never have to be.
def fast_pan_twin(name: str, seed: int, desk_seed: int, hfov_deg: float, dist: list[float],
                   board: tuple[int, int, float, float, int], pan: dict) -> dict:
    """A fast-pan tuning twin: 2 s at 30 fps, 640x480, over a GridBoard of DICT_4X4_50 markers
    (markers_x, markers_y, marker_length m, separation m, first_id), on a 2 m x 1.6 m desk; webcam effects
    with motion blur over 60 % of the frame interval and a 30 ms rolling shutter. `pan`: the trajectory's
    pan parameters (trajectory.py)."""
    nx, ny, length, sep, first = board
    return {
        "name": name, "seed": seed, "fps": 30, "duration": 2.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": hfov_deg, "dist": dist},
        "anchors": [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": nx, "markers_y": ny,
                     "marker_length": length, "separation": sep, "first_id": first}],
        "desk": {"size": [2.0, 1.6], "ppm": 1600, "seed": desk_seed},
        "trajectory": {"kind": "pan", **pan},
        "effects": webcam_effects(motion_blur=0.6, blur_samples=7, rolling_shutter=0.03),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    }
