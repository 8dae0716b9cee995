"""Optical flow from the last tracked frame (`tracking.slam.flow`): between full frames on the last full
frame's inlier map points (`FlowFollower.between_full_frames`), and as a pose source of its own when the
anchors and the map fail (`follow_from_last`), or, once the anchors move in the room, on points of the
anchors alone (`follow_on_anchors`). `FlowFollower` keeps the points it follows and the last tracked
frame's grey image."""

from __future__ import annotations

import numpy as np

from tracking.camera import Camera
from tracking.fusion.config import TrackerConfig
from tracking.fusion.handover import Handover
from tracking.fusion.state import FrameState
from tracking.slam.anchor_motion import on_anchor, outline_region
from tracking.slam.flow import Tracks, follow, seed_on_plane
from tracking.slam.frame_pose import MotionModel, position_spread

MAX_TRACKS = 200  # keypoints followed by optical flow between full frames
FLOW_SEEDS = 300  # points followed by optical flow when the anchors and the map both fail
# the most the flow's camera position on moving anchors may be expected to be off (its spread at 1 px), as a
# fraction of the camera's distance from its points: a board's ~100 points hold it to ~0.2 %, the few
# points of a lone marker's bits drift by centimetres within frames (then lost is the honest answer)
MOVING_FLOW_SPREAD = 0.03


