"""Anchors that move in the room (a card held up to a webcam): on keypoint frames the background (ORB
features off the anchors between two checked frames, and the map's points off them) is tested against the
anchors' poses (`tracking.slam.anchor_motion`), and for a lone marker or QR code, whose pose is too loose for
that, in pixels: whether the background stood still while the anchors' corners moved. Once it disagrees
(twice within `MOVED_WINDOW` frames, or once beyond doubt), `MovingAnchors.moving` turns on for the rest of
the session and the tracker drops its map. While a first disagreement waits for its confirmation
(`MovingAnchors.suspects`), and for a while after a two-view test that could not say (`checks_often`), the
tracker checks every frame the anchors are read on; while one waits, the room's own fit does not carry a frame
they are not read on."""

from __future__ import annotations

import numpy as np

from tracking.camera import Camera
from tracking.fusion.handover import Handover, fits_well
from tracking.poses import rotation_angle
from tracking.slam.anchor_motion import (MIN_BACKGROUND, background_rigid, background_shift, disagrees, on_anchor,
                                         outline_region)
from tracking.slam.frame_pose import position_spread

# checks in a row on which the background map disagrees with the anchors (`anchor_motion.disagrees`) before
# the anchors count as moving in the room: one check can meet a flipped lone marker or a map point mismatch
MOVED_CHECKS = 2
# frames within which a disagreeing check must be confirmed by the next one, else it is forgotten; while one
# waits (`MovingAnchors.suspects`) every frame with the anchors is checked (the tracker extracts keypoints on
# each): a card drifting only half a second before a swing gives one check before the swing, and the next,
# ten frames later, came only after the still room had carried the card across the swing
MOVED_WINDOW = 15
# pixels: the noise taken for a lone marker's or QR code's corners in its expected error (their residual
# says nothing: four corners fit a pose to hundredths of a pixel whatever its error)
MARKER_SIGMA_PX = 0.5
# the background's two-view test (`anchor_motion.background_rigid`): the share of background matches no indoor
# depth explains above which a check counts against the anchors (a few mismatches, a hand, are below it);
# under a fifth, with the anchors' pose turned by MOVED_TURN_DEG or moved MOVED_SHIFT_M since, counts for them
MOVED_MISS = 0.5
MOVED_TURN_DEG = 1.5
MOVED_SHIFT_M = 0.03
MOVED_SURE = 0.9   # ... and above which, on 3 * MIN_BACKGROUND matches or more, one check is enough
# the still-background test for a lone marker or QR code (`_still_background_verdict`): the background's
# matches moved STILL_SHIFT_PX or less (median), STILL_SHARE of them less than `anchor_motion.STILL_PX`, while
# the anchors' corners moved STILL_MOVED_PX or more (median)
STILL_SHIFT_PX = 0.5
STILL_SHARE = 0.6
STILL_MOVED_PX = 4.0
STILL_SURE = 2.5   # ... times which, on 3 * MIN_BACKGROUND matches or more, one check is enough
MOVED_REF_FRAMES = 45   # frames after which the test's earlier frame is too old to compare with


