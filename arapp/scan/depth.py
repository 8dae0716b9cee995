"""Dense depth per view: semi-global matching (OpenCV SGBM) on rectified pairs, or a depth camera's own
depth (`sensor_depth`), then multi-view consistency filtering.

Each chosen view is paired with a neighbour whose baseline is mostly
horizontal in the view's image (SGBM matches along rows) and whose viewing
direction differs by `min_angle_deg`..`max_angle_deg`. The pair is rectified
(cv2.stereoRectify) and matched; the depth map belongs to the rectified left
camera, a `DepthMap` with its own pinhole K and pose (world_from_camera,
metres). A depth is kept only where at least `min_agree` other depth maps see
the same surface within a relative tolerance (rejects mismatches, which
rarely agree across views).

A view that carries depth (an OAK-D's stereo depth, a recording's depth
stream) needs no matching: `sensor_depth` makes its depth map directly, on
the view's own (undistorted) camera and pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class DepthMap:
    """Metric depth (H,W) float32 along the camera's z (0 = none), pinhole `K`, `pose` world_from_camera,
    and the colour image it was matched on (BGR, same size)."""

    depth: np.ndarray
    K: np.ndarray
    pose: np.ndarray
    image: np.ndarray
    view: int

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """World points (N,3) of the valid pixels and their flat pixel indices."""
        v, u = np.nonzero(self.depth > 0)
        z = self.depth[v, u]
        x = (u - self.K[0, 2]) / self.K[0, 0] * z
        y = (v - self.K[1, 2]) / self.K[1, 1] * z
        pc = np.c_[x, y, z]
        return pc @ self.pose[:3, :3].T + self.pose[:3, 3], v * self.depth.shape[1] + u


def choose_pairs(poses: list[np.ndarray], target: np.ndarray, min_angle_deg: float = 6.0,
                 max_angle_deg: float = 25.0, ideal_deg: float = 12.0) -> list[tuple[int, int]]:
    """Unordered pairs: for each view, on each side (left, right in its image), the partner whose baseline
    is mostly horizontal and whose angle (seen from `target`) is nearest `ideal_deg` within the bounds."""
    dirs = np.array([T[:3, 3] - target for T in poses])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pairs = set()
    for i, Ti in enumerate(poses):
        best, best_cost = [None, None], [np.inf, np.inf]
        for j, Tj in enumerate(poses):
            if i == j:
                continue
            ang = np.degrees(np.arccos(np.clip(dirs[i] @ dirs[j], -1, 1)))
            if not min_angle_deg <= ang <= max_angle_deg:
                continue
            b = Ti[:3, :3].T @ (Tj[:3, 3] - Ti[:3, 3])   # baseline in camera i
            if abs(b[0]) < 2.0 * abs(b[1]):
                continue
            cost = abs(ang - ideal_deg)
            side = int(b[0] > 0)
            if cost < best_cost[side]:
                best[side], best_cost[side] = j, cost
        pairs.update((min(i, j), max(i, j)) for j in best if j is not None)
    return sorted(pairs)


def stereo_depth(img_a, img_b, K, pose_a, pose_b, z_range: tuple[float, float], index: int,
                 block: int = 5) -> DepthMap | None:
    """Depth of the rectified left camera of the pair (a, b) by SGBM; None when the pair cannot be matched."""
    h, w = img_a.shape[:2]
    b_from_a = np.linalg.inv(pose_b) @ pose_a
    R, T = b_from_a[:3, :3].copy(), b_from_a[:3, 3].reshape(3, 1).copy()
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(K, np.zeros(5), K, np.zeros(5), (w, h), R, T, flags=cv2.CALIB_ZERO_DISPARITY,
                                                alpha=-1)
    if abs(P2[1, 3]) > abs(P2[0, 3]):
        return None   # vertical rectification: SGBM matches along rows only
    if P2[0, 3] > 0:   # b is on the left: swap so that disparities are positive
        return stereo_depth(img_b, img_a, K, pose_b, pose_a, z_range, index, block)
    f = P1[0, 0]
    baseline = -P2[0, 3] / P2[0, 0]
    d_min = max(0, int(np.floor(f * baseline / z_range[1])))
    d_max = int(np.ceil(f * baseline / z_range[0]))
    n_disp = int(np.ceil(max(16, d_max - d_min) / 16.0)) * 16
    # SGBM needs the search to fit in the row (OpenCV allocates width - minDisparity - numDisparities)
    n_disp = min(n_disp, (w // 2 - d_min) // 16 * 16)
    if n_disp < 16 or n_disp > 512:
        return None
    map_a = cv2.initUndistortRectifyMap(K, None, R1, P1, (w, h), cv2.CV_32FC1)
    map_b = cv2.initUndistortRectifyMap(K, None, R2, P2, (w, h), cv2.CV_32FC1)
    ra = cv2.remap(img_a, *map_a, cv2.INTER_LINEAR)
    rb = cv2.remap(img_b, *map_b, cv2.INTER_LINEAR)
    valid_a = cv2.remap(np.full((h, w), 255, np.uint8), *map_a, cv2.INTER_NEAREST) > 0
    sgbm = cv2.StereoSGBM_create(minDisparity=d_min, numDisparities=n_disp, blockSize=block,
                                 P1=8 * 3 * block ** 2, P2=32 * 3 * block ** 2, disp12MaxDiff=1,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    disp = sgbm.compute(ra, rb).astype(np.float32) / 16.0
    ok = (disp > d_min) & valid_a
    depth = np.zeros((h, w), np.float32)
    depth[ok] = f * baseline / disp[ok]
    depth[(depth < z_range[0]) | (depth > z_range[1])] = 0
    # the rectified left camera: rotated by R1 (rect_from_cam) from camera a, same centre
    rect_pose = pose_a.copy()
    rect_pose[:3, :3] = pose_a[:3, :3] @ R1.T
    return DepthMap(depth, P1[:3, :3].copy(), rect_pose, ra, index)


def sensor_depth(depth: np.ndarray, image: np.ndarray, K: np.ndarray, pose: np.ndarray,
                 z_range: tuple[float, float], index: int, max_step: float = 0.01,
                 speckle_px: int = 100, stride: int = 1) -> DepthMap:
    """The depth map of a view whose depth came from the camera (float metres along z on the undistorted
    image's pixels, 0 = none), cleaned as a stereo camera's depth needs (no matching, no cross-check):

    - depths outside `z_range` (m) are dropped, as SGBM's search range drops them;
    - depth edges: a pixel whose 3x3 neighbourhood spans more than `max_step` x its depth is dropped
      (mixed foreground/background "flying pixels" at occluding contours, and surfaces seen edge-on);
    - speckles: connected blobs under `speckle_px` pixels whose neighbours step by less than `max_step`
      x depth are dropped (isolated mismatches, as SGBM's speckle filter does);
    - `stride` > 1 keeps every stride-th pixel in both directions (no averaging across edges), with the
      intrinsics scaled to match: fewer points for the fusion, which samples depth at voxel centres.

    The camera is the view's own (pinhole `K`, `pose` world_from_camera)."""
    d = np.asarray(depth, np.float32).copy()
    if d.shape != image.shape[:2]:
        raise ValueError(f"view {index}: depth of shape {d.shape} is not aligned to its {image.shape[1]}x"
                         f"{image.shape[0]} image")
    d[~np.isfinite(d) | (d < z_range[0]) | (d > z_range[1])] = 0
    k = np.ones((3, 3), np.uint8)
    # next to missing depth the window's minimum is 0: the rims of holes go too (mixed pixels live there)
    d[(cv2.dilate(d, k) - cv2.erode(d, k)) > max_step * d] = 0
    if speckle_px > 0:
        step_units = 0.0005   # 0.5 mm counts in int16: depths up to 16 m
        counts = np.clip(np.rint(d / step_units), 0, 32767).astype(np.int16)
        max_diff = int(max(1, round(max_step * float(np.median(d[d > 0])) / step_units))) if np.any(d > 0) else 1
        cv2.filterSpeckles(counts, 0, speckle_px, max_diff)
        d[counts == 0] = 0
    K = np.asarray(K, float).copy()
    if stride > 1:
        # pixel centres at integers: pixel u' of the subsampled map is pixel stride * u' of the full one
        d, image = np.ascontiguousarray(d[::stride, ::stride]), np.ascontiguousarray(image[::stride, ::stride])
        K[:2] /= stride
    return DepthMap(d, K, np.asarray(pose, float).copy(), image, index)


def _project(dm: DepthMap, X: np.ndarray):
    cfw = np.linalg.inv(dm.pose)
    pc = X @ cfw[:3, :3].T + cfw[:3, 3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(dm.K[0, 0] * pc[:, 0] / z + dm.K[0, 2]).astype(np.int64)
        v = np.round(dm.K[1, 1] * pc[:, 1] / z + dm.K[1, 2]).astype(np.int64)
    h, w = dm.depth.shape
    inside = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    return u, v, z, inside


def filter_consistent(maps: list[DepthMap], min_agree: int = 2, rel_tol: float = 0.006,
                      neighbours: int = 8, keep=None) -> None:
    """Zero the depths that fewer than `min_agree` of the `neighbours` nearest other maps confirm
    (their depth at the projected pixel within rel_tol x depth). `keep(points) -> bool mask` limits the
    work to a region (the rest is zeroed). In place."""
    axes = np.array([m.pose[:3, 2] for m in maps])
    new = []
    for i, dm in enumerate(maps):
        X, flat = dm.points()
        if keep is not None and len(X):
            sel = keep(X)
            X, flat = X[sel], flat[sel]
        votes = np.zeros(len(X), np.int32)
        order = np.argsort(-(axes @ axes[i]))
        others = [j for j in order if j != i][:neighbours]
        for j in others:
            u, v, z, inside = _project(maps[j], X)
            d = np.zeros(len(X), np.float32)
            d[inside] = maps[j].depth[v[inside], u[inside]]
            votes += (d > 0) & (np.abs(d - z) < rel_tol * z)
        out = np.zeros_like(dm.depth)
        good = flat[votes >= min_agree]
        out.ravel()[good] = dm.depth.ravel()[good]
        new.append(out)
    for dm, d in zip(maps, new):
        dm.depth = d
