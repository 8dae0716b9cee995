"""The combined tracker: anchors (markers, boards, QR codes) fused with keypoint SLAM and optical flow.

tracker (`Tracker`: the per-frame steps by name), config (`TrackerConfig`), state (the per-frame
`FrameState`, `TrackStatus`, `AnchorMemory`, `TrackResult`), handover (which of anchors / map / flow
carries a frame), fits (a full frame's pose fits), flow_follow (optical flow from the last frame), output
(the pose shown, faded at seams), keyframes (when a frame becomes a keyframe), moving (anchors that move in
the room), image (a frame made ready for tracking).
"""

from tracking.fusion.config import TrackerConfig
from tracking.fusion.state import TrackResult
from tracking.fusion.tracker import Tracker

__all__ = ["Tracker", "TrackerConfig", "TrackResult"]
