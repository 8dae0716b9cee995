"""AnchorResult: what AnchorTracker.process says about one frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class AnchorResult:
    """What the anchors say about one frame.

    world_from_camera: filtered pose (4x4) or None when no anchor was seen.
    raw_world_from_camera: this frame's own solution (no filtering), or None.
    markers: ArUco markers / QR codes detected and used; inliers: corner points in the final PnP.
    reprojection_error: RMS pixels of the final solution (nan if none).
    object_points (N,3) world metres / image_points (N,2) distorted pixels: the inlier correspondences.
    anchors_seen: indices into the anchors list; ms: processing time of this frame.
    covered: the pose rests on markers whose white margin is partly covered (a hand reaching in): its
    corners may be off by pixels, the filter gave it little weight, and a caller with another source
    of pose (map, optical flow) should prefer that one.
    refitted: a marker's margin was partly covered, but its corners were found again on the uncovered
    parts of its edges (AnchorTracker._refit_covered); the measurement counts `refit_weight` in the filter.
    rejected: anchors (indices) detected this frame but left out as inconsistent: never seen before
    in this session and far from where the reference pose puts them (a look-alike pattern).
    ambiguous: the pose rests on a lone marker whose two IPPE poses both fit (small, seen nearly head-on)
    and the desk around it has not yet decided between them (`desk.DeskPlane`): its tilt may be off by
    degrees; tilting the camera (or moving it sideways) decides. desk: the pose was fitted to the marker
    and the desk keypoints around it together (decided).
    """

    world_from_camera: np.ndarray | None = None
    raw_world_from_camera: np.ndarray | None = None
    markers: int = 0
    inliers: int = 0
    reprojection_error: float = float("nan")
    object_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    image_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    anchors_seen: list[int] = field(default_factory=list)
    ms: float = 0.0
    covered: bool = False
    refitted: bool = False
    rejected: list[int] = field(default_factory=list)
    ambiguous: bool = False
    desk: bool = False
