"""The marks that show the markers the tracker sees, drawn on the live view's frame: each marker's outline
and a small RGB axis triad at each anchor's origin. No Qt, no GL.

The outlines are the anchors' marker corners (tracking.anchors.model: anchor frame, metres) projected
with the frame's `world_from_camera` and the source's camera (distortion applied, as cv2.projectPoints),
so they lie on the markers as the pose puts them: where they sit off the printed squares, the pose is
off. Only markers whose four corners are in front of the camera and inside the frame are outlined, and
nothing is drawn on a frame where the tracker detected no marker (state "slam" or "lost").

`MarksUnderlay` draws them into the frame in the processing thread before the model is composited
(`arapp.pipeline.Pipeline.underlay`), so they lie on the paper, under the model: the renderer's own
picture covers them as much as the display mode's surface covers the paper. Nothing of them is left
for the UI thread to compute or paint.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.anchors.model import build_models

# the triad's length in marker sides: plain to see, and short of the next marker on a board
AXIS_SHARE = 1.0
MIN_DEPTH_M = 0.01  # points nearer the camera than this (or behind it) are not drawn
OUTLINE_BGR = (255, 230, 0)  # cyan: stands out on paper, skin and wood alike
AXIS_BGR = ((40, 40, 255), (40, 220, 40), (255, 110, 60))  # x red, y green, z blue
OUTLINE_PX, AXIS_PX = 2.0, 3.0  # line widths in display pixels (as painted on screen)
SUBPIXEL_BITS = 4  # cv2 drawing with 1/16-pixel positions
LIMIT_PX = 1e6  # line ends are clipped to this far off the frame (cv2 takes int32 positions)


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


def draw_marks(image: np.ndarray, marks: MarkerMarks, display_scale: float = 1.0) -> None:
    """Draw `marks` on the BGR `image` (frame pixels) in place, antialiased, with line widths chosen so
    that they are OUTLINE_PX / AXIS_PX wide once the frame is shown `display_scale` times its size."""
    s = max(float(display_scale), 1e-3)
    widths = {-1: max(1, round(OUTLINE_PX / s)), 0: max(1, round(AXIS_PX / s))}
    one = 1 << SUBPIXEL_BITS
    for a, b, kind in marks.lines():
        ab = np.clip(np.array([a, b], float), -LIMIT_PX, LIMIT_PX)  # a triad's end may project far off
        if not np.isfinite(ab).all():
            continue
        pa, pb = (tuple(int(round(v * one)) for v in p) for p in ab)
        colour = OUTLINE_BGR if kind < 0 else AXIS_BGR[kind]
        cv2.line(image, pa, pb, colour, widths[min(kind, 0)], cv2.LINE_AA, SUBPIXEL_BITS)


class MarksUnderlay:
    """`Pipeline.underlay` drawing the marker marks of `camera` and `anchors` (the pipeline's) on each frame
    with a pose and a detected marker; `display_scale` (display pixels per frame pixel) sets line widths."""

    def __init__(self, camera, anchors: list):
        self.camera, self.anchors = camera, list(anchors)
        self.display_scale = 1.0

    def __call__(self, image: np.ndarray, world_from_camera: np.ndarray | None, markers_seen: int) -> None:
        marks = marker_marks(self.camera, self.anchors, world_from_camera, markers_seen)
        if marks.quads or marks.axes:
            draw_marks(image, marks, self.display_scale)


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
