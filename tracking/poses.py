"""Rigid poses as 4x4 numpy arrays, and TUM trajectory files.

A pose is `a_from_b`: it maps points of frame b into frame a, `p_a = T @ p_b`.
The one pose type of the tracker is `world_from_camera` with OpenCV's camera
axes (x right, y down, z forward). Lengths in metres.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation


def make_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 pose from a 3x3 rotation and a translation 3-vector."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=float).reshape(3)
    return T


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 pose (transpose rotation, rotate translation back)."""
    R = T[:3, :3]
    return make_pose(R.T, -R.T @ T[:3, 3])


def from_rvec_tvec(rvec, tvec) -> np.ndarray:
    """`camera_from_object` pose from OpenCV's Rodrigues vector and translation."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))
    return make_pose(R, np.asarray(tvec, dtype=float).reshape(3))


def to_rvec_tvec(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV (rvec, tvec), each shape (3, 1), of a `camera_from_object` pose."""
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    return rvec.reshape(3, 1), T[:3, 3].reshape(3, 1).copy()


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 pose to points of shape (..., 3)."""
    p = np.asarray(points, dtype=float)
    return p @ T[:3, :3].T + T[:3, 3]


def rotation_angle(R: np.ndarray) -> float:
    """Angle in radians of a 3x3 rotation."""
    # (np.trace's sum and np.clip written out: the same numbers, without their per-call cost)
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0
    return float(np.arccos(min(max(c, -1.0), 1.0)))


def pose_to_tum(T: np.ndarray) -> np.ndarray:
    """(tx, ty, tz, qx, qy, qz, qw) of a pose; quaternion unit, scalar last, qw >= 0."""
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    if q[3] < 0:
        q = -q
    return np.concatenate([T[:3, 3], q])


def tum_to_pose(row) -> np.ndarray:
    """4x4 pose from (tx, ty, tz, qx, qy, qz, qw)."""
    row = np.asarray(row, dtype=float)
    return make_pose(Rotation.from_quat(row[3:7]).as_matrix(), row[:3])


def write_tum(path: str | Path, times, poses, mode: str = "w") -> None:
    """Write `world_from_camera` poses as a TUM trajectory (`t tx ty tz qx qy qz qw`)."""
    with open(path, mode) as f:
        if mode == "w":
            f.write("# t tx ty tz qx qy qz qw\n")
        for t, T in zip(times, poses):
            f.write(tum_line(t, T))


def tum_line(t: float, T: np.ndarray) -> str:
    """One TUM line (with newline) for time t in seconds and a 4x4 pose."""
    v = pose_to_tum(T)
    return f"{t:.6f} " + " ".join(f"{x:.9f}" for x in v) + "\n"


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory: (times (N,), poses (N, 4, 4)). Comments and blank lines skipped."""
    times, poses = [], []
    with open(path) as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            parts = s.split()
            if len(parts) != 8:
                raise ValueError(
                    f"{path}:{lineno}: a TUM line has 8 numbers (t tx ty tz qx qy qz qw), found {len(parts)}"
                )
            try:
                vals = [float(x) for x in parts]
            except ValueError:
                raise ValueError(f"{path}:{lineno}: not a number in {s!r}") from None
            times.append(vals[0])
            poses.append(tum_to_pose(vals[1:]))
    return np.asarray(times), np.asarray(poses).reshape(-1, 4, 4)
