"""Anchors: ArUco markers, GridBoards, ChArUco boards and QR codes -> the camera's pose in the world.

Public API: AnchorTracker (per-frame pose, filtered and raw, with the correspondences used),
AnchorResult, plain_opencv_pose (the plain OpenCV baseline), PoseFilter (the SE(3) filter).
Modules: kinds (the anchor kinds: fields, geometry, drawing, words), model (anchor geometry), detect (ArUco/ChArUco detection and marker tracking), edges (subpixel
corners by edge fitting), qr (QR decode + finder-corner tracking), pose (IPPE hypotheses, fused PnP,
outlier rejection, LM), filter, tracker (result: its AnchorResult; plain: the plain OpenCV baseline; hold:
the filtered pose held to the corners; desk: the desk around a lone head-on marker judging its tilt),
diagnose (why anchors are not found), render (synthetic views and the drawing used by printable sheets).
"""

import importlib

# Loaded on first use, not here: session.py reads anchor blocks through tracking.anchors.kinds, and the
# tracker imports session.py, so importing the tracker with this package would make a cycle.
_LAZY = {"PoseFilter": "tracking.anchors.filter", "AnchorTracker": "tracking.anchors.tracker",
         "AnchorResult": "tracking.anchors.result", "plain_opencv_pose": "tracking.anchors.plain"}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["AnchorTracker", "AnchorResult", "plain_opencv_pose", "PoseFilter"]
