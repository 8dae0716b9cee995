"""The desk's reference pose refined over several frames at once (issue 25.4, desk.DeskPlane).

One pair of frames (the reference and one later frame) fixes the marker's tilt only as well as that pair's
flow shows the desk plane's normal: with a hand's few centimetres of baseline, a third to half a degree.
Several frames spread over the camera's path see it from several baselines, with their own noise: the
reference pose fitted to all of them at once (each frame's pose free too) averages it.

Frames ("keys") are packed into arrays: `Keys.xr` (M,2) the desk points' normalised coordinates in the
reference, `xc` (M,2) in the key frame, `key` (M,) which key each point belongs to, `world` (K,4,3) the
marker's corners (metres) and `corners` (K,4,2) their normalised coordinates in each key. Pose vectors as in
desk_geometry; residuals in standard deviations (normalised coordinates times `f / px` for a pixel noise).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from tracking.anchors.desk_geometry import lift, project, rot


@dataclass
class Keys:
    """Kept frames packed for the bundle (module docstring)."""

    xr: np.ndarray
    xc: np.ndarray
    key: np.ndarray
    world: np.ndarray
    corners: np.ndarray

    @staticmethod
    def pack(frames: list[tuple]) -> Keys:
        """Keys from [(xr (N,2), xc (N,2), (world (4,3), corners (4,2))), ...]."""
        return Keys(np.concatenate([k[0] for k in frames]), np.concatenate([k[1] for k in frames]),
                    np.concatenate([np.full(len(k[0]), i) for i, k in enumerate(frames)]),
                    np.array([k[2][0] for k in frames], float), np.array([k[2][1] for k in frames], float))


def residuals(p: np.ndarray, ref_marker: tuple, keys: Keys, marker_scale: float, desk_scale) -> np.ndarray:
    """Residuals of the reference pose p[:6] and the keys' poses (6 each after it): the marker's corners in
    the reference (`ref_marker`: world (4,3), normalised (4,2)) and in every key (times `marker_scale`), every
    key's desk points lifted onto z = 0 from the reference and projected into the key (times `desk_scale`, a
    number or one per point, (M,1)).
    Laid out [reference corners (8), keys' corners (8 each), desk points (2 each)]."""
    Rr, tr = rot(p[:6])
    n = len(keys.world)
    Rs = np.array([cv2.Rodrigues(np.asarray(p[6 + 6 * i:9 + 6 * i], np.float64).reshape(3, 1))[0] for i in range(n)])
    ts = p[6:].reshape(n, 6)[:, 3:]
    out = [((project(Rr, tr, ref_marker[0]) - ref_marker[1]) * marker_scale).ravel()]
    W = np.einsum("kij,knj->kni", Rs, keys.world) + ts[:, None, :]
    out.append(((W[..., :2] / W[..., 2:3] - keys.corners) * marker_scale).ravel())
    X = lift(Rr, tr, keys.xr)
    Xc = np.einsum("mij,mj->mi", Rs[keys.key], X) + ts[keys.key]
    out.append(((Xc[:, :2] / Xc[:, 2:3] - keys.xc) * desk_scale).ravel())
    return np.concatenate(out)


def _row_keys(keys: Keys) -> np.ndarray:
    """Which key each residual row belongs to (-1: the reference's corners)."""
    n = len(keys.world)
    return np.concatenate([np.full(8, -1), np.repeat(np.arange(n), 8), np.repeat(keys.key, 2)])


def jacobian(fun, p: np.ndarray, rows: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """Forward-difference Jacobian of `fun` at p in 12 evaluations: a key's parameters move only its own rows
    (`rows`: each row's key, -1 for none), so one step moves the same parameter of every key at once."""
    r0 = fun(p)
    J = np.zeros((len(r0), len(p)))
    n = (len(p) - 6) // 6
    cols = 6 + 6 * np.arange(n)
    mine = rows >= 0
    for j in range(6):
        q = p.copy()
        q[j] += step
        J[:, j] = (fun(q) - r0) / step
        q = p.copy()
        q[cols + j] += step
        J[np.flatnonzero(mine), 6 + 6 * rows[mine] + j] = ((fun(q) - r0) / step)[mine]
    return J


def _solve(fun, start: np.ndarray, rows: np.ndarray, max_nfev: int):
    """Levenberg-Marquardt on `fun` from `start` with `jacobian`: the solution, or None when it fails."""
    try:
        return least_squares(fun, start, jac=lambda q: jacobian(fun, q, rows), method="lm", x_scale="jac",
                             max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError):
        return None


def refine(start: np.ndarray, ref_marker: tuple, keys: Keys, marker_scale: float, desk_scale: float,
           max_nfev: int = 10) -> tuple[np.ndarray, float] | None:
    """The reference and keys' poses (start: [reference, key 0, key 1, ...]) fitted to `residuals` by
    Levenberg-Marquardt: (parameters, the reference rotation's largest standard deviation in radians), or
    None when the fit fails. Twice: the second time each key's desk points count by that key's own residual
    after the first (a frame whose points are noisier than `desk_scale` says, from a coarser JPEG or a
    faster hand, and often off by a pattern of their own, counts for less)."""
    rows = _row_keys(keys)
    n = len(keys.world)
    scale = np.full((len(keys.xr), 1), float(desk_scale))
    r = None
    for first in (True, False):
        r = _solve(lambda q: residuals(q, ref_marker, keys, marker_scale, scale), start if r is None else r.x,
                   rows, max_nfev)
        if r is None:
            return None
        if first:
            d2 = (r.fun[8 + 8 * n:].reshape(-1, 2) ** 2).sum(axis=1)
            rms = np.sqrt(np.bincount(keys.key, d2, n) / np.maximum(2 * np.bincount(keys.key, minlength=n), 1))
            scale = scale / np.maximum(rms, 1.0)[keys.key][:, None]
    try:
        cov = np.linalg.inv(r.jac.T @ r.jac)
    except np.linalg.LinAlgError:
        return None
    return r.x, float(np.sqrt(max(np.linalg.eigvalsh(cov[:3, :3]).max(), 0.0)))
