"""Camera trajectories over a desk: orbit, static, approach, pan, keyframes, plus hand-held shake.

Trajectories are built in desk coordinates (metres; x right, y away from the
default viewer, z up out of the desk) relative to the scene centre, and
returned as functions `t -> desk_from_camera` (4x4, OpenCV camera axes).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from tracking.errors import SessionError
from tracking.poses import make_pose

PoseFn = Callable[[float], np.ndarray]


def look_at(eye, target, roll_rad: float = 0.0) -> np.ndarray:
    """desk_from_camera for a camera at `eye` looking at `target` (desk coordinates).

    Image x is kept parallel to the desk (cross of view direction and desk up),
    so the desk's far side is at the top of the image; `roll_rad` turns the
    camera about its optical axis.
    """
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:  # looking straight down: keep desk x as image x
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    if roll_rad:
        R = R @ Rotation.from_rotvec([0.0, 0.0, roll_rad]).as_matrix()
    return make_pose(R, eye)


def _smoothstep(s):
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def _eye_from_polar(azimuth_deg: float, distance: float, elevation_deg: float) -> np.ndarray:
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _get(spec: dict, key: str, default=None, where: str = "trajectory"):
    if key in spec:
        v = spec[key]
        if isinstance(default, (int, float)) and not isinstance(v, (int, float)):
            raise SessionError(f"{where}.{key}: must be a number, got {v!r}")
        return v
    if default is None:
        raise SessionError(f"{where}.{key}: missing")
    return default


def make_trajectory(spec: dict, duration: float, seed: int = 0, where: str = "trajectory") -> PoseFn:
    """`t -> desk_from_camera` relative to the scene centre for a trajectory block.

    kinds (angles in degrees, lengths in metres, azimuth 0 = +x, -90 = the near side):
      static:    azimuth, distance, elevation
      orbit:     azimuth_start, azimuth_end, distance, elevation, elevation_swing
      approach:  azimuth, elevation, distance_start, distance_end
      pan:       azimuth, distance, elevation, pan_deg (half sweep), cycles (back-and-forth sweeps)
      leave_view: azimuth, distance, elevation, away [dx, dy] (where the view turns to), leave_at,
                 back_at, ramp (seconds): the anchors leave the view and come back
      keyframes: keys = [{"t", "eye": [x, y, z], "target": [x, y, z], "roll": deg}], spline-interpolated
    Any kind takes `shake`: {"pos_mm", "rot_deg", "freq_hz"} for hand-held tremor.
    """
    if not isinstance(spec, dict) or "kind" not in spec:
        raise SessionError(f"{where}: must be an object with a kind (static, orbit, approach, pan, leave_view, "
                          "keyframes)")
    kind = spec["kind"]
    g = lambda k, d=None: _get(spec, k, d, where)  # noqa: E731
    target0 = np.asarray(spec.get("target", [0.0, 0.0, 0.0]), float)
    if not isinstance(kind, str) or kind not in _KINDS:
        raise SessionError(f"{where}.kind: must be static, orbit, approach, pan, leave_view or keyframes, "
                          f"got {kind!r}")
    base = _KINDS[kind](g, target0, duration, where)

    shake = spec.get("shake")
    return _with_shake(base, shake, seed) if shake else base


# Each kind's path: (g: a field of the block by name and default, checked; the point looked at; the duration s;
# where, for errors) -> t -> desk_from_camera.

def _static(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    eye = _eye_from_polar(g("azimuth", -90.0), g("distance", 0.5), g("elevation", 60.0)) + target0
    return lambda t: look_at(eye, target0)


def _orbit(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    a0, a1 = g("azimuth_start", -130.0), g("azimuth_end", -50.0)
    d, el, swing = g("distance", 0.5), g("elevation", 55.0), g("elevation_swing", 0.0)

    def base(t):
        s = t / duration
        eye = _eye_from_polar(a0 + (a1 - a0) * s, d, el + swing * np.sin(2 * np.pi * s)) + target0
        return look_at(eye, target0)
    return base


def _approach(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    az, el = g("azimuth", -90.0), g("elevation", 60.0)
    d0, d1 = g("distance_start", 0.7), g("distance_end", 0.25)

    def base(t):
        d = d0 + (d1 - d0) * _smoothstep(t / duration)
        return look_at(_eye_from_polar(az, d, el) + target0, target0)
    return base


def _pan(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    eye = _eye_from_polar(g("azimuth", -90.0), g("distance", 0.5), g("elevation", 60.0)) + target0
    half, cycles = np.radians(g("pan_deg", 30.0)), g("cycles", 1.0)
    right = np.array([1.0, 0.0, 0.0])

    def base(t):
        ang = half * np.sin(2 * np.pi * cycles * t / duration)
        dist = np.linalg.norm(target0 - eye)
        return look_at(eye, target0 + right * dist * np.tan(ang))
    return base


def _leave_view(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    eye0 = _eye_from_polar(g("azimuth", -90.0), g("distance", 0.45), g("elevation", 60.0)) + target0
    away = np.array(list(g("away", [0.45, 0.1])) + [0.0], float)
    t_leave, t_back, ramp = g("leave_at", 1.0), g("back_at", 3.0), g("ramp", 0.6)

    def base(t):
        # 0 -> 1 over `ramp` seconds from leave_at, back to 0 over `ramp` seconds before back_at
        w = _smoothstep((t - t_leave) / ramp) * (1.0 - _smoothstep((t - (t_back - ramp)) / ramp))
        return look_at(eye0 + 0.4 * w * away, target0 + w * away)
    return base


def _keyframe_path(g, target0: np.ndarray, duration: float, where: str) -> PoseFn:
    return _keyframes(g("keys"), where)


_KINDS = {"static": _static, "orbit": _orbit, "approach": _approach, "pan": _pan, "leave_view": _leave_view,
          "keyframes": _keyframe_path}


def _keyframes(keys, where: str) -> PoseFn:
    """Clamped cubic splines through the keys' eye, target and roll (held at the first and last key)."""
    if not isinstance(keys, list) or len(keys) < 2:
        raise SessionError(f"{where}.keys: need at least two keyframes {{t, eye, target}}")
    try:
        ts = np.array([k["t"] for k in keys], float)
        eyes = np.array([k["eye"] for k in keys], float)
        targets = np.array([k.get("target", [0, 0, 0]) for k in keys], float)
        rolls = np.radians([k.get("roll", 0.0) for k in keys])
    except (KeyError, TypeError, ValueError) as e:
        raise SessionError(f"{where}.keys: each key needs t, eye [x,y,z] and optional target, roll ({e})") from None
    if np.any(np.diff(ts) <= 0):
        raise SessionError(f"{where}.keys: times must increase")
    se = CubicSpline(ts, eyes, bc_type="clamped")
    st = CubicSpline(ts, targets, bc_type="clamped")
    sr = CubicSpline(ts, rolls, bc_type="clamped")

    def base(t):
        tc = float(np.clip(t, ts[0], ts[-1]))
        return look_at(se(tc), st(tc), float(sr(tc)))

    return base


def _with_shake(base: PoseFn, shake: dict, seed: int) -> PoseFn:
    """`base` followed by hand-held tremor: {"pos_mm", "rot_deg", "freq_hz"}, repeatable for a seed."""
    rng = np.random.default_rng(seed + 7919)
    pos_amp = float(shake.get("pos_mm", 2.0)) / 1000.0
    rot_amp = np.radians(float(shake.get("rot_deg", 0.5)))
    f0 = float(shake.get("freq_hz", 2.0))
    # Three incommensurate sinusoids per axis: smooth, band-limited tremor, repeatable for a seed.
    freqs = f0 * rng.uniform(0.4, 1.6, (6, 3))
    phases = rng.uniform(0, 2 * np.pi, (6, 3))
    amps = rng.uniform(0.5, 1.0, (6, 3)) / 1.8

    def shaken(t):
        w = (amps * np.sin(2 * np.pi * freqs * t + phases)).sum(axis=1)
        delta = make_pose(Rotation.from_rotvec(w[3:] * rot_amp).as_matrix(), w[:3] * pos_amp)
        return base(t) @ delta

    return shaken
