"""What to draw over the live view to show the markers the tracker sees: each marker's outline and a small
RGB axis triad at each anchor's origin, as 2-D primitives in frame pixels. No Qt, no GL.

The outlines are the anchors' marker corners (tracking.anchors.model: anchor frame, metres) projected
with the frame's `world_from_camera` and the source's camera (distortion applied, as cv2.projectPoints),
so they lie on the markers as the pose puts them: where they sit off the printed squares, the pose is
off. Only markers whose four corners are in front of the camera and inside the frame are outlined, and
nothing is drawn on a frame where the tracker detected no marker (state "slam" or "lost").

The marks lie on the paper, under the model: `model_cover` is the placed model's silhouette in the frame
(its triangles projected as the renderer projects them), and `MarkerMarks.pieces` splits each mark's
line into the runs the model covers and those it does not, so the view paints a covered run at
`under_opacity` (what shows through the model's surface in the display mode: nothing when shaded).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from arapp.geometry.placement import world_from_model
from arapp.render.modes import SURFACE_ALPHA
from tracking.anchors.model import build_models

# the triad's length in marker sides: plain to see, and short of the next marker on a board
AXIS_SHARE = 1.0
MIN_DEPTH_M = 0.01  # points nearer the camera than this (or behind it) are not drawn
COVER_SCALE = 0.5  # the silhouette's cells: 2 frame pixels wide (its edge within a pixel or two)
PIECE_PX = 2.0  # a mark's line is tested against the silhouette every this many frame pixels


def model_world_vertices(model, mesh, placement, anchor) -> np.ndarray:
    """The display mesh's vertices in the world (metres) with `model` placed at `placement` on `anchor`
    (as the pipeline places it: arapp.geometry.placement.world_from_model)."""
    placed = copy.copy(model)
    placed.placement = placement
    T = world_from_model(anchor, placed)
    v = np.asarray(mesh.vertices, float)
    return v @ T[:3, :3].T + T[:3, 3]


def under_opacity(mode: str) -> float:
    """How much of a mark under the model shows through its surface in display `mode` (0: none)."""
    return max(0.0, 1.0 - float(SURFACE_ALPHA.get(mode, 1.0)))


@dataclass
class Cover:
    """The model's silhouette: `mask` (uint8, 1 where the model is) on a grid of cells `1 / scale` frame
    pixels wide."""

    mask: np.ndarray
    scale: float

    def covered(self, uv: np.ndarray) -> np.ndarray:
        """Boolean per frame pixel position (N, 2): the model covers it."""
        h, w = self.mask.shape
        ij = np.floor((np.asarray(uv, float).reshape(-1, 2) + 0.5) * self.scale).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
        out = np.zeros(len(ij), bool)
        out[ok] = self.mask[ij[ok, 1], ij[ok, 0]] > 0
        return out


def fill_triangles(tri: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """uint8 mask of `shape` (h, w) with 1 in each cell whose centre lies in one of the triangles
    (tri: (F, 3, 2) in cell units, cell (i, j) spanning [i, i + 1) x [j, j + 1)), and in the cell of each
    triangle's centroid (a triangle smaller than a cell still covers one). A union, unlike cv2.fillPoly's
    even-odd rule, under which overlapping triangles cancel out."""
    h, w = shape
    mask = np.zeros((h, w), np.uint8)
    tri = np.asarray(tri, np.float32)
    if not len(tri):
        return mask
    tmin, tmax = tri.min(axis=1), tri.max(axis=1)
    onscreen = (tmax[:, 0] >= 0) & (tmax[:, 1] >= 0) & (tmin[:, 0] < w) & (tmin[:, 1] < h)
    tri, tmin, tmax = tri[onscreen], tmin[onscreen], tmax[onscreen]
    if not len(tri):
        return mask
    lo = np.clip(np.floor(tmin).astype(np.int32), 0, [w - 1, h - 1])
    hi = np.clip(np.floor(tmax).astype(np.int32), 0, [w - 1, h - 1])
    # each edge a -> b as a line equation e(p) = A x + B y + C, signed so that inside is e >= 0 for all three
    a, b = tri, np.roll(tri, -1, axis=1)
    A, B = a[..., 1] - b[..., 1], b[..., 0] - a[..., 0]
    C = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    area = (tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1]) - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0])
    sign = np.where(area < 0, -1.0, 1.0).astype(np.float32)[:, None]
    coef = np.concatenate([A * sign, B * sign, C * sign], axis=1)  # (F, 9): A0 A1 A2 B0 B1 B2 C0 C1 C2
    n = hi - lo + 1
    count = n[:, 0] * n[:, 1]
    k = np.repeat(np.arange(len(tri)), count)  # one row per (triangle, cell of its box)
    off = np.arange(len(k), dtype=np.int32) - np.repeat((np.cumsum(count) - count).astype(np.int32), count)
    nx = n[k, 0]
    ix, iy = lo[k, 0] + off % nx, lo[k, 1] + off // nx
    px, py = ix.astype(np.float32) + 0.5, iy.astype(np.float32) + 0.5
    c = coef[k]
    inside = ((c[:, 0] * px + c[:, 3] * py + c[:, 6] >= 0) & (c[:, 1] * px + c[:, 4] * py + c[:, 7] >= 0)
              & (c[:, 2] * px + c[:, 5] * py + c[:, 8] >= 0))
    mask[iy[inside], ix[inside]] = 1
    cen = np.floor(tri.mean(axis=1)).astype(np.int32)
    ok = (cen[:, 0] >= 0) & (cen[:, 0] < w) & (cen[:, 1] >= 0) & (cen[:, 1] < h)
    mask[cen[ok, 1], cen[ok, 0]] = 1
    return mask


def model_cover(camera, vertices_world: np.ndarray, faces: np.ndarray, world_from_camera: np.ndarray,
                scale: float = COVER_SCALE) -> Cover:
    """The silhouette of a mesh (vertices in the world, metres; faces (F, 3)) seen by `camera` from
    `world_from_camera`: vertices projected with lens distortion as cv2.projectPoints (edges straight
    between them), triangles with a vertex behind the camera left out; cells `1 / scale` pixels wide."""
    v = np.asarray(vertices_world, float)
    f = np.asarray(faces, np.int64)
    shape = (int(np.ceil(camera.height * scale)), int(np.ceil(camera.width * scale)))
    if not len(v) or not len(f):
        return Cover(np.zeros(shape, np.uint8), scale)
    pose = np.asarray(world_from_camera, float)
    camera_from_world = np.linalg.inv(pose)
    depth = v @ camera_from_world[2, :3] + camera_from_world[2, 3]
    uv = camera.project_world(v, pose)
    keep = (depth > MIN_DEPTH_M)[f].all(axis=1)
    return Cover(fill_triangles((uv[f[keep]] + 0.5) * scale, shape), scale)


@dataclass
class MarkerMarks:
    """Frame-pixel primitives (pixel centres at integers, frame `width` x `height`).

    quads: (4, 2) arrays, one per marker, in OpenCV corner order.
    axes: (origin, x_end, y_end, z_end), each a (2,) pixel position, one per anchor.
    """

    width: int
    height: int
    quads: list[np.ndarray] = field(default_factory=list)
    axes: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    cover: Cover | None = None  # the model's silhouette (None: no model shown)
    under_opacity: float = 0.0  # the opacity of a mark's run under the model

    def pieces(self, a, b) -> list[tuple[np.ndarray, np.ndarray, bool]]:
        """The line a -> b (frame pixels) as runs (start, end, covered by the model), in order."""
        return self.runs([(a, b)])[0]

    def runs(self, lines) -> list[list[tuple[np.ndarray, np.ndarray, bool]]]:
        """`pieces` of many lines [(a, b), ...], with one silhouette test for all their samples."""
        lines = [(np.asarray(a, float), np.asarray(b, float)) for a, b in lines]
        if self.cover is None:
            return [[(a, b, False)] for a, b in lines]
        counts = [max(1, int(np.ceil(np.linalg.norm(b - a) / PIECE_PX))) for a, b in lines]
        ts = [(np.arange(n) + 0.5) / n for n in counts]  # the middle of each of n steps
        pts = np.concatenate([a + t[:, None] * (b - a) for (a, b), t in zip(lines, ts)]) if lines else np.zeros((0, 2))
        hits = np.split(self.cover.covered(pts), np.cumsum(counts)[:-1])
        out = []
        for (a, b), n, hit in zip(lines, counts, hits):
            runs, start = [], 0
            for k in range(1, n + 1):
                if k == n or hit[k] != hit[start]:
                    runs.append((a + (start / n) * (b - a), a + (k / n) * (b - a), bool(hit[start])))
                    start = k
            out.append(runs)
        return out

    def lines(self) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Every mark's line as (a, b, kind): kind -1 for a marker outline's edge, 0/1/2 for an x/y/z axis."""
        out = [(q[k], q[(k + 1) % 4], -1) for q in self.quads for k in range(4)]
        out += [(origin, end, i) for origin, *ends in self.axes for i, end in enumerate(ends)]
        return out


