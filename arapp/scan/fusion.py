"""From filtered depth maps to a watertight solid: the board frame, the object's region, TSDF fusion,
the silhouette hull, and marching cubes.

Frames and units: metres. `BoardFrame` is the first anchor's plane (the world
frame's z = 0) with `up` pointing out of the printed side; heights `h` are
measured along `up` from the paper. The object is what stands above the paper
inside the board's outline; the desk and the board (h <= 0) are cut away.

Fusion: a dense truncated signed distance grid over the object's box
(weighted average of per-view signed distances along the rays, the standard
TSDF). Voxels never observed (behind the surfaces) are inside when they lie in
the silhouette hull (in the object's image region in every depth map that sees
them, but for `hull_slack` maps) and outside otherwise; everything at or below
the paper is outside. Marching cubes (scikit-image) on this closed field, padded
with "outside", gives a watertight surface by construction; the largest
component is kept (small cavities and floaters go) and lightly smoothed
(Taubin, which keeps the volume).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import trimesh
from scipy import ndimage

from tracking.anchors.model import build_models


@dataclass
class BoardFrame:
    """The paper plane: `origin` and orthonormal `e1`, `e2` in it, `up` out of the printed side (world, m);
    `outline` (K,2) the board's marker corners as (e1, e2) coordinates."""

    origin: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    up: np.ndarray
    outline: np.ndarray

    @property
    def R(self) -> np.ndarray:
        """world_from_board rotation (columns e1, e2, up)."""
        return np.column_stack([self.e1, self.e2, self.up])

    def to_local(self, X: np.ndarray) -> np.ndarray:
        return (X - self.origin) @ self.R

    def to_world(self, L: np.ndarray) -> np.ndarray:
        return L @ self.R.T + self.origin

    def on_board(self, L: np.ndarray, margin: float = 0.0) -> np.ndarray:
        lo, hi = self.outline.min(axis=0) - margin, self.outline.max(axis=0) + margin
        return np.all((L[:, :2] >= lo) & (L[:, :2] <= hi), axis=1)


def board_frame(anchors) -> BoardFrame:
    """The first anchor's plane. Boards (GridBoard, ChArUco) have z into the paper (up = -z); single
    markers and QR codes z out of it (docs/recording-format.md)."""
    model = build_models(list(anchors))[0]
    T = model.world_from_anchor
    sign = model.anchor_kind.face
    up = sign * T[:3, 2]
    e1 = T[:3, 0]
    e2 = np.cross(up, e1)
    frame = BoardFrame(T[:3, 3].copy(), e1, e2, up, np.zeros((0, 2)))
    frame.outline = frame.to_local(model.to_world(model.outline()))[:, :2]
    return frame


def object_region(points: np.ndarray, frame: BoardFrame, min_height: float = 0.003, cell: float = 0.003,
                  margin: float = 0.006):
    """Box (lo, hi) in board coordinates around the object: points above `min_height` over the board,
    binned into `cell` voxels (3+ points each); the largest 26-connected cluster. None if nothing stands there."""
    L = frame.to_local(points)
    L = L[(L[:, 2] > min_height) & frame.on_board(L)]
    if len(L) < 100:
        return None
    keys = np.floor(L / cell).astype(np.int64)
    kmin = keys.min(axis=0)
    keys -= kmin
    shape = keys.max(axis=0) + 1
    counts = np.zeros(shape, np.int32)
    np.add.at(counts, tuple(keys.T), 1)
    labels, n = ndimage.label(counts >= 3, structure=np.ones((3, 3, 3)))
    if n == 0:
        return None
    sizes = ndimage.sum(counts, labels, index=np.arange(1, n + 1))
    idx = np.argwhere(labels == 1 + int(np.argmax(sizes)))
    lo = (idx.min(axis=0) + kmin) * cell - margin
    hi = (idx.max(axis=0) + 1 + kmin) * cell + margin
    lo[2] = -margin   # down to below the paper: the cut at h = 0 makes the flat bottom
    return lo, hi