class FlowFollower:
    """The points followed by optical flow (`tracks`, measured in the last tracked frame, whose grey image
    is `prev_gray`), whether flow carried the last frame (`via_flow`, since `flow_start` seconds) and how
    many tracks the last full frame started with (`full_tracks`)."""

    def __init__(self, config: TrackerConfig, camera: Camera, motion: MotionModel, handover: Handover):
        self.config = config
        self.camera = camera
        self.motion = motion
        self.handover = handover
        self.tracks: Tracks | None = None
        self.prev_gray: np.ndarray | None = None
        self.via_flow = False
        self.flow_start: float | None = None
        self.full_tracks = 0

    # -- what the tracker tells it ---------------------------------------------------------------------
    def tracked(self, gray) -> None:
        """A frame got its pose (not by the flow unless `carried` follows): its image is the next one's start."""
        self.prev_gray = gray
        self.via_flow = False

    def stretch_start(self, t: float) -> float:
        """When flow alone began to carry the pose, if it carries the frame at t (before `tracked`)."""
        return self.flow_start if self.via_flow else t

    def carried(self, tracks: Tracks, start: float) -> None:
        """The flow's pose carried the frame, flow alone since `start` (`stretch_start`); `tracks` are
        followed on from it."""
        self.tracks = tracks
        self.via_flow, self.flow_start = True, start

    def lose(self) -> None:
        """A frame without a pose: nothing to follow from."""
        self.tracks = None
        self.prev_gray = None
        self.via_flow = False

    def start_tracks(self, gray, feats, fit) -> None:
        """Keypoints of this full frame (the fit's inlier features and map points) to follow by optical flow
        until the next one."""
        self.tracks = None
        n = fit.feature_idx.size
        if n:
            # a spread subset is plenty for the pose and keeps the flow cheap
            sel = np.arange(n) if n <= MAX_TRACKS else np.linspace(0, n - 1, MAX_TRACKS).astype(int)
            self.tracks = Tracks(gray, feats.xy[fit.feature_idx[sel]].astype(np.float32), fit.points[sel].copy())
        self.full_tracks = int(min(n, MAX_TRACKS))

    # -- following ----------------------------------------------------------------------------------------
    def between_full_frames(self, frame: FrameState) -> tuple[np.ndarray, np.ndarray] | None:
        """Between full frames: follow the last frame's inlier map points by optical flow and refine the
        pose on them (no detection, no descriptors); (pose, the motion model's prediction) or None when
        that is not good enough. The followed points are kept."""
        motion, min_inliers = self.motion, self.config.min_inliers
        if self.tracks is None or motion.last is None:
            return None
        # flow only from a well-supported full frame, and only while most of its tracks survive
        if self.full_tracks < 4 * min_inliers or len(self.tracks) < 0.6 * self.full_tracks:
            return None
        t = frame.t
        pred = motion.predict(t)
        got = follow(self.camera, self.tracks, frame.gray, pred, min_inliers, min_inlier_ratio=0.8,
                     dt=t - motion.last_t)
        if got is None or not self.handover.plausible(got[0], motion.last, t):
            return None
        self.tracks = got[1]
        return got[0], pred

    def follow_from_last(self, frame: FrameState, lost: int) -> tuple[np.ndarray, Tracks] | None:
        """One frame of optical flow from the last tracked frame: its flow points or map inliers,
        topped up with points seeded on the anchors' plane in the last image. (pose, tracks now
        measured in this frame's image), or None when the flow does not hold or the pose is implausible."""
        # computed at most once a frame (also ahead of need, beside the anchors): the state it reads does
        # not change within a frame before the pose is final
        if not frame.flow_ran:
            frame.followed, frame.flow_ran = self._follow(frame, lost), True
        return frame.followed

    def _follow(self, frame: FrameState, lost: int) -> tuple[np.ndarray, Tracks] | None:
        if not self._may_follow(frame, lost):
            return None
        motion, t = self.motion, frame.t
        tracks = self.tracks
        if tracks is None or len(tracks) < FLOW_SEEDS // 2:
            tracks = seed_on_plane(self.camera, self.prev_gray, motion.last, FLOW_SEEDS, keep=tracks,
                                   later=(motion.predict(t), t - motion.last_t))
        got = follow(self.camera, tracks, frame.gray, motion.predict(t), self.config.min_inliers,
                     dt=t - motion.last_t, lifted_from=motion.last, before=motion.last_step())
        if got is None or not self.handover.plausible(got[0], motion.last, t):
            return None
        return got

    def _may_follow(self, frame: FrameState, lost: int) -> bool:
        """Whether the flow may carry this frame: on, tracked on the last frame with a velocity (just
        (re)acquired, a flow started at zero motion can lock onto a look-alike of each point: tiles, any
        repeated texture, and give a wrong pose that holds together), and flow alone has not carried the
        pose for longer than `flow_hold_s`."""
        gray = frame.gray
        return (self.config.flow and lost == 0 and self.motion.velocity is not None and self.prev_gray is not None
                and self.prev_gray.shape == gray.shape
                and not (self.via_flow and frame.t - self.flow_start > self.config.flow_hold_s))

    def follow_on_anchors(self, frame: FrameState, lost: int, outlines) -> tuple[np.ndarray, Tracks] | None:
        """`follow_from_last` for moving anchors: only points on the anchors (their plane, within their
        `outlines`: `anchor_motion.on_anchor`) are followed, seeds are found only inside the anchors' outline
        in the last image; (pose, tracks) or None. Once a frame, like `follow_from_last`."""
        if not frame.flow_ran:
            frame.followed, frame.flow_ran = self._follow_on_anchors(frame, lost, outlines), True
        return frame.followed

    def _follow_on_anchors(self, frame: FrameState, lost: int, outlines) -> tuple[np.ndarray, Tracks] | None:
        if not self._may_follow(frame, lost):
            return None
        motion, t = self.motion, frame.t
        tracks = None if self.tracks is None else self.tracks.subset(on_anchor(self.tracks.X, outlines))
        if tracks is None or len(tracks) < FLOW_SEEDS // 2:
            region = outline_region(self.camera, motion.last, outlines)
            if region is not None:
                tracks = seed_on_plane(self.camera, self.prev_gray, motion.last, FLOW_SEEDS, keep=tracks,
                                       later=(motion.predict(t), t - motion.last_t), region=region)
        if tracks is None or not len(tracks):
            return None
        got = follow(self.camera, tracks, frame.gray, motion.predict(t), self.config.min_inliers,
                     dt=t - motion.last_t, lifted_from=motion.last, before=motion.last_step())
        if got is not None and not self.handover.plausible(got[0], motion.last, t):
            got = None
        if got is not None:
            X = got[1].X
            far = float(np.linalg.norm(got[0][:3, 3] - X.mean(axis=0)))
            if not position_spread(self.camera.K, got[0], X, 1.0) <= MOVING_FLOW_SPREAD * far:
                got = None   # too few points, too close together, to hold the pose
        return got