_models_cache: tuple = (None, [])  # (the anchors list last asked about, its models): frames share one list


def _models(anchors: list) -> list:
    global _models_cache
    if _models_cache[0] is not anchors:
        _models_cache = (anchors, build_models(list(anchors)))
    return _models_cache[1]


def marker_marks(camera, anchors: list, world_from_camera: np.ndarray | None, markers_seen: int = 1,
                 cover: Cover | None = None, mode: str = "shaded") -> MarkerMarks:
    """The outlines and axis triads of `anchors` (AnchorSpec list) seen by `camera` (tracking.camera.Camera)
    from `world_from_camera` (4x4, metres); empty without a pose or when `markers_seen` is 0. `cover`: the
    model's silhouette (model_cover), drawn in display `mode`."""
    marks = MarkerMarks(int(camera.width), int(camera.height), cover=cover, under_opacity=under_opacity(mode))
    if world_from_camera is None or markers_seen <= 0 or not anchors:
        return marks
    pose = np.asarray(world_from_camera, float)
    camera_from_world = np.linalg.inv(pose)
    w, h = camera.width, camera.height
    quads_w, triads_w = [], []
    for model in _models(anchors):
        side = None
        for corners in model.markers.values():
            c = np.asarray(corners, float)
            quads_w.append(model.to_world(c))
            if side is None:
                side = float(np.linalg.norm(c[1] - c[0]))
        if side is None:  # a QR code or ChArUco without markers listed: size the triad by the outline
            outline = np.asarray(model.outline(), float)
            side = float(np.ptp(outline[:, 0])) if len(outline) else 0.05
        length = AXIS_SHARE * side
        triads_w.append(model.to_world(np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], float)))
    # one projection for every point: the per-frame cost stays well under a millisecond on the UI thread
    pts = np.concatenate(quads_w + triads_w).reshape(-1, 3)
    depth = pts @ camera_from_world[2, :3] + camera_from_world[2, 3]
    uv = camera.project_world(pts, pose)
    inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
    front = depth > MIN_DEPTH_M
    for k in range(len(quads_w)):
        s = slice(4 * k, 4 * k + 4)
        if front[s].all() and inside[s].all():
            marks.quads.append(uv[s])
    base = 4 * len(quads_w)
    for k in range(len(triads_w)):
        s = slice(base + 4 * k, base + 4 * k + 4)
        if front[s].all():
            marks.axes.append(tuple(uv[s]))
    return marks
