"""What to draw over the live view to show the markers the tracker sees: each marker's outline and a small
RGB axis triad at each anchor's origin, as 2-D primitives in frame pixels. No Qt, no GL.

The outlines are the anchors' marker corners (tracking.anchors.model: anchor frame, metres) projected
with the frame's `world_from_camera` and the source's camera (distortion applied, as cv2.projectPoints),
so they lie on the markers as the pose puts them: where they sit off the printed squares, the pose is
off. Only markers whose four corners are in front of the camera and inside the frame are outlined, and
nothing is drawn on a frame where the tracker detected no marker (state "slam" or "lost").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracking.anchors.model import build_models

# the triad's length in marker sides: plain to see, and short of the next marker on a board
AXIS_SHARE = 1.0
MIN_DEPTH_M = 0.01  # points nearer the camera than this (or behind it) are not drawn


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


def _in_front(camera_from_world: np.ndarray, pts_world: np.ndarray) -> bool:
    z = pts_world @ camera_from_world[2, :3] + camera_from_world[2, 3]
    return bool(np.all(z > MIN_DEPTH_M))


def marker_marks(camera, anchors: list, world_from_camera: np.ndarray | None, markers_seen: int = 1) -> MarkerMarks:
    """The outlines and axis triads of `anchors` (AnchorSpec list) seen by `camera` (tracking.camera.Camera)
    from `world_from_camera` (4x4, metres); empty without a pose or when `markers_seen` is 0."""
    marks = MarkerMarks(int(camera.width), int(camera.height))
    if world_from_camera is None or markers_seen <= 0 or not anchors:
        return marks
    pose = np.asarray(world_from_camera, float)
    camera_from_world = np.linalg.inv(pose)
    w, h = camera.width, camera.height
    for model in build_models(list(anchors)):
        side = None
        for corners in model.markers.values():
            pw = model.to_world(np.asarray(corners, float))
            if not _in_front(camera_from_world, pw):
                continue
            uv = camera.project_world(pw, pose)
            if np.all((uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)):
                marks.quads.append(uv)
            if side is None:
                side = float(np.linalg.norm(np.asarray(corners, float)[1] - np.asarray(corners, float)[0]))
        if side is None:  # a QR code or ChArUco without markers listed: size the triad by the outline
            outline = np.asarray(model.outline(), float)
            side = float(np.ptp(outline[:, 0])) if len(outline) else 0.05
        length = AXIS_SHARE * side
        ends = model.to_world(np.array([[0, 0, 0], [length, 0, 0], [0, length, 0], [0, 0, length]], float))
        if _in_front(camera_from_world, ends):
            uv = camera.project_world(ends, pose)
            marks.axes.append((uv[0], uv[1], uv[2], uv[3]))
    return marks
