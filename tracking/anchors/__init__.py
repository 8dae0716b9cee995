"""Anchors: ArUco markers, GridBoards, ChArUco boards and QR codes -> the camera's pose in the world.

Public API: AnchorTracker, AnchorResult, plain_opencv_pose (the plain OpenCV baseline), PoseFilter,
render_view (synthetic views with a known pose). See tracker.py.
"""

from tracking.anchors.filter import PoseFilter
from tracking.anchors.tracker import AnchorResult, AnchorTracker, plain_opencv_pose

__all__ = ["AnchorTracker", "AnchorResult", "plain_opencv_pose", "PoseFilter"]
