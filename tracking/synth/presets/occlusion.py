"""Occlusion scenes (OCCLUSION, issue 30): a hand or an object between the camera and a virtual model,
with depth and ground-truth masks (tracking.synth.occlusion)."""

from __future__ import annotations

import copy

# Occlusion (issue 30): a hand or an object passing between the camera and a virtual model standing on the
# marker, with a stereo depth camera's depth and ground-truth masks (tracking.synth.occlusion). Rendered on
# demand and cached (tests/test_occlusion.py, benchmarks/bench_occlusion.py), not bundled. The depth
# occlusion's parameters (arapp.render.occlusion.OcclusionParams) were chosen on the tuning ones (scene
# 341-342, desk 441-442); the test ones (scene 141-142, desk 241-242) are only measured.
def _occlusion(name: str, seed: int, desk_seed: int, kind: str, marker_id: int, azimuth: tuple[float, float],
               distance: float, elevation: float, model: list[float], fraction: float, sweep: float,
               width: int = 640, height: int = 480, duration: float = 2.0, fps: float = 15.0) -> dict:
    return {
        "name": name, "seed": seed, "fps": fps, "duration": duration,
        "camera": {"width": width, "height": height, "hfov_deg": 62, "dist": [-0.06, 0.03, 0.0003, -0.0003, 0.0]},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": marker_id, "length": 0.06}],
        "desk": {"size": [1.6, 1.3], "ppm": 1500, "seed": desk_seed},
        "trajectory": {"kind": "orbit", "azimuth_start": azimuth[0], "azimuth_end": azimuth[1],
                       "distance": distance, "elevation": elevation,
                       "shake": {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.5}},
        "effects": {"noise": 0.8},
        "video": {"fourcc": "MJPG", "quality": 85},
        "supersample": 1,
        "occlusion": {"model": {"size": model, "offset": [0.0, 0.0]},
                      "occluder": {"kind": kind, "start": 0.1 * duration, "end": 0.9 * duration,
                                   "fraction": fraction, "sweep": sweep},
                      "depth": {}},
    }


OCCLUSION: dict[str, dict] = {
    "tune_occlusion_hand": _occlusion("tune_occlusion_hand", 341, 441, "hand", 3, (-110, -80), 0.5, 50,
                                      [0.06, 0.05, 0.09], 0.3, 0.16),
    "tune_occlusion_object": _occlusion("tune_occlusion_object", 342, 442, "object", 4, (-75, -100), 0.48, 45,
                                        [0.05, 0.06, 0.08], 0.35, 0.12),
    "test_occlusion_hand": _occlusion("test_occlusion_hand", 141, 241, "hand", 5, (-95, -70), 0.52, 55,
                                      [0.07, 0.05, 0.08], 0.32, 0.17),
    "test_occlusion_object": _occlusion("test_occlusion_object", 142, 242, "object", 6, (-85, -115), 0.46, 48,
                                        [0.05, 0.05, 0.1], 0.4, 0.12),
}
OCCLUSION_TUNING = [n for n in OCCLUSION if n.startswith("tune_")]
OCCLUSION_TEST = [n for n in OCCLUSION if n.startswith("test_")]


def occlusion_scene(name: str, width: int | None = None, height: int | None = None,
                    duration: float | None = None) -> dict:
    """A copy of occlusion preset `name`, optionally smaller or shorter (tests render 320x240 in a second)."""
    data = copy.deepcopy(OCCLUSION[name])
    if width is not None:
        scale = int(width) / data["camera"]["width"]
        data["camera"]["width"], data["camera"]["height"] = int(width), int(height)
        data["desk"]["ppm"] = round(data["desk"]["ppm"] * min(1.0, scale * 1.2))  # the texture as fine as seen
    if duration is not None:
        data["duration"] = float(duration)
        data["occlusion"]["occluder"]["start"] = 0.1 * duration
        data["occlusion"]["occluder"]["end"] = 0.9 * duration
    return data
