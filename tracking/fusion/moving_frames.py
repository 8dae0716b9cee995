"""The combined tracker's frames while its anchors may move in the room (a card held up to a webcam), kept
apart from `tracking.fusion.tracker` for size: `Tracker` inherits them and they work on its state (`frame`,
`status`, `motion`, `flow`, `room`, `handover`, `anchor_tracker`, its `_finish` and `_lost_frame`). The
still-room frames and the pieces they share stay in tracker.py."""

from __future__ import annotations

from tracking.fusion.handover import anchor_output, anchor_usable, precise
from tracking.fusion.state import TrackResult
from tracking.slam.anchor_motion import disagrees
from tracking.slam.flow import relift
from tracking.slam.frame_pose import position_spread


class MovingAnchorFrames:
    """`Tracker`'s frames for anchors that move, or may move, in the room (`MovingAnchors`)."""

    def _unread_while_suspect(self, markers: int) -> TrackResult:
        """The anchors are not read while a check that found them moving in the room waits to be confirmed
        (`MovingAnchors.suspects`): the room's points must not carry a card that may be swinging. One frame of
        flow on points of the anchors (as once they move) and one on the room's (map points, plane seeds) from
        the last frame: the room's carries when the two agree (`anchor_motion.disagrees` at 1 px: the card
        stood still in the room, the check was a one-off), else the anchors'; without the anchors' the frame
        is lost."""
        frame, K = self.frame, self.camera.K
        frame.flow_ran = False   # (one of the flows may have run beside the anchors already)
        card = self._follow_on_anchors()
        frame.flow_ran = False
        room = self._follow_from_last()
        if card is None:
            if self.status.lost == 0:
                self.anchor_tracker.reset()   # (as once they move: a filter carried over would lag the card)
            return self._lost_frame(markers)
        got = card
        if room is not None and not disagrees(card[0], room[0], position_spread(K, card[0], card[1].X, 1.0),
                                              position_spread(K, room[0], room[1].X, 1.0)):
            got = room
        frame.followed = got
        return self._flow_result(got, markers)

    def _moving_anchor_frame(self) -> TrackResult:
        """A frame once the anchors move in the room (`anchors_moving`): the anchors' pose when they are measured
        (with the start and smear checks of the still case), else optical flow on points of the anchors
        themselves (`FlowFollower.follow_on_anchors`), else lost: nothing of the room carries the pose."""
        t = self.frame.t
        ar, got = self._measure_anchors(self._follow_on_anchors)
        markers = int(ar.markers)
        if anchor_usable(ar):
            pose = anchor_output(ar)
            usable, got = self._moving_anchors_hold(ar, pose, got)
            if usable:
                self.flow.tracks = None if got is None else relift(self.camera, got[1], pose)
                return self._finish(pose, self.motion.predict(t), "marker", "anchors", None, markers,
                                    int(ar.inliers), precise=precise(ar))
        if not self.room.moving:
            return self._unread_while_suspect(markers)
        if got is None:
            got = self._follow_on_anchors()
        if got is not None:
            return self._flow_result(got, markers)
        if self.status.lost == 0:
            # the card moves unseen (a swing): the anchors' filter state and tracked corners are stale, and a
            # filter that carried them over would lag the card's new place by centimetres when it is read again
            self.anchor_tracker.reset()
        return self._lost_frame(markers)

    def _moving_anchors_hold(self, ar, pose, got) -> tuple[bool, tuple | None]:
        """(whether the moving anchors' usable pose `pose` carries this frame, the flow on the anchors when it
        ran): not when they cannot start the pose, are implausible, or the flow on them holds better."""
        h, frame, t = self.handover, self.frame, self.frame.t
        if self.status.lost > 0 or self.motion.last is None:
            if h.board_fit(ar) is None:
                # a lone marker or QR code after a swing: nothing else can carry the card, and its smeared
                # reading is what plain detection shows (the sharpness rule waits for a camera's next,
                # sharper frames; a card keeps swinging); a board's smeared start reads centimetres off
                return True, got
            return not h.cannot_start(ar, frame), got
        if not h.plausible(pose, self.motion.last, t) or h.start_uncertain(ar, frame):
            # a board smeared at a swing's start reads centimetres off: the points on it, else lost
            return False, got
        if got is None and h.moving_fast(ar, t):
            got = self._follow_on_anchors()
        if got is not None and (h.smeared(ar, got, frame.gray, t, self.anchor) or h.partial_view(ar)
                                or h.flow_holds_better(ar, got, t, self.anchor)):
            return False, got   # the points on the anchors, followed from the last frame, hold better
        return True, got
