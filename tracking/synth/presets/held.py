"""Cards held before a camera (HELD, issue 25): tuning and test scenes for tracking.synth.held."""

from __future__ import annotations

import numpy as np

from tracking.synth.presets.parts import webcam_effects

# Cards held before a camera (tracking.synth.held, issue 25): the anchors on a textured card moved by hand
# in front of a textured wall, seen by a still webcam (a laptop's) or by a moving camera too ("both").
# Rendered on demand and cached (tests/scenes.py `held_recording`), not bundled. Tuning ones (scene
# 331-338, desk 431-438, wall 531-538) may be looked at; test ones (scene 131-134, desk 231-234, wall
# 251-254) are only measured.
def _held_keys(seed: int, swings: list[tuple[float, float, list[float], list[float]]],
               duration: float, drift_mm: float = 60.0, rest: tuple[float, float] | None = None) -> list[dict]:
    """Card keys (tracking.synth.held) over `duration` s: the card starts still at the room origin facing
    the camera, drifts slowly (a few cm a second: readable) between swings, each swing (start s,
    length s, centre shift [x, y, z] m, rotation vector [deg]) a fast move past reading to a new place;
    a hand's tremor of ~2 mm on every key. `rest` (from s, to s): the card is put down and lies still
    then (no drift). Repeatable for a seed."""
    rng = np.random.default_rng(seed + 4242)
    keys, centre, rot, t = [], np.zeros(3), np.zeros(3), 0.0
    keys.append({"t": 0.0, "centre": [0.0, 0.0, 0.0], "rot": [0.0, 0.0, 0.0]})
    # still at first (the room's map is built while the card lies still), then slow drifts and swings
    events = sorted(swings) + [(duration, 0.0, None, None)]
    t = 0.7
    keys.append({"t": t, "centre": centre.tolist(), "rot": rot.tolist()})
    for start, length, shift, turn in events:
        # slow drift up to the swing: about drift_mm/s, along a random direction in the card's plane
        while start - t > 0.45:
            t += 0.4
            d = rng.normal(0, 1, 3) * [1.0, 0.3, 1.0]
            wobble = rng.normal(0, 2.5, 3)
            if not (rest is not None and rest[0] <= t <= rest[1] + 0.4):
                centre = centre + d / np.linalg.norm(d) * drift_mm * 0.4 / 1000
                rot = rot + wobble
            # (lying still: the same place keyed every 0.4 s, so the spline holds it there)
            keys.append({"t": round(t, 3), "centre": [round(float(v), 5) for v in centre],
                         "rot": [round(float(v), 3) for v in rot]})
        if shift is None:
            break
        t = start
        keys.append({"t": round(t, 3), "centre": [round(float(v), 5) for v in centre],
                     "rot": [round(float(v), 3) for v in rot]})
        centre, rot = centre + np.asarray(shift, float), rot + np.asarray(turn, float)
        t = start + length
        tremor = rng.normal(0, 0.002, 3)
        keys.append({"t": round(t, 3), "centre": [round(float(v), 5) for v in centre + tremor],
                     "rot": [round(float(v), 3) for v in rot]})
    if keys[-1]["t"] < duration:
        keys.append({"t": duration, "centre": keys[-1]["centre"], "rot": keys[-1]["rot"]})
    return keys


def _held(name: str, seed: int, desk_seed: int, wall_seed: int, anchor: dict, card: tuple[float, float],
          swings: list, camera: dict, hfov_deg: float = 62.0, dist: list[float] | None = None,
          duration: float = 4.0, rest: tuple[float, float] | None = None, drift_mm: float = 60.0) -> dict:
    """A held-card scene: 640x480 at 30 fps, `anchor` on a `card` (width, height m) card held before the
    camera (`camera`: the trajectory block, room frame), webcam effects with motion blur over 60 % of the
    frame interval (global shutter), a wall 0.8 m behind the card; `drift_mm`: the card's slow drift, mm/s."""
    return {
        "name": name, "seed": seed, "fps": 30, "duration": duration,
        "camera": {"width": 640, "height": 480, "hfov_deg": hfov_deg, "dist": dist or [-0.06, 0.03, 0.0, 0.0, 0.0]},
        "anchors": [anchor],
        "desk": {"size": list(card), "ppm": 2000, "seed": desk_seed},
        "trajectory": camera,
        "effects": webcam_effects(motion_blur=0.6, blur_samples=9, rolling_shutter=0.0),
        "video": {"fourcc": "MJPG", "quality": 80},
        "supersample": 2,
        "held": {"wall": {"distance": 0.8, "size": [3.2, 2.6], "ppm": 450, "seed": wall_seed},
                 "keys": _held_keys(seed, swings, duration, drift_mm=drift_mm, rest=rest)},
    }


