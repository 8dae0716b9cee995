"""A frame's pose against the map: motion prediction, projection matching, PnP RANSAC,
robust (Huber) pose-only refinement.

Poses: `world_from_camera` 4x4 (OpenCV camera axes); internally the optimiser
works on `camera_from_world`. Image points are undistorted pixels (same K).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

# the pose fit itself lives below the layers (tracking.pose_fit); re-exported for the map's callers
from tracking.pose_fit import CHI2_2D, position_spread, project, refine_pose  # noqa: F401
from tracking.poses import invert, rotation_angle
from tracking.slam.features import Features, hamming


def pnp_ransac(K: np.ndarray, X: np.ndarray, uv: np.ndarray, guess: np.ndarray | None = None,
               threshold: float = 3.0) -> tuple[np.ndarray | None, np.ndarray]:
    """RANSAC PnP on undistorted pixels: (world_from_camera or None, inlier mask)."""
    n = X.shape[0]
    if n < 6:
        return None, np.zeros(n, bool)
    kw = {}
    if guess is not None:
        cw = invert(guess)
        rvec, _ = cv2.Rodrigues(np.ascontiguousarray(cw[:3, :3]))
        kw = dict(rvec=rvec, tvec=cw[:3, 3].reshape(3, 1).copy(), useExtrinsicGuess=True)
    ok, rvec, tvec, inl = cv2.solvePnPRansac(
        np.ascontiguousarray(X, np.float64), np.ascontiguousarray(uv, np.float64), K, None,
        iterationsCount=100, reprojectionError=threshold, confidence=0.99, flags=cv2.SOLVEPNP_EPNP, **kw)
    mask = np.zeros(n, bool)
    if not ok or inl is None or len(inl) < 6:
        return None, mask
    mask[inl.ravel()] = True
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return invert(T), mask


def match_by_projection(K: np.ndarray, width: int, height: int, world_from_camera: np.ndarray,
                        X: np.ndarray, desc: np.ndarray, feats: Features, radius: float,
                        max_distance: int = 64, ratio: float = 0.9, k: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Match map points to features near their predicted projection.

    Returns (point indices, feature indices), one-to-one, best descriptor
    distance first. A match needs Hamming distance <= max_distance and, when a
    second candidate exists, to beat it by `ratio`.
    """
    if X.shape[0] == 0 or len(feats) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    uv, z = project(K, invert(world_from_camera), X)
    vis = (z > 0.02) & (uv[:, 0] > -radius) & (uv[:, 0] < width + radius) & (uv[:, 1] > -radius) & (uv[:, 1] < height + radius)
    pi = np.nonzero(vis)[0]
    if pi.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    tree = cKDTree(feats.und)
    kk = min(k, len(feats))
    dist, fi = tree.query(uv[pi], k=kk, distance_upper_bound=radius)
    dist = dist.reshape(pi.size, kk)
    fi = fi.reshape(pi.size, kk)
    valid = np.isfinite(dist)
    fi_safe = np.where(valid, fi, 0)
    hd = hamming(desc[pi][:, None, :], feats.desc[fi_safe])
    hd = np.where(valid, hd, 10_000)
    order = np.argsort(hd, axis=1)
    best = np.take_along_axis(hd, order[:, :1], 1)[:, 0]
    second = np.take_along_axis(hd, order[:, 1:2], 1)[:, 0] if kk > 1 else np.full(pi.size, 10_000)
    bf = np.take_along_axis(fi_safe, order[:, :1], 1)[:, 0]
    ok = (best <= max_distance) & ((second >= 10_000) | (best < ratio * second) | (second - best >= 8))
    pi, bf, best = pi[ok], bf[ok], best[ok]
    # one map point per feature: the closest descriptor wins
    o = np.argsort(best, kind="stable")
    pi, bf = pi[o], bf[o]
    _, first = np.unique(bf, return_index=True)
    first = np.sort(first)
    return pi[first], bf[first]


@dataclass
class MotionModel:
    """Constant-velocity prediction of `world_from_camera` from the last two poses."""

    last: np.ndarray | None = None
    last_t: float | None = None
    velocity: np.ndarray | None = None   # (6,) rotvec rad/s (camera frame), translation m/s (world)
    steps: int = 0   # frame-to-frame differences the velocity rests on (1: a single one, start-up noise and all)
    before: np.ndarray | None = None     # the pose before `last` when the two were consecutive updates
    before_t: float | None = None

    def reset(self) -> None:
        self.last, self.last_t, self.velocity, self.steps = None, None, None, 0
        self.before, self.before_t = None, None

    def predict(self, t: float) -> np.ndarray | None:
        if self.last is None:
            return None
        if self.velocity is None or self.last_t is None:
            return self.last.copy()
        dt = min(max(t - self.last_t, 0.0), 0.5)
        T = self.last.copy()
        # cv2.Rodrigues: the same rotation as scipy's Rotation, a tenth of the time (called several times a frame)
        T[:3, :3] = self.last[:3, :3] @ cv2.Rodrigues(np.ascontiguousarray(self.velocity[:3] * dt, dtype=float))[0]
        T[:3, 3] = self.last[:3, 3] + self.velocity[3:] * dt
        return T

    def update(self, pose: np.ndarray, t: float, smoothing: float = 0.5) -> None:
        if self.last is not None and self.last_t is not None and t - self.last_t > 1e-6 and t - self.last_t < 0.5:
            dt = t - self.last_t
            rel = self.last[:3, :3].T @ pose[:3, :3]
            # (cv2.Rodrigues: scipy's Rotation.from_matrix(rel).as_rotvec() to 1e-12 rad, a twentieth of the time)
            rotvec = cv2.Rodrigues(np.ascontiguousarray(rel))[0].ravel()
            v = np.concatenate([rotvec / dt, (pose[:3, 3] - self.last[:3, 3]) / dt])
            self.velocity = v if self.velocity is None else smoothing * v + (1 - smoothing) * self.velocity
            self.steps += 1
            self.before, self.before_t = self.last, self.last_t
        else:
            self.velocity, self.steps = None, 0
            self.before, self.before_t = None, None
        self.last, self.last_t = pose.copy(), t

    def last_step(self) -> tuple[np.ndarray, float] | None:
        """(the pose before `last`, the seconds from it to `last`), when the velocity rests on that step; else None."""
        if self.before is None or self.velocity is None or self.last_t is None or self.before_t is None:
            return None
        return self.before, self.last_t - self.before_t

    def lose(self) -> None:
        """Forget the velocity after a failed frame, keep the last pose for gating."""
        self.velocity, self.steps = None, 0
        self.before, self.before_t = None, None


def plausible(pose: np.ndarray, reference: np.ndarray, dt: float, max_speed: float = 2.0,
              max_angular: float = 4.0, slack_m: float = 0.03, slack_rad: float = 0.15) -> bool:
    """Whether `pose` can follow `reference` after dt seconds (metres, radians): no teleports."""
    dt = max(dt, 0.0)
    d = np.linalg.norm(pose[:3, 3] - reference[:3, 3])
    a = rotation_angle(reference[:3, :3].T @ pose[:3, :3])
    return d <= slack_m + max_speed * dt and a <= slack_rad + max_angular * dt
