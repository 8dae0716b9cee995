"""Poses as 6-vectors and the marker's plane z = 0 seen by a camera: the small geometry the desk's fits
(desk.py, desk_bundle.py) share.

A pose vector p is [rvec (3), tvec (3)] of camera_from_world (world = the marker's anchor world, metres);
image points are normalised coordinates (undistorted, divided by depth).
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.poses import from_rvec_tvec, to_rvec_tvec


def params(cfw: np.ndarray) -> np.ndarray:
    """The pose vector (6,) of a 4x4 camera_from_world."""
    r, t = to_rvec_tvec(cfw)
    return np.concatenate([np.ravel(r), np.ravel(t)])


def pose(p: np.ndarray) -> np.ndarray:
    """The 4x4 camera_from_world of a pose vector."""
    return from_rvec_tvec(p[:3], p[3:6])


def rot(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R 3x3, t 3) of a pose vector."""
    return cv2.Rodrigues(np.asarray(p[:3], np.float64).reshape(3, 1))[0], np.asarray(p[3:6], float)


def project(R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Normalised coordinates (N,2) of world points X (N,3) seen by camera (R, t)."""
    Xc = X @ R.T + t
    return Xc[:, :2] / Xc[:, 2:3]


def lift(R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """World points (N,3) on the plane z = 0 seen at normalised coordinates x (N,2) by camera (R, t)."""
    c = -R.T @ t
    d = np.column_stack([x, np.ones(len(x))]) @ R   # rows: R^T [x, y, 1]
    lam = -c[2] / np.where(np.abs(d[:, 2]) > 1e-9, d[:, 2], 1e-9)
    return c + lam[:, None] * d