def _webcam_still(azimuth: float = -90.0, distance: float = 0.45, elevation: float = 4.0) -> dict:
    """A webcam on a laptop's lid: still, facing the card's rest place at the room origin."""
    return {"kind": "static", "azimuth": azimuth, "distance": distance, "elevation": elevation}


def _hand_camera(seed: int, dx: float = 0.12) -> dict:
    """A hand-held camera moving sideways by `dx` m and back while looking at the card's rest place."""
    return {"kind": "keyframes", "keys": [
        {"t": 0.0, "eye": [-dx / 2, -0.46, 0.04], "target": [0.0, 0.0, 0.0]},
        {"t": 2.0, "eye": [dx / 2, -0.43, 0.07], "target": [0.01, 0.0, 0.01]},
        {"t": 4.0, "eye": [-dx / 4, -0.47, 0.03], "target": [0.0, 0.0, 0.0]}],
        "shake": {"pos_mm": 2.0, "rot_deg": 0.35, "freq_hz": 2.0}}


def _board(nx, ny, length, sep, first, dictionary="DICT_4X4_50") -> dict:
    return {"kind": "aruco_board", "dictionary": dictionary, "markers_x": nx, "markers_y": ny,
            "marker_length": length, "separation": sep, "first_id": first}


HELD: dict[str, dict] = {
    # a 4x3 board card waved before a still webcam: two fast swings past reading
    "tune_held_board": _held("tune_held_board", 331, 431, 531, _board(4, 3, 0.035, 0.008, 0), (0.23, 0.18),
                             [(1.5, 0.25, [-0.16, 0.01, -0.05], [0, 10, 8]), (2.7, 0.22, [0.14, 0.0, 0.06], [5, -12, -6])],
                             _webcam_still()),
    # a single 6 cm marker card before a still webcam
    "tune_held_marker": _held("tune_held_marker", 332, 432, 532,
                              {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 9, "length": 0.06}, (0.12, 0.12),
                              [(1.4, 0.22, [0.15, 0.0, 0.04], [-8, 6, 0]), (2.6, 0.25, [-0.12, 0.01, -0.06], [6, -8, 5])],
                              _webcam_still(distance=0.42)),
    # both move: a hand-held camera and a hand-held board card
    "tune_held_both": _held("tune_held_both", 333, 433, 533, _board(4, 3, 0.034, 0.008, 12), (0.22, 0.17),
                            [(1.6, 0.25, [0.15, 0.0, 0.04], [0, -10, 6]), (2.8, 0.22, [-0.13, 0.01, -0.05], [-6, 10, 0])],
                            _hand_camera(333)),
    "test_held_board": _held("test_held_board", 131, 231, 251, _board(4, 3, 0.036, 0.008, 20), (0.24, 0.19),
                             [(1.6, 0.22, [0.15, -0.01, 0.05], [-4, -10, 6]), (2.8, 0.25, [-0.15, 0.01, -0.04], [0, 12, -8])],
                             _webcam_still(azimuth=-92, distance=0.46, elevation=5), hfov_deg=61),
    "test_held_marker": _held("test_held_marker", 132, 232, 252,
                              {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 17, "length": 0.065},
                              (0.13, 0.12),
                              [(1.5, 0.25, [-0.14, 0.0, 0.05], [6, 8, 0]), (2.7, 0.22, [0.13, 0.01, -0.05], [-5, -8, 5])],
                              _webcam_still(azimuth=-88, distance=0.43, elevation=3), hfov_deg=63),
    "test_held_both": _held("test_held_both", 133, 233, 253, _board(4, 3, 0.035, 0.008, 30), (0.23, 0.18),
                            [(1.5, 0.22, [-0.14, 0.01, 0.05], [4, 10, -6]), (2.7, 0.25, [0.15, 0.0, -0.04], [-4, -10, 6])],
                            _hand_camera(133, dx=0.14), hfov_deg=62),
    # both move, and the board card is put down for ~2.5 s between its swings while the hand-held camera
    # goes on moving (the map may come back, and must go again at the second swing)
    "tune_held_rest": _held("tune_held_rest", 334, 434, 534, _board(4, 3, 0.034, 0.008, 36), (0.22, 0.17),
                            [(1.2, 0.22, [0.13, 0.0, 0.04], [-6, 8, 0]), (4.3, 0.25, [-0.12, 0.01, -0.05], [5, -8, 4])],
                            _hand_camera(334), duration=5.2, rest=(1.5, 4.2)),
    "test_held_rest": _held("test_held_rest", 134, 234, 254, _board(4, 3, 0.035, 0.008, 4), (0.23, 0.18),
                            [(1.3, 0.25, [-0.13, 0.01, 0.05], [5, 7, 0]), (4.4, 0.22, [0.12, 0.0, -0.04], [-4, -8, 5])],
                            _hand_camera(134, dx=0.13), hfov_deg=62, duration=5.3, rest=(1.6, 4.3)),
    # more of the card put down between swings (issue 25.2), tuning only: the board drifts only about half a
    # second before its first swing while the hand-held camera moves (_b), drifts slower while the camera
    # moves wider (_c), drifts slower still (_d), or half a second
    # slowly (_e)
    "tune_held_rest_b": _held("tune_held_rest_b", 335, 435, 535, _board(4, 3, 0.035, 0.008, 16), (0.23, 0.18),
                              [(1.3, 0.24, [0.12, 0.0, 0.05], [-5, 7, 3]), (4.4, 0.23, [-0.13, 0.01, -0.04], [4, -9, 0])],
                              _hand_camera(335, dx=0.13), hfov_deg=61, duration=5.3, rest=(1.6, 4.3)),
    "tune_held_rest_c": _held("tune_held_rest_c", 336, 436, 536, _board(4, 3, 0.034, 0.008, 24), (0.22, 0.17),
                              [(1.25, 0.22, [-0.14, 0.01, -0.04], [6, -7, 0]), (4.3, 0.25, [0.12, 0.0, 0.05], [-5, 8, -4])],
                              _hand_camera(336, dx=0.15), hfov_deg=63, duration=5.2, rest=(1.55, 4.2), drift_mm=45.0),
    "tune_held_rest_d": _held("tune_held_rest_d", 337, 437, 537, _board(4, 3, 0.035, 0.008, 0), (0.23, 0.18),
                              [(1.3, 0.25, [0.13, -0.01, 0.05], [4, 8, -5]), (4.3, 0.22, [-0.12, 0.01, -0.05], [-6, -7, 4])],
                              _hand_camera(337, dx=0.11), hfov_deg=62, duration=5.2, rest=(1.6, 4.2), drift_mm=35.0),
    "tune_held_rest_e": _held("tune_held_rest_e", 338, 438, 538, _board(4, 3, 0.034, 0.008, 30), (0.22, 0.18),
                              [(1.2, 0.23, [-0.12, 0.0, 0.05], [-4, -8, 6]), (4.2, 0.24, [0.13, -0.01, -0.04], [5, 7, -3])],
                              _hand_camera(338, dx=0.14), hfov_deg=60, duration=5.1, rest=(1.5, 4.1), drift_mm=40.0),
}
HELD_TUNING = [n for n in HELD if not n.startswith("test_")]
HELD_TEST = [n for n in HELD if n.startswith("test_")]
