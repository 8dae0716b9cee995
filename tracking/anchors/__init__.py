"""Anchors: ArUco markers, GridBoards, ChArUco boards and QR codes -> the camera's pose in the world.

Public API: AnchorTracker (per-frame pose, filtered and raw, with the correspondences used),
AnchorResult, plain_opencv_pose (the plain OpenCV baseline), PoseFilter (the SE(3) filter).
Modules: model (anchor geometry), detect (ArUco/ChArUco detection and marker tracking), edges (subpixel
corners by edge fitting), qr (QR decode + finder-corner tracking), pose (IPPE hypotheses, fused PnP,
outlier rejection, LM), filter, tracker, diagnose (why anchors are not found), render (synthetic views
and the drawing used by printable sheets).
"""

from tracking.anchors.filter import PoseFilter
from tracking.anchors.tracker import AnchorResult, AnchorTracker, plain_opencv_pose

__all__ = ["AnchorTracker", "AnchorResult", "plain_opencv_pose", "PoseFilter"]