class MovingAnchors:
    """Whether the anchors move in the room (`moving`), from checks of the background against them.
    `track_map(init, X, D, feats)`: the tracker's map-only fit (`PoseFits.track_map`)."""

    def __init__(self, camera: Camera, handover: Handover, track_map, min_inliers: int):
        self.camera = camera
        self.handover = handover
        self.track_map = track_map
        self.min_inliers = min_inliers
        self.moving = False   # the anchors were seen to move in the room: map off, flow on them
        self.votes = 0        # background-map checks in a row that disagreed with the anchors
        self.voted_at = -1    # the frame of the last check that disagreed
        self.background_vote = False   # ... and whether the background's own test cast it (not the map's)
        # ... on many matches (3 x MIN_BACKGROUND): only then is it suspected at once (`suspects`); across a
        # fast pan a frame compared with one from before it mismatches most of the few background features both
        # hold, and every frame's keypoint work until the next check would follow for nothing
        self.many = False
        self.doubted_at = -MOVED_WINDOW - 1   # the frame of the last two-view test that could not say
        self.ref_agreed = False   # the background agreed with the anchors between `ref` and the frame before it
        self.strong = False   # the last check that disagreed did so beyond doubt (MOVED_SURE)
        self.ref: tuple | None = None   # (frame, Features, anchors' pose, their outline px) to compare with
        # (frame, Features, the anchors' corners in the image px, their outline px) for the still-background test
        self.still_ref: tuple | None = None

    def check(self, ar, anchor_pose, corners_w, feats, X, D, frame: int, steady: bool) -> bool:
        """Compare the anchors' pose this frame with the pose the map's points off the anchors give, fitted
        from it; when they disagree beyond both fits' expected errors (`anchor_motion.disagrees`) on
        `MOVED_CHECKS` checks in a row, the anchors move in the room. `steady`: tracked on the last frame with
        a velocity of 3+ steps (the background's two-view test needs it). True when the anchors turned out
        to move on this very check (the caller drops the map, which holds the room)."""
        if self.moving or len(feats) < self.min_inliers or ar.covered:
            return False
        if self.votes and frame - self.voted_at > MOVED_WINDOW:
            self.votes = 0   # not confirmed in time: a one-off (a mismatch, a hand), forgotten
        # only a board that fits well holds its turn to a few hundredths of a degree; a lone marker's pose turns
        # by a degree with its noise (5-9 px at the image edge: a still desk then reads as moving), so a lone
        # marker is compared with the background in pixels instead
        board = self.handover.board_fit(ar) is not None
        verdict = (self._background_verdict(anchor_pose, feats, frame)
                   if steady and board and fits_well(ar) else None)
        if verdict is None and not board:
            verdict = self._still_background_verdict(anchor_pose, corners_w, feats, frame)
        by_background = verdict is not None
        off = ~on_anchor(X, self.handover.anchors.outlines)
        if verdict is None and off.sum() >= self.min_inliers:
            p, pi, _, inl = self.track_map(anchor_pose, X[off], D[off], feats)
            if p is not None:
                map_spread = position_spread(self.camera.K, p, X[off][pi[inl]], 1.0)
                spread = self.handover.anchor_spread(ar)
                if spread is None:
                    spread = position_spread(self.camera.K, anchor_pose, corners_w, MARKER_SIGMA_PX)
                verdict = disagrees(anchor_pose, p, spread, map_spread)
                if not verdict and self.votes and self.background_vote:
                    # under its floor (`anchor_motion.MOVED_FLOOR_M`) the map's test cannot tell a card that
                    # began to drift from a still one: it does not clear the background's disagreement
                    verdict = None
        if verdict is None:
            return False   # the background is not matched here: no verdict either way
        if not verdict:
            self.votes = 0
            return False
        self.votes += 1
        self.voted_at, self.background_vote = frame, by_background
        if self.votes >= MOVED_CHECKS or self.strong:
            self.moving = True
        return self.moving

    def suspects(self, frame: int) -> bool:
        """Whether a check disagreed and waits, on `frame`, for the next to confirm it (within `MOVED_WINDOW`
        frames): the tracker checks every frame with the anchors until then."""
        return (not self.moving and self.votes > 0 and frame - self.voted_at <= MOVED_WINDOW
                and (self.many or not self.background_vote))

    def checks_often(self, frame: int) -> bool:
        """Whether the anchors are to be checked on every frame they are read on (not only on keypoint frames):
        while a disagreement waits (`suspects`), and for `MOVED_WINDOW` frames after a two-view test that could
        not say (a share of the background between `MOVED_MISS` and a fifth against the anchors: a card that
        has only begun to drift)."""
        return self.suspects(frame) or (not self.moving and frame - self.doubted_at <= MOVED_WINDOW)

    def _still_background_verdict(self, anchor_pose, corners_w, feats, frame: int) -> bool | None:
        """The still-background test for a lone marker or QR code (whose four corners hold the pose too
        loosely to compare poses), in pixels and without any pose: between an earlier checked frame and
        this one, the background (`anchor_motion.background_shift`) stood still while the anchors' corners
        moved by STILL_MOVED_PX or more: the camera is still and the anchors move in the room. None when it
        cannot say (the background moved: a moving camera, left to the map's test; or the corners did not
        move enough yet: the earlier frame is kept so that the motion adds up)."""
        region = outline_region(self.camera, anchor_pose, self.handover.anchors.outlines)
        px = self.camera.project_world(np.asarray(corners_w, float).reshape(-1, 3), anchor_pose)
        now = (frame, feats, px, region)
        ref = self.still_ref
        if ref is None or frame - ref[0] > MOVED_REF_FRAMES or len(ref[2]) != len(px):
            self.still_ref = now
            return None
        n, shift, still = background_shift((ref[1], None, ref[3]), (feats, None, region))
        moved = float(np.median(np.linalg.norm(px - ref[2], axis=1)))
        if n < MIN_BACKGROUND or not (shift <= STILL_SHIFT_PX and still >= STILL_SHARE):
            self.still_ref = now
            return None
        if moved < STILL_MOVED_PX:
            return None
        self.still_ref = now
        # a still background on many matches while the corners moved well past their noise: no doubt
        self.strong = n >= 3 * MIN_BACKGROUND and moved >= STILL_SURE * STILL_MOVED_PX
        return True

    def _background_verdict(self, anchor_pose, feats, frame: int) -> bool | None:
        """The background's two-view test (`anchor_motion.background_rigid`) between this frame and an earlier
        checked one: True when most background matches move as no point rigid with the anchors could, False
        when nearly all do while the anchors' pose changed enough to tell, None when it cannot say yet (the
        earlier frame is then kept, so the motion adds up)."""
        region = outline_region(self.camera, anchor_pose, self.handover.anchors.outlines)
        now = (frame, feats, anchor_pose, region)
        ref = self.ref
        if ref is None or frame - ref[0] > MOVED_REF_FRAMES:
            self.ref = now
            return None
        turned = np.degrees(rotation_angle(ref[2][:3, :3].T @ anchor_pose[:3, :3]))
        shifted = float(np.linalg.norm(ref[2][:3, 3] - anchor_pose[:3, 3]))
        if not (turned > MOVED_TURN_DEG or shifted > MOVED_SHIFT_M):
            return None   # too little motion to tell from the anchors' own noise: the motion adds up
        n, miss = background_rigid(self.camera.K, ref[1:], now[1:])
        if n < MIN_BACKGROUND:
            return None
        if miss > MOVED_MISS:
            # nearly the whole background against the anchors, on many matches: no mismatch or hand does that
            self.strong = miss > MOVED_SURE and n >= 3 * MIN_BACKGROUND
            self.many = n >= 3 * MIN_BACKGROUND
            if not (self.ref_agreed and n >= 3 * MIN_BACKGROUND and self.votes == 0):
                self.ref, self.ref_agreed = now, False
            # (else the earlier frame, which its own check found rigid with the room, stays the one to compare
            # with: the confirming check, a frame or a few on, needs no new motion to add up first. Not after a
            # disagreement on few matches: across a fast pan, a frame compared with one from before it mismatches
            # most of the few background features both hold, and would again on the next frame)
            return True
        self.ref, self.ref_agreed = now, miss < 0.2
        if miss >= 0.2:
            self.doubted_at = frame   # neither rigid nor against: the next frames tell
            return None
        return False
