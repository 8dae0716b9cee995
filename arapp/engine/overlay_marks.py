"""The marks that show the markers the tracker sees on the live view: each marker's outline and a small
RGB axis triad at each anchor's origin, drawn into the display picture. No Qt, no GL.

The outlines are the anchors' marker corners (tracking.anchors.model: anchor frame, metres) projected
with the frame's `world_from_camera` and the source's camera (distortion applied, as cv2.projectPoints),
so they lie on the markers as the pose puts them: where they sit off the printed squares, the pose is
off. Only markers whose four corners are in front of the camera and inside the frame are outlined, and
nothing is drawn on a frame where the tracker detected no marker (state "slam" or "lost").

`draw_marks` draws them in the processing thread into the picture scaled to the view, after the
model was composited, so the UI thread neither computes nor paints them and the full-size composite
(`FrameResult.image`: AR videos) stays without them. They lie on the paper, under the model: a mark's pixel
where the renderer drew the model (the composite differs from the frame as captured there: the
compositor leaves every other pixel bit-exact) shows only as much as the display mode's surface lets
the paper through (`under_opacity`: nothing when shaded).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import cv2
import numpy as np

from arapp.render.modes import SURFACE_ALPHA
from tracking.anchors.model import build_models

# the triad's length in marker sides: plain to see, and short of the next marker on a board
AXIS_SHARE = 1.0
MIN_DEPTH_M = 0.01  # points nearer the camera than this (or behind it) are not drawn
OUTLINE_RGB = (0, 230, 255)  # cyan: stands out on paper, skin and wood alike
AXIS_RGB = ((255, 40, 40), (40, 220, 40), (60, 110, 255))  # x red, y green, z blue
# line widths in display pixels, as cv2's antialiased lines come out: an outline edge is two 1-pixel
# lines half a pixel either side of it (about 2 px), an axis one line of thickness 2 (about 3 px)
OUTLINE_PX, AXIS_PX = 2, 3
SUBPIXEL_BITS = 4  # cv2 drawing with 1/16-pixel positions
LIMIT_PX = 1e6  # line ends are clipped to this far off the picture (cv2 takes int32 positions)


def under_opacity(mode: str) -> float:
    """How much of a mark under the model shows through its surface in display `mode` (0: none)."""
    return max(0.0, 1.0 - float(SURFACE_ALPHA.get(mode, 1.0)))


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

    def lines(self) -> list[tuple[np.ndarray, np.ndarray, int]]:
        """Every mark's line as (a, b, kind): kind -1 for a marker outline's edge, 0/1/2 for an x/y/z axis."""
        out = [(q[k], q[(k + 1) % 4], -1) for q in self.quads for k in range(4)]
        out += [(origin, end, i) for origin, *ends in self.axes for i, end in enumerate(ends)]
        return out


def _native(rgb: tuple[int, int, int]) -> tuple[int, int, int, int]:
    """An opaque colour in the display picture's 32-bit order (arapp.engine.processor.to_bgra)."""
    r, g, b = rgb
    return (b, g, r, 255) if sys.byteorder == "little" else (255, r, g, b)


def draw_marks(display: np.ndarray, marks: MarkerMarks, composite: np.ndarray | None = None,
               frame: np.ndarray | None = None, under: float = 0.0) -> None:
    """Draw `marks` (frame pixels) into `display` in place: the (h, w, 4) uint8 picture of the frame scaled
    to the view (its aspect kept), antialiased lines OUTLINE_PX / AXIS_PX display pixels wide.

    composite, frame: the full-size BGR frame with the model drawn and as captured; where they differ
    (the model), a mark's pixel keeps only `under` of its colour (under_opacity of the display mode).
    """
    h, w = display.shape[:2]
    sx, sy = w / marks.width, h / marks.height
    lines = marks.lines()
    if not lines:
        return
    # the lines' box in the display (a few pixels wider for line width and antialiasing), clipped
    ends = np.array([[a, b] for a, b, _ in lines], float).reshape(-1, 2)
    ends = np.clip((ends + 0.5) * (sx, sy) - 0.5, -LIMIT_PX, LIMIT_PX)
    if not np.isfinite(ends).all():
        return
    x0, y0 = np.maximum(np.floor(ends.min(axis=0)).astype(int) - 4, 0)
    x1, y1 = np.minimum(np.ceil(ends.max(axis=0)).astype(int) + 5, (w, h))
    if x1 <= x0 or y1 <= y0:
        return
    box = display[y0:y1, x0:x1]
    groups = _strokes((ends - (x0, y0)).reshape(-1, 2, 2), [kind for _a, _b, kind in lines])
    model = None
    if composite is not None and frame is not None and under < 1.0:
        model = _model_mask(composite, frame, (x0, y0, x1, y1), (sx, sy))
        before = box.copy() if model is not None else None
    for (colour, thickness), polylines in groups.items():
        cv2.polylines(box, polylines, False, colour, thickness, cv2.LINE_AA, SUBPIXEL_BITS)
    if model is not None:
        # where the model is drawn, the marks show only as much as its surface lets the paper through
        seen = before if under <= 0.0 else cv2.addWeighted(box, under, before, 1.0 - under, 0.0)
        out = cv2.copyTo(seen, model, box)  # in place over the view (ten times numpy's copyto with where)
        if out is not box:
            box[...] = out


