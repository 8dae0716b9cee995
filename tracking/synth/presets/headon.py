"""A small marker seen nearly head-on (HEADON, issue 25.4): tuning and test scenes for the planar-ambiguity
flip."""

from __future__ import annotations

import numpy as np

from tracking.synth.presets.parts import webcam_effects
from tracking.synth.trajectory import look_at

# A small marker seen nearly head-on over a textured desk (issue 25.4, the planar-ambiguity flip): a 3 cm
# marker at ~0.7 m, the camera held by hand 2-6 degrees off the marker's normal (a person at the desk's near
# side looking down at it), drifting a centimetre or two between keys, with a hand's tremor and webcam effects.
# Rendered on demand and cached (tests/scenes.py `held_recording_folder`), not bundled. Tuning ones (scene
# 341-342 and 353-355, desk 441-442 and 453-455) may be looked at; the test one (scene 141, desk 241) is only
# measured.
def _headon_keys(seed: int, duration: float, distance: float) -> list[dict]:
    """Camera keys over `duration` s: the eye 5-8 cm toward the desk's near side and up to 2 cm sideways of
    the marker (at the origin), `distance` m above the desk (+-2 cm), looking at a point within 2 cm of the
    marker, the image's x axis within a few degrees of the desk's (a hand does not spin the camera about
    its axis: look_at alone would, with the view this close to the desk's normal); a new key every ~0.6 s.
    Repeatable for a seed."""
    rng = np.random.default_rng(seed + 2525)
    keys, t = [], 0.0
    rolls = np.radians(np.arange(-180.0, 180.0, 0.25))
    while True:
        eye = [rng.uniform(-0.02, 0.02), rng.uniform(-0.08, -0.05), distance + rng.uniform(-0.02, 0.02)]
        target = [rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), 0.0]
        x0 = look_at(eye, target)[:3, :3]
        yaw = np.radians(rng.uniform(-4.0, 4.0))   # the image x axis's wanted direction on the desk
        xs = np.cos(rolls)[:, None] * x0[:, 0] + np.sin(rolls)[:, None] * x0[:, 1]
        roll = float(np.degrees(rolls[np.argmax(xs[:, 0] * np.cos(yaw) + xs[:, 1] * np.sin(yaw))]))
        keys.append({"t": round(t, 3), "eye": [round(v, 4) for v in eye], "target": [round(v, 4) for v in target],
                     "roll": round(roll, 2)})
        if t >= duration:
            return keys
        t = min(t + rng.uniform(0.5, 0.7), duration)


def _headon(name: str, seed: int, desk_seed: int, marker_id: int, hfov_deg: float, dist: list[float],
            length: float = 0.03, distance: float = 0.70, duration: float = 3.0) -> dict:
    """A head-on scene: 640x480 at 30 fps, one DICT_4X4_50 marker `length` m wide at the desk's origin,
    the camera ~`distance` m above it (_headon_keys) with a hand's tremor, webcam effects (25 ms rolling
    shutter, MJPEG)."""
    return {
        "name": name, "seed": seed, "fps": 30, "duration": duration,
        "camera": {"width": 640, "height": 480, "hfov_deg": hfov_deg, "dist": dist},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": marker_id, "length": length}],
        "desk": {"size": [1.6, 1.3], "ppm": 1600, "seed": desk_seed},
        "trajectory": {"kind": "keyframes", "keys": _headon_keys(seed, duration, distance),
                       "shake": {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.6}},
        "effects": webcam_effects(),
        "video": {"fourcc": "MJPG", "quality": 80},
        "supersample": 2,
    }


HEADON: dict[str, dict] = {
    "tune_headon": _headon("tune_headon", 341, 441, 8, hfov_deg=62, dist=[-0.07, 0.035, 0.0003, -0.0003, 0.0]),
    "tune_headon_b": _headon("tune_headon_b", 342, 442, 21, hfov_deg=60, dist=[-0.06, 0.03, -0.0004, 0.0002, 0.0],
                             length=0.032, distance=0.68),
    "tune_headon_c": _headon("tune_headon_c", 353, 453, 30, hfov_deg=61, dist=[-0.068, 0.032, -0.0002, -0.0002, 0.0],
                             length=0.031, distance=0.69),
    "tune_headon_d": _headon("tune_headon_d", 354, 454, 3, hfov_deg=63, dist=[-0.062, 0.028, 0.0003, 0.0001, 0.0],
                             length=0.029, distance=0.72),
    "tune_headon_e": _headon("tune_headon_e", 355, 455, 42, hfov_deg=59, dist=[-0.072, 0.036, -0.0001, 0.0003, 0.0],
                             length=0.031, distance=0.70),
    "test_headon": _headon("test_headon", 141, 241, 14, hfov_deg=61, dist=[-0.065, 0.03, 0.0002, 0.0004, 0.0],
                           distance=0.71),
}
HEADON_TUNING = [n for n in HEADON if not n.startswith("test_")]
HEADON_TEST = [n for n in HEADON if n.startswith("test_")]
