"""The sparse map: keyframes and map points in the anchors' world frame, metres.

Thread safety: the tracking thread reads snapshots and bumps match counters,
the mapping thread adds, moves and culls; both hold `Map.lock` while touching
shared state, and only briefly.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from tracking.slam.features import Features


@dataclass
class Keyframe:
    """A frame kept for mapping. `pose` world_from_camera; `point_ids[i]` the map point of feature i or -1.

    `anchor_world` (M,3) / `anchor_uv` (M,2 undistorted px): the anchors' corners
    seen in this keyframe; they tie the map to the markers in bundle adjustment.
    """

    id: int
    t: float
    pose: np.ndarray
    feats: Features
    point_ids: np.ndarray
    anchor_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    anchor_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def from_anchors(self) -> bool:
        return self.anchor_world.shape[0] >= 4

    @property
    def centre(self) -> np.ndarray:
        return self.pose[:3, 3]


@dataclass
class MapPoint:
    """A triangulated point: position (3,) world metres, a representative ORB descriptor,
    observations {keyframe id: feature index}. Match statistics live in `Map.match_counts`."""

    id: int
    xyz: np.ndarray
    desc: np.ndarray
    obs: dict[int, int]
    first_kf: int
    ready: bool = True     # tracking uses a new point only once bundle adjustment has refined it


class Map:
    """Keyframes and map points, with cached arrays for fast projection matching."""

    def __init__(self):
        self.lock = threading.RLock()
        self.keyframes: dict[int, Keyframe] = {}
        self.points: dict[int, MapPoint] = {}
        self._next_kf = 0
        self._next_pt = 0
        self.version = 0
        self._cache_version = -1
        self._cache = (np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 32), np.uint8))
        self._visible = np.zeros(0, np.int32)
        self._found = np.zeros(0, np.int32)

    # -- building ---------------------------------------------------------------
    def new_keyframe(self, t: float, pose: np.ndarray, feats: Features, point_ids: np.ndarray,
                     anchor_world=None, anchor_uv=None) -> Keyframe:
        with self.lock:
            kf = Keyframe(self._next_kf, t, pose.copy(), feats, point_ids.copy())
            if anchor_world is not None and len(anchor_world):
                kf.anchor_world = np.asarray(anchor_world, float).reshape(-1, 3)
                kf.anchor_uv = np.asarray(anchor_uv, float).reshape(-1, 2)
            self._next_kf += 1
            self.keyframes[kf.id] = kf
            for fi, pid in enumerate(kf.point_ids):
                p = self.points.get(int(pid))
                if pid >= 0 and p is not None:
                    p.obs[kf.id] = fi
                    p.desc = feats.desc[fi]   # latest view: keeps matching working as the viewpoint turns
                elif pid >= 0:
                    kf.point_ids[fi] = -1
            self.version += 1
            return kf

    def add_point(self, xyz: np.ndarray, desc: np.ndarray, obs: dict[int, int], ready: bool = True) -> MapPoint:
        with self.lock:
            p = MapPoint(self._next_pt, np.asarray(xyz, float).copy(), desc.copy(), dict(obs), min(obs), ready)
            self._next_pt += 1
            self.points[p.id] = p
            for kid, fi in obs.items():
                self.keyframes[kid].point_ids[fi] = p.id
            self.version += 1
            return p

    def remove_point(self, pid: int) -> None:
        with self.lock:
            p = self.points.pop(pid, None)
            if p is None:
                return
            for kid, fi in p.obs.items():
                kf = self.keyframes.get(kid)
                if kf is not None and kf.point_ids[fi] == pid:
                    kf.point_ids[fi] = -1
            self.version += 1

    def clear(self) -> None:
        with self.lock:
            self.keyframes.clear()
            self.points.clear()
            self.version += 1

    # -- reading ----------------------------------------------------------------
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(ids (N,), positions (N,3), descriptors (N,32)) of the points ready for tracking; cached
        until the map changes."""
        with self.lock:
            if self._cache_version != self.version:
                pts = [p for p in self.points.values() if p.ready]
                if pts:
                    self._cache = (np.array([p.id for p in pts], int), np.array([p.xyz for p in pts]),
                                   np.array([p.desc for p in pts], np.uint8))
                else:
                    self._cache = (np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 32), np.uint8))
                self._cache_version = self.version
            return self._cache

    def count_matches(self, visible_ids: np.ndarray, found_ids: np.ndarray) -> None:
        """Tracking statistics: points predicted in view, and those actually matched as inliers."""
        with self.lock:
            n = self._next_pt
            if self._visible.size < n:
                grow = max(n, 2 * self._visible.size)
                self._visible = np.concatenate([self._visible, np.zeros(grow - self._visible.size, np.int32)])
                self._found = np.concatenate([self._found, np.zeros(grow - self._found.size, np.int32)])
            np.add.at(self._visible, np.asarray(visible_ids, int), 1)
            np.add.at(self._found, np.asarray(found_ids, int), 1)

    def match_counts(self, pid: int) -> tuple[int, int]:
        """(times predicted visible, times matched) of a point while tracking, each at least 1."""
        if pid < self._visible.size:
            return int(self._visible[pid]) + 1, int(self._found[pid]) + 1
        return 1, 1

    def mark_ready(self, ids=None) -> None:
        """Let tracking use these points (all when ids is None)."""
        with self.lock:
            for pid in (self.points if ids is None else ids):
                p = self.points.get(int(pid))
                if p is not None and not p.ready:
                    p.ready = True
                    self.version += 1

    def recent_keyframes(self, n: int) -> list[Keyframe]:
        with self.lock:
            ids = sorted(self.keyframes)[-n:]
            return [self.keyframes[i] for i in ids]

    def nearest_keyframes(self, pose: np.ndarray, n: int, angle_weight: float = 0.3) -> list[Keyframe]:
        """The n keyframes closest in position (+ angle_weight m per radian of viewing-direction change)."""
        with self.lock:
            kfs = list(self.keyframes.values())
        if not kfs:
            return []
        c = np.array([k.centre for k in kfs])
        z = np.array([k.pose[:3, 2] for k in kfs])
        d = np.linalg.norm(c - pose[:3, 3], axis=1) + angle_weight * np.arccos(np.clip(z @ pose[:3, 2], -1, 1))
        return [kfs[i] for i in np.argsort(d)[:n]]

    # -- culling ----------------------------------------------------------------
    def cull(self, newest_kf: int, min_found_ratio: float = 0.25, min_obs: int = 2, grace_kfs: int = 3) -> int:
        """Remove points seldom matched when predicted visible, or still seen by too few keyframes
        `grace_kfs` keyframes after their creation. Returns how many were removed."""
        with self.lock:
            bad = []
            for p in self.points.values():
                visible, found = self.match_counts(p.id)
                if (visible >= 10 and found < min_found_ratio * visible) or (
                        newest_kf - p.first_kf >= grace_kfs and len(p.obs) < min_obs + 1 and found < 5):
                    bad.append(p.id)
        for pid in bad:
            self.remove_point(pid)
        return len(bad)