def _model_mask(composite: np.ndarray, frame: np.ndarray, box: tuple[int, int, int, int],
                scale: tuple[float, float]) -> np.ndarray | None:
    """uint8 (y1 - y0, x1 - x0), 1 at the display pixels of `box` (x0, y0, x1, y1) whose frame pixel
    (nearest, the display being the frame `scale`d) shows the model: the composite differs from the frame
    there. None when the model covers none of them."""
    x0, y0, x1, y1 = box
    sx, sy = scale
    h, w = frame.shape[:2]
    fx0, fy0 = max(int(np.floor((x0 + 0.5) / sx - 0.5)) - 1, 0), max(int(np.floor((y0 + 0.5) / sy - 0.5)) - 1, 0)
    fx1, fy1 = min(int(np.ceil((x1 - 0.5) / sx + 0.5)) + 1, w), min(int(np.ceil((y1 - 0.5) / sy + 0.5)) + 1, h)
    if fx1 <= fx0 or fy1 <= fy0:
        return None
    diff = cv2.absdiff(composite[fy0:fy1, fx0:fx1], frame[fy0:fy1, fx0:fx1])
    # any channel differing: the channels' sum (saturated: nonzero exactly where one is; numpy's max over
    # the last axis takes ten times as long)
    changed = cv2.transform(diff, np.ones((1, diff.shape[2]))) if diff.ndim == 3 else diff
    if not changed.any():
        return None
    # display pixel (u, v) of the box shows frame pixel ((u + x0 + 0.5) / sx - 0.5, ...): the inverse map
    to_box = np.array([[sx, 0.0, (fx0 + 0.5) * sx - 0.5 - x0], [0.0, sy, (fy0 + 0.5) * sy - 0.5 - y0]])
    return cv2.warpAffine(np.minimum(changed, 1), to_box, (x1 - x0, y1 - y0), flags=cv2.INTER_NEAREST)


def _strokes(segments: np.ndarray, kinds: list[int]) -> dict:
    """cv2 polylines (1/16 pixels) grouped by (colour, thickness) for line `segments` (N, 2, 2) of `kinds`
    (MarkerMarks.lines): an outline edge as two 1-pixel lines half a pixel either side, an axis as one
    line of thickness 2."""
    one = 1 << SUBPIXEL_BITS
    kinds = np.asarray(kinds)
    groups: dict = {}
    edges = segments[kinds < 0]
    if len(edges):
        d = edges[:, 1] - edges[:, 0]
        n = np.stack([-d[:, 1], d[:, 0]], 1) / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None] * 0.5
        both = np.concatenate([edges + n[:, None], edges - n[:, None]])
        groups[(_native(OUTLINE_RGB), 1)] = list(np.round(both * one).astype(np.int32))
    for k in range(3):
        axes = segments[kinds == k]
        if len(axes):
            groups[(_native(AXIS_RGB[k]), 2)] = list(np.round(axes * one).astype(np.int32))
    return groups


_models_cache: tuple = (None, [])  # (the anchors list last asked about, its models): frames share one list


def _models(anchors: list) -> list:
    global _models_cache
    if _models_cache[0] is not anchors:
        _models_cache = (anchors, build_models(list(anchors)))
    return _models_cache[1]


def marker_marks(camera, anchors: list, world_from_camera: np.ndarray | None, markers_seen: int = 1) -> MarkerMarks:
    """The outlines and axis triads of `anchors` (AnchorSpec list) seen by `camera` (tracking.camera.Camera)
    from `world_from_camera` (4x4, metres); empty without a pose or when `markers_seen` is 0."""
    marks = MarkerMarks(int(camera.width), int(camera.height))
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
    # one projection for every point: well under a millisecond per frame
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
