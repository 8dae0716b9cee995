"""The tracker's state, in small dataclasses: `FrameState` (this frame only, replaced each frame),
`TrackStatus` (how the frames before went), `AnchorMemory` (the anchors' last accepted pose), and the
frame's outcome `TrackResult`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np


@dataclass
class TrackResult:
    """One frame's outcome. `world_from_camera` None when lost; `markers` anchors' markers detected
    this frame (0 on frames where detection was not run); `inliers` PnP inliers (marker corners +
    map points); `ms` tracking time of the frame in milliseconds."""

    world_from_camera: np.ndarray | None
    state: str
    markers: int
    inliers: int
    ms: float
    ambiguous: bool = False   # the pose rests on a lone head-on marker the desk has not yet judged (issue 25.4)


@dataclass
class FrameState:
    """What belongs to one frame only; `Tracker.process` makes a new one for each frame.

    `index` counts frames from 1 (0 before the first), `t` its time (seconds), `t0` when its tracking
    began (`time.perf_counter`), `gray` its grey image (None when unusable). Filled in during the frame:
    `anchors` the anchor tracker's result when it measured the anchors here (a pose on 4+ corners),
    `sharpness` the anchors' edge sharpness for the start checks (`Handover.start_sharpness`), and
    `followed` one frame of optical flow from the last frame (`(pose, Tracks)` or None), once `flow_ran`:
    the flow runs at most once a frame, also ahead of need beside the anchors."""

    index: int = 0
    t: float = 0.0
    t0: float = 0.0
    gray: np.ndarray | None = None
    anchors: object | None = None
    sharpness: float | None = None
    flow_ran: bool = False
    followed: tuple | None = None
    anchor_motion: tuple | None = None   # (pixels, view share) the anchors move this frame (`SmearGate.measure`)

    def ms(self) -> float:
        """Milliseconds since this frame's tracking began."""
        return (time.perf_counter() - self.t0) * 1000.0


@dataclass
class TrackStatus:
    """How the frames before this one went: `lost` frames in a row without a pose, the last frame's state,
    frames since the anchors were last detected (`since_detect`) and the last full frame (keypoints
    extracted and matched, `full_frame`)."""

    lost: int = 0
    last_state: str = "lost"
    since_detect: int = 10**9
    full_frame: int = -(10**9)


@dataclass
class AnchorMemory:
    """The anchors' last accepted pose: when (`t`, seconds), its expected position error (`spread`, metres;
    boards only, else None), frames since (`since`), whether the output still counts as anchored, and
    the world corners (N,3) the anchors measured last (`corners`, for the motion they predict)."""

    t: float | None = None
    spread: float | None = None
    since: int = 10**9
    anchored: bool = False
    corners: np.ndarray | None = field(default=None, repr=False)