def object_masks(maps, frame: BoardFrame, lo, hi, min_height: float = 0.003, grow_px: int = 12):
    """Per depth map: the object's image region (pixels whose depth lies in the box above min_height),
    closed, holes filled and grown by grow_px (depth is missing at occluding edges)."""
    masks = []
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
    for dm in maps:
        X, flat = dm.points()
        m = np.zeros(dm.depth.shape, np.uint8)
        if len(X):
            L = frame.to_local(X)
            inside = np.all((L >= lo) & (L <= hi), axis=1) & (L[:, 2] > min_height)
            m.ravel()[flat[inside]] = 255
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k)
        m = cv2.dilate(m, k)
        # fill holes: everything not reachable from the border is inside
        ff = m.copy()
        pad = np.zeros((m.shape[0] + 2, m.shape[1] + 2), np.uint8)
        cv2.floodFill(ff, pad, (0, 0), 128)
        m[ff == 0] = 255
        # a map that saw none of the object (its pair failed there) cannot vote on the silhouette
        masks.append(m > 0 if m.any() else None)
    return masks


def fuse(maps, frame: BoardFrame, lo, hi, voxel: float, trunc: float, masks=None, hull_slack: int = 2,
         progress=None):
    """Fuse the depth maps into a closed signed field over the box; returns (field, origin_local, voxel).
    Negative inside. Grid layer k lies at height (k + 0.5) * voxel above the paper (so the cut is at h = 0)."""
    lo = np.asarray(lo, float).copy()
    lo[2] = np.floor(lo[2] / voxel) * voxel
    n = np.ceil((np.asarray(hi) - lo) / voxel).astype(int) + 1
    g = [lo[a] + (np.arange(n[a]) + 0.5) * voxel for a in range(3)]
    Lx, Ly, Lz = np.meshgrid(*g, indexing="ij")
    L = np.c_[Lx.ravel(), Ly.ravel(), Lz.ravel()]
    W = frame.to_world(L).astype(np.float32)
    tsdf = np.zeros(len(L), np.float32)
    weight = np.zeros(len(L), np.float32)
    outside_votes = np.zeros(len(L), np.int16)
    for k, dm in enumerate(maps):
        cfw = np.linalg.inv(dm.pose).astype(np.float32)
        pc = W @ cfw[:3, :3].T + cfw[:3, 3]
        z = pc[:, 2]
        h, w = dm.depth.shape
        front = np.nonzero(z > 1e-3)[0]
        zf = z[front]
        u = np.rint(dm.K[0, 0] * pc[front, 0] / zf + dm.K[0, 2])
        v = np.rint(dm.K[1, 1] * pc[front, 1] / zf + dm.K[1, 2])
        ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
        idx, ui, vi, zi = front[ok], u[ok].astype(np.int64), v[ok].astype(np.int64), zf[ok]
        d = dm.depth[vi, ui]
        sdf = d - zi
        upd = (d > 0) & (sdf > -trunc)
        j = idx[upd]
        val = np.clip(sdf[upd] / trunc, -1.0, 1.0)
        tsdf[j] = (tsdf[j] * weight[j] + val) / (weight[j] + 1.0)
        weight[j] += 1.0
        if masks is not None and masks[k] is not None:
            outside_votes[idx[~masks[k][vi, ui]]] += 1
        if progress is not None:
            progress("fusing", k + 1, len(maps))
    field = tsdf.copy()
    unknown = weight == 0
    hull = outside_votes <= hull_slack if masks is not None else np.ones(len(L), bool)
    field[unknown] = np.where(hull[unknown], -1.0, 1.0)
    field[L[:, 2] < 0] = 1.0
    field = field.reshape(n)
    return field, lo, voxel


def surface_from_field(field: np.ndarray, lo_local: np.ndarray, voxel: float, frame: BoardFrame,
                       smooth_iterations: int = 6) -> trimesh.Trimesh:
    """Watertight mesh (world frame, metres, outward normals) of the zero level set, largest component."""
    from skimage.measure import marching_cubes  # optional extra arapp[scan]; the CLI checks it first

    padded = np.pad(field, 1, constant_values=1.0)
    if padded.min() >= 0:
        raise RuntimeError("nothing solid was reconstructed above the board; scan closer, with more texture")
    verts, faces, _, _ = marching_cubes(padded, level=0.0, spacing=(voxel, voxel, voxel),
                                        gradient_direction="ascent")
    local = verts + (np.asarray(lo_local) + 0.5 * voxel - voxel)
    mesh = trimesh.Trimesh(frame.to_world(local), faces, process=True)
    parts = mesh.split(only_watertight=True)
    if len(parts) == 0:
        raise RuntimeError("the reconstructed surface does not close; scan the object from more sides")
    mesh = max(parts, key=lambda p: abs(p.volume))
    if smooth_iterations:
        trimesh.smoothing.filter_taubin(mesh, iterations=smooth_iterations)
    if mesh.volume < 0:
        mesh.invert()
    return mesh
