"""The hand-over rules: which of the anchors, the map and the optical flow carries a frame.

The anchors' measurement is shown when it can be trusted; these rules say when it cannot: smeared by a
fast pan (`smeared`), a board seen in part at the image edge (`partial_view`), a board that reads worse
than a frame of flow is expected to (`flow_holds_better`), a lone marker's corner that jumped while the
scene did not (`jumped`, `flow_disagrees`), anchors too soft or too uncertain to start the pose from
(`cannot_start`). `Handover` holds the tracker's long-lived parts the rules read (settings, camera, the
anchor tracker's anchor models, the motion model); everything of the moment comes in as arguments, so
tests call the rules directly. The pure functions at the top read one anchor result (`AnchorResult` of
`tracking.anchors`) alone.
"""

from __future__ import annotations

import numpy as np

from tracking.anchors.edges import edge_sharpness
from tracking.camera import Camera
from tracking.fusion.config import TrackerConfig
from tracking.fusion.state import AnchorMemory, FrameState
from tracking.slam.frame_pose import MotionModel, plausible, position_spread

# pixels: RMS reprojection error up to which a board's (12+ corners) own pose is shown as measured; sharp
# boards fit to 0.1-0.3 px, boards smeared by a fast pan to 0.6-1 px
PRECISE_RMS_PX = 0.6
# the most the camera position's spread per corner may grow over that of the anchors' whole outline before
# the anchors seen count as a partial view (they do not start the pose, and lose to the flow when smeared)
PARTIAL_VIEW = 1.8
# the most a board's first pose may be expected to be off (its camera position's spread with its own RMS
# residual as the pixel noise), as a fraction of the camera's distance from it, to start the pose: four
# smeared markers caught mid-pan fit to ~1 px and read ~2 cm off at 0.5 m; a board that fits to 0.7 px
# on seven markers, ~1 %, reads 2 mm off
START_SPREAD = 0.015
# `edge_sharpness` (about 1/pixels of smear) from which a board counts as sharp for START_SPREAD: only a
# smeared board is held back (the next frames of a moving camera are sharper); a sharp one that fits poorly
# (curved paper, a print's errors) fits no better a frame later and starts the pose. Sharp boards on the
# tuning recordings measure 0.30-0.42 across x and y, the smeared starts of the fast pans 0.14-0.25.
START_SHARP = 0.28
# metres a frame the flow's camera position drifts from the anchors' pose it started from, to weigh the flow
# against a board's measurement (`flow_holds_better`): on the tuning pans' flow stretches the error grows
# by 0.1-0.4 mm a frame; 0.2 and 0.3 mm gave the same tracking on them, 0.5 took bad boards back too often
FLOW_DRIFT_M = 0.0003


def anchor_usable(ar) -> bool:
    """The anchors' own pose can be shown as it is: measured this frame on enough corners, none of
    them on a partly covered marker."""
    return (ar is not None and ar.world_from_camera is not None and ar.raw_world_from_camera is not None
            and len(ar.object_points) >= 4 and not ar.covered)


def precise(ar) -> bool:
    """The anchors' pose this frame rests on 12 or more corners, none partly covered (a board: the output
    fades onto it over `precise_blend_frames`)."""
    return ar is not None and not ar.covered and len(ar.object_points) >= 12


def fits_well(ar) -> bool:
    """The anchors' corners this frame are 12 or more and fit their pose to `PRECISE_RMS_PX`."""
    return len(ar.object_points) >= 12 and ar.reprojection_error <= PRECISE_RMS_PX


def anchor_output(ar) -> np.ndarray:
    """The anchors' pose to show: a board's or QR code's many corners are precise as measured (the
    filter would only add lag on a moving camera); a lone marker's four, or a board's corners that fit
    poorly (smeared), are smoothed by its filter, which weighs smeared measurements less."""
    return np.asarray(ar.raw_world_from_camera if fits_well(ar) else ar.world_from_camera, float)


