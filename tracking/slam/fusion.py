"""Fusing anchors and keypoints into one pose, and hiding the seams between sources.

- `fuse_pose`: one robust pose from marker corners (known world points, high
  weight: the anchors dominate) together with the map points matched this frame.
- `PoseBlender`: when the pose source switches (marker <-> keypoints) or the
  tracker relocalises, the estimate may step by a few millimetres; the blender
  spreads such a step over a few frames so overlays do not visibly jump.

Poses are `world_from_camera` 4x4; image points undistorted pixels; metres.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from tracking.poses import invert, make_pose
from tracking.slam.frame_pose import refine_pose


def fuse_pose(K: np.ndarray, init: np.ndarray, corner_world: np.ndarray, corner_uv: np.ndarray,
              map_world: np.ndarray, map_uv: np.ndarray, corner_weight: float = 4.0,
              map_weights: np.ndarray | None = None, corner_share: float = 1 / 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Joint Huber refinement of marker corners and map points from `init`.

    Returns (pose, corner inlier mask, map inlier mask, RMS px). Corners carry
    `corner_weight` (information relative to a 1 px keypoint), and their total
    weight is raised so they hold at least `corner_share` of the information:
    the map refines the marker pose without being able to pull it away.
    """
    nc, nm = corner_world.shape[0], map_world.shape[0]
    wm = np.ones(nm) if map_weights is None else np.asarray(map_weights, float)
    wc = corner_weight
    if nc and nm:
        share = min(max(corner_share, 0.0), 0.95)
        wc = max(wc, share / (1 - share) * wm.sum() / nc)
    X = np.concatenate([corner_world.reshape(-1, 3), map_world.reshape(-1, 3)])
    uv = np.concatenate([corner_uv.reshape(-1, 2), map_uv.reshape(-1, 2)])
    w = np.concatenate([np.full(nc, wc), wm])
    # inlier test on the measurement noise alone (corners ~1 px, keypoints by their weight)
    s2 = np.concatenate([np.ones(nc), 1.0 / np.maximum(wm, 1e-12)])
    pose, inl, rms = refine_pose(K, init, X, uv, w, sigma2=s2)
    return pose, inl[:nc], inl[nc:], rms


def _log(T: np.ndarray) -> np.ndarray:
    return np.concatenate([Rotation.from_matrix(T[:3, :3]).as_rotvec(), T[:3, 3]])


def _exp(v: np.ndarray) -> np.ndarray:
    return make_pose(Rotation.from_rotvec(v[:3]).as_matrix(), v[3:])


class PoseBlender:
    """Output pose = estimate @ offset, with a camera-side `offset` that fades to identity.

    `switch(estimate, previous_output_predicted)` starts a fade when the step is
    small enough to be a seam (<= max_step_m, max_step_rad); a larger step is a
    real relocation and is taken at once.
    """

    def __init__(self, frames: int = 8, max_step_m: float = 0.05, max_step_rad: float = 0.15):
        self.frames = max(1, int(frames))
        self.max_step_m = max_step_m
        self.max_step_rad = max_step_rad
        self.reset()

    def reset(self) -> None:
        self._offset0 = None
        self._k = 0
        self._frames = self.frames

    @property
    def active(self) -> bool:
        return self._offset0 is not None

    def current_offset(self) -> np.ndarray:
        if self._offset0 is None:
            return np.eye(4)
        a = max(0.0, 1.0 - self._k / self._frames)
        return _exp(a * self._offset0)

    def switch(self, estimate: np.ndarray, target: np.ndarray, frames: int | None = None,
               at_once: bool = False) -> None:
        """Fade from `target` (where the output would have been) to `estimate`, over `frames` frames
        (default `self.frames`; fewer when the new estimate is known to be the better one). `at_once`: this
        frame's output already takes the first step (else it is `target` itself)."""
        off = invert(estimate) @ target
        v = _log(off)
        if np.linalg.norm(v[3:]) > self.max_step_m or np.linalg.norm(v[:3]) > self.max_step_rad:
            self.reset()
            return
        self._offset0 = v
        self._frames = self.frames if frames is None else max(1, int(frames))
        self._k = 1 if at_once else 0
        if self._k >= self._frames:
            self.reset()

    def hurry(self, frames: int) -> None:
        """An active fade that has more than `frames` frames to go finishes within `frames` instead, from
        the offset it has reached (this frame's output takes the first of those steps)."""
        if self._offset0 is None or self._frames - self._k <= frames:
            return
        self._offset0 = max(0.0, 1.0 - self._k / self._frames) * self._offset0
        self._frames = max(1, int(frames))
        self._k = 1
        if self._k >= self._frames:
            self.reset()

    def apply(self, estimate: np.ndarray) -> np.ndarray:
        """The output pose for this frame's estimate; advances the fade by one frame."""
        if self._offset0 is None:
            return estimate
        out = estimate @ self.current_offset()
        self._k += 1
        if self._k >= self._frames:
            self.reset()
        return out
