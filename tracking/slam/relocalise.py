"""Relocalisation by keyframes: when tracking is lost and no anchor is in view, match the frame's
ORB descriptors against the map points seen by keyframes and solve PnP RANSAC.

Fewer than `min_inliers` (default 20) RANSAC inliers is not trusted (docs/domain.md §3).
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.slam.features import Features
from tracking.slam.map import Map
from tracking.slam.frame_pose import pnp_ransac, refine_pose


def relocalise(m: Map, feats: Features, K: np.ndarray, near: np.ndarray | None = None, max_keyframes: int = 8,
               min_inliers: int = 20, ratio: float = 0.8, max_hamming: int = 60) -> tuple[np.ndarray | None, int]:
    """(world_from_camera or None, inliers) from descriptor matching against keyframes' map points.

    Keyframes nearest to `near` (the last known pose) are tried first; without it (nothing tracked yet
    this run: a map loaded from a scene file, tracking.slam.map_io) every keyframe's points are.
    """
    if len(feats) < min_inliers:
        return None, 0
    with m.lock:
        kfs = m.nearest_keyframes(near, max_keyframes) if near is not None else list(m.keyframes.values())
    if not kfs:
        return None, 0
    # the union of map points these keyframes see, with their current positions and descriptors
    with m.lock:
        pids = sorted({int(p) for k in kfs for p in k.point_ids if p >= 0 and int(p) in m.points})
        if len(pids) < min_inliers:
            return None, 0
        X = np.array([m.points[p].xyz for p in pids])
        D = np.array([m.points[p].desc for p in pids], np.uint8)
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(feats.desc, D, k=2)
    fi, pi = [], []
    for mm in knn:
        if not mm or mm[0].distance > max_hamming:
            continue
        if len(mm) > 1 and mm[0].distance > ratio * mm[1].distance:
            continue
        fi.append(mm[0].queryIdx)
        pi.append(mm[0].trainIdx)
    if len(fi) < min_inliers:
        return None, 0
    fi, pi = np.array(fi), np.array(pi)
    _, u = np.unique(pi, return_index=True)
    fi, pi = fi[u], pi[u]
    pose, mask = pnp_ransac(K, X[pi], feats.und[fi], threshold=4.0)
    if pose is None or mask.sum() < min_inliers:
        return None, int(mask.sum())
    pose, inl, _ = refine_pose(K, pose, X[pi][mask], feats.und[fi][mask])
    if inl.sum() < min_inliers:
        return None, int(inl.sum())
    return pose, int(inl.sum())