class Handover:
    """The hand-over rules (see the module docstring). `anchors`: the anchor tracker (its `models` and
    `outlines`); `motion`: the tracker's motion model (its last pose and prediction)."""

    def __init__(self, config: TrackerConfig, camera: Camera, anchors, motion: MotionModel):
        self.config = config
        self.camera = camera
        self.anchors = anchors
        self.motion = motion

    # -- the pose's own plausibility -------------------------------------------------------------------
    def plausible(self, pose, ref, t, lost: bool = False) -> bool:
        """Whether `pose` can follow `ref` (the last pose) at time t: no teleports (`max_speed`,
        `max_angular`); `lost`: after a gap, the walking-pace bounds of a relocalisation."""
        if ref is None:
            return True
        last_t = self.motion.last_t
        dt = (t - last_t) if last_t is not None else 0.0
        cfg = self.config
        if lost:
            # after a gap the camera may have moved, but not further than walking pace allows
            return plausible(pose, ref, dt, cfg.max_speed, cfg.max_angular, 0.10, 0.5)
        return plausible(pose, ref, dt, cfg.max_speed, cfg.max_angular)

    # -- the anchors against the flow ------------------------------------------------------------------
    def smeared(self, ar, got, gray, t, memory: AnchorMemory) -> bool:
        """Whether the anchors' measurement this frame is to be distrusted in favour of the flow pose
        `got` (see smear_px / smear_sharpness / smear_gate_px / smear_hold_s): recently anchored, the
        image moved fast (the flow measures it without any pose), the markers' edges are smeared
        along that motion, and either the corners do not fit well (`fits_well`) or the flow pose
        disagrees with them."""
        cfg = self.config
        if got is None or memory.t is None or t - memory.t > cfg.smear_hold_s:
            return False
        motion = got[1].image_motion()
        if motion is None or np.linalg.norm(motion) < cfg.smear_px:
            return False
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        if not edge_sharpness(gray, seen, motion) < cfg.smear_sharpness:
            return False   # sharp (or unmeasurable) markers are measured where they are
        if not fits_well(ar) or self.partial_view(ar):
            # a smeared board's corners can sit within a pixel of the flow's and still tilt its pose by
            # a centimetre; a pose from a few markers' or from poorly fitting corners loses to the flow
            return True
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        gap = float(np.median(np.linalg.norm(self.camera.project_world(corners, got[0]) - seen, axis=1)))
        return gap > cfg.smear_gate_px

    def anchor_spread(self, ar, min_px: float = 0.05) -> float | None:
        """The expected error (metres) of the camera position the anchors measured this frame: the
        position's spread (`position_spread`) with the fit's own RMS residual, scaled to its degrees of
        freedom (at least `min_px`), as the pixel noise. Only for boards: a lone marker's or QR code's four
        corners fit to hundredths of a pixel whatever their error, so their residual says nothing. None
        when not a board."""
        board = self.board_fit(ar)
        if board is None or len(board[1]) < 4 or not np.isfinite(ar.reprojection_error):
            return None
        pose, seen = board
        n = len(seen)
        sigma = max(ar.reprojection_error * np.sqrt(2 * n / max(2 * n - 6, 1)), min_px)
        return position_spread(self.camera.K, pose, seen, sigma)

    def flow_holds_better(self, ar, got, t: float, memory: AnchorMemory) -> bool:
        """Whether the flow's pose `got` is expected closer to the truth than the anchors' this frame: the
        anchors' expected error (`anchor_spread`) exceeds the flow's, which is that of the anchors' pose it
        started from (`memory.spread`) plus `FLOW_DRIFT_M` for each frame since. A board going out of view
        (a pan speeding up: a few markers, smeared, at the image edge) reads millimetres to centimetres off
        while the flow, one frame after a sharp board, is within a millimetre; the flow's points would
        otherwise be placed on the plane again from the worse pose and carry its error through the whole
        pan. Only while the anchors' last pose is recent (`smear_hold_s`) and was a board's."""
        if (got is None or ar is None or memory.spread is None or memory.t is None
                or t - memory.t > self.config.smear_hold_s):
            return False
        spread = self.anchor_spread(ar)
        return spread is not None and spread > memory.spread + FLOW_DRIFT_M * (memory.since + 1)

    def jumped(self, ar, t) -> bool:
        """Whether a corner of a lone marker (4 points: one wrong corner does not show in its reprojection
        error, and 1 px on one corner tilts a 70-pixel marker's pose by centimetres at 45 cm) is more
        than `jump_px` from where the motion model predicts it: a jump to be checked
        against the image's own motion (optical flow) before it is shown."""
        cfg, motion = self.config, self.motion
        if cfg.jump_px <= 0 or not cfg.flow or motion.last is None or len(ar.object_points) > 4:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        pred = self.camera.project_world(corners, motion.predict(t))
        # only on a steady camera: while it moves, a pixel is within what the prediction misses, and
        # flow over repeated texture can lock onto a look-alike that agrees with the prediction
        moved = np.linalg.norm(pred - self.camera.project_world(corners, motion.last), axis=1).max()
        if moved > 0.5 * cfg.smear_px:
            return False
        return float(np.linalg.norm(pred - seen, axis=1).max()) > cfg.jump_px   # a dragged corner moves alone

    def flow_disagrees(self, ar, got, t, memory: AnchorMemory) -> bool:
        """Whether the flow pose `got` (the image's own motion since the last frame) puts a jumped lone
        marker's corners more than `jump_px` from where they were detected while agreeing with the motion
        model's prediction better than the marker does: the marker moved, the scene did not. Only within
        `smear_hold_s` of the anchors' last accepted frame (after that they win again)."""
        cfg = self.config
        if got is None or memory.t is None or t - memory.t > cfg.smear_hold_s:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        flow_px = self.camera.project_world(corners, got[0])
        pred_px = self.camera.project_world(corners, self.motion.predict(t))
        to_seen = float(np.linalg.norm(flow_px - seen, axis=1).max())
        to_pred = float(np.linalg.norm(flow_px - pred_px, axis=1).max())
        # the flow must confirm the prediction to within a pixel: a flow pose that merely leans toward it
        # (drifting over repeated texture) proves nothing against a marker
        return to_seen > cfg.jump_px and to_pred < min(0.5 * to_seen, cfg.jump_px)

    def flow_over_anchors(self, ar, got, jumped: bool, frame: FrameState, memory: AnchorMemory) -> str | None:
        """Whether the flow's pose `got` carries this frame instead of anchors that are usable and plausible:
        "smeared" (the anchors are smeared, or a jumped marker's corner disagrees with the flow), "better"
        (the flow holds the position better: the seam fades from the anchors' pose), or None (the anchors)."""
        t = frame.t
        if self.smeared(ar, got, frame.gray, t, memory) or (jumped and self.flow_disagrees(ar, got, t, memory)):
            return "smeared"
        if self.flow_holds_better(ar, got, t, memory):
            return "better"
        return None

    def flow_keeps(self, ar, got, usable: bool, frame: FrameState, memory: AnchorMemory) -> bool:
        """Flow carried the last frame: whether its pose `got` carries this one too, against the anchors
        measured now (`usable`: usable and plausible). A board seen in part as it comes back (one marker at
        the image edge, sharp at a pan's turn) can read centimetres off (its tilt and the camera's shift
        trade off): it does not take over from the flow."""
        t = frame.t
        return got is not None and (not usable or self.smeared(ar, got, frame.gray, t, memory)
                                    or self.partial_view(ar) or self.flow_holds_better(ar, got, t, memory)
                                    or (self.jumped(ar, t) and self.flow_disagrees(ar, got, t, memory)))

    # -- how far the anchors move in the image -----------------------------------------------------------
    def corner_motion(self, corners: np.ndarray, *poses: np.ndarray) -> float:
        """How far (pixels, the most of any) world points `corners` (N,3) move in the image from the last
        pose (`motion.last`) to `poses` (world_from_camera; the most over them)."""
        last = self.camera.project_world(corners, self.motion.last)
        return max(float(np.linalg.norm(self.camera.project_world(corners, p) - last, axis=1).max()) for p in poses)

    def moving_fast(self, ar, t) -> bool:
        """Whether the anchors may have moved more than smear_px in the image since the last frame, by the
        motion model or by their own raw measurement (the model lags when the camera turns around, and so
        does a lone marker's filtered pose)."""
        if not self.config.flow or self.motion.last is None:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        measured = ar.raw_world_from_camera if ar.raw_world_from_camera is not None else anchor_output(ar)
        moved = self.corner_motion(corners, self.motion.predict(t), np.asarray(measured, float))
        return moved >= self.config.smear_px

    # -- what the anchors seen hold ------------------------------------------------------------------------
    def partial_view(self, ar) -> bool:
        """Whether the anchors' corners seen this frame hold the camera position much worse than the anchors
        they belong to would whole: the position's spread per corner (`position_spread`, times the square
        root of the corner count) over that of the anchors' whole outline at the same pose exceeds
        `PARTIAL_VIEW`. A board's last few markers at the image edge read centimetres off (their tilt
        and the camera's shift trade off); a whole board is about 1. Only boards can be seen in part."""
        board = self.board_fit(ar)
        if board is None:
            return False   # markers and QR codes are seen whole or not at all
        pose, seen = board
        K = self.camera.K
        whole = np.concatenate([self.anchors.outlines[i] for i in ar.anchors_seen])
        spread_seen = position_spread(K, pose, seen, 1.0) * np.sqrt(len(seen))
        spread_whole = position_spread(K, pose, whole, 1.0) * np.sqrt(len(whole))
        # an outline partly behind the camera (inf) says nothing: not partial
        return bool(np.isfinite(spread_whole) and spread_seen > PARTIAL_VIEW * spread_whole)

    def board_fit(self, ar) -> tuple[np.ndarray, np.ndarray] | None:
        """(the anchors' raw pose this frame, world_from_camera; the world corners (N,3) it was fitted to) when
        the anchors seen include a board; None otherwise."""
        pose = ar.raw_world_from_camera
        if pose is None or not any(len(self.anchors.models[i].markers) > 1 for i in ar.anchors_seen):
            return None
        return np.asarray(pose, float), np.asarray(ar.object_points, float).reshape(-1, 3)

    # -- starting the pose ---------------------------------------------------------------------------------
    def cannot_start(self, ar, frame: FrameState) -> bool:
        """Whether anchors measured while nothing holds the pose (the first sighting, after a loss) must not
        start it: too smeared, seen in part, or a board whose pose is too uncertain."""
        return self.too_smeared_to_start(ar, frame) or self.partial_view(ar) or self.start_uncertain(ar, frame)

    def too_smeared_to_start(self, ar, frame: FrameState) -> bool:
        """Whether the anchors' edges are too soft across x or y (`start_sharpness`) to start the pose from
        them alone. Nothing says which way the camera moves yet, so both directions are measured."""
        if self.config.start_sharpness <= 0:
            return False
        return bool(self.start_sharpness(ar, frame) < self.config.start_sharpness)   # NaN (unmeasurable): start

    def start_sharpness(self, ar, frame: FrameState) -> float:
        """The anchors' edge sharpness this frame (`edge_sharpness`), the lower of across x and across y;
        measured once a frame (kept in `frame.sharpness`) for the start checks."""
        if frame.sharpness is None:
            seen = np.asarray(ar.image_points, float).reshape(-1, 2)
            sharp = [edge_sharpness(frame.gray, seen, np.array(d)) for d in ((1.0, 0.0), (0.0, 1.0))]
            frame.sharpness = min(sharp)
        return frame.sharpness

    def start_uncertain(self, ar, frame: FrameState | None = None) -> bool:
        """Whether a smeared board's pose this frame is expected to be off by more than `START_SPREAD` of the
        camera's distance from it: the camera position's spread (`position_spread`) with the fit's own RMS
        residual, scaled to the residual's degrees of freedom, as the pixel noise. With `frame` (its grey
        image), boards whose edges are sharp across x and y (`START_SHARP`) are never held back. Markers and
        QR codes (four corners fit to a few hundredths of a pixel whatever their error) are left to
        `start_sharpness`."""
        spread = self.anchor_spread(ar, min_px=0.0)
        if spread is None:
            return False
        pose, seen = self.board_fit(ar)
        if not spread > START_SPREAD * float(np.linalg.norm(pose[:3, 3] - seen.mean(axis=0))):
            return False
        if frame is None:
            return True
        return bool(self.start_sharpness(ar, frame) < START_SHARP)   # NaN (unmeasurable): not held back
