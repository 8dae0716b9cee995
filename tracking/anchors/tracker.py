"""AnchorTracker: the camera pose from a session's anchors, frame by frame (its result: result.py; the plain
OpenCV baseline: plain.py, both re-exported here)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from tracking.anchors.blur import MIN_MARKERS, fit_pose_and_stretch, marker_groups, marker_offsets, spread_enough
from tracking.anchors.card import CardPoints
from tracking.anchors.desk import DeskPlane
from tracking.anchors.deskew import deskew_observation
from tracking.anchors.diagnose import diagnose as diagnose_image
from tracking.anchors.detect import ArucoDetection, Observation
from tracking.anchors.edges import edge_sharpness
from tracking.anchors.filter import PoseFilter
from tracking.anchors.hold import hold_to_corners
from tracking.anchors.model import AnchorModel, build_models
from tracking.anchors.occlusion import covered_fraction, is_covered, refit_covered
from tracking.anchors.plain import plain_opencv_pose, to_gray  # noqa: F401  (plain_opencv_pose: re-exported)
from tracking.anchors.numeric import median, row_norms
from tracking.anchors.pose import planar_solutions, project, project_pixels, residuals, solve_pose
from tracking.anchors.qr import QRTracking
from tracking.anchors.result import AnchorResult
from tracking.camera import Camera
from tracking.poses import invert, rotation_angle, transform_points
from tracking.anchors.kinds import AnchorSpec


class AnchorTracker:
    """Tracks the camera against a session's anchors (ArUco markers, GridBoards, ChArUco boards, QR codes).

    anchors: the session's anchors (the first defines the world); camera: intrinsics and distortion of the
    images passed to `process`. filter: smooth the output pose (PoseFilter; `filter_params` are its
    min_cutoff, beta, max_gap, jump). roi: detect markers only around where the last pose predicts them,
    with a full-frame search every `full_every` frames. track_markers: between those searches, re-find the
    last frame's markers on their edges where the prediction puts them, without running the detector
    (it falls back to detection when they are not found). outlier_px: reprojection error beyond which a
    corner is an outlier. branch_decay / branch_switch: how evidence for the other IPPE solution of a lone
    marker accumulates before the tracker switches to it (see _other_branch_wins). smear_px /
    smear_sharpness: a measurement whose markers moved `smear_px` pixels or more since the last frame
    and whose edges are smeared along that motion (`edges.edge_sharpness` below `smear_sharpness`)
    counts less in the filter (motion blur biases corners by pixels).
    cover_fraction / cover_weight: an ArUco marker with a side whose white margin is at least
    `cover_fraction` covered (`occlusion.covered_fraction`) is left out when other markers carry the
    pose, else its corners are fitted again on the uncovered parts of its edges, starting from the
    prediction (`_refit_covered`; the measurement then counts `refit_weight` in the filter and the result
    says `refitted`), and where that fails its measurement counts `cover_weight` and the result says
    `covered`.
    unblur_px: when five or more markers spread over the image moved this many pixels since the last
    frame, motion blur's stretch of the markers is fitted together with the pose (blur.py); None: never.
    new_anchor_gate: a frame's anchor never seen before in this session, detected while a reference
    pose exists (the caller's, else the filter's prediction, else the first declared anchor in view),
    is used only if its corners lie within `new_anchor_gate` times its own image size (pixels, the
    geometric mean of its bounding box's sides; at least 20 px) of where the reference puts them; it
    becomes trusted once used. 0 turns the check off.
    lone_end_margin: a lone marker's sides are edge-fitted from this fraction of their length to 1 minus it
    (boards: 0.2), weak steps left out (edges.refine_squares): its four corners carry the whole pose, and
    lines fitted over more of the sides pin them better. cover_relax_s: after the last covered or refitted
    frame, the cover's weight relaxes back to 1 with this time constant (seconds; `_cover_relax`).
    A pose on a lone marker's four corners also tells the filter their centre: the orbit mode about it,
    which such a pose shows worst, gets its own gain there (filter.py).
    hold_sigmas: the filtered pose never projects the anchor points it rests on further than this many
    times the measurement's pixel noise from where the frame's own solution does (`_hold_to_corners`; the
    filter's lag behind an accelerating camera or anchor); 0 turns the hold off.
    desk / desk_ambiguous_px: a lone square marker whose two IPPE poses both fit its corners within
    `desk_ambiguous_px` RMS (small, seen nearly head-on) is judged by the desk around it (desk.DeskPlane: its
    keypoints followed from a reference frame fix the plane's tilt); until that decides, results say
    `ambiguous`, and once it has, the desk's fit is the frame's measurement. False: never.
    other_polarity_every: once each ArUco anchor was found in some polarity (its print), a detection that
    finds none of a dictionary's anchors reads the other polarity only on every this-many-th miss in a row
    (detect.ArucoDetection.other_every; on every second one until then); 1: on every miss.
    branch_sigma_deg: how far (degrees, one sigma) the pose may turn from the filter's prediction in the
    choice between a lone marker's two IPPE poses (solve_pose's `motion_sigma_deg`): the prediction decides
    only between poses that fit the corners about equally well. With 1 degree it outweighed any fit, and on a
    card held and moved before a still camera the tracker kept the branch that fitted its corners worse, 4-8
    cm off, for frames on end. Chosen on tune_held_marker (4 to 30 alike, 3 and below kept the worse branch)
    and test_anchors' ambiguous still marker (0.45 px corner noise: 8 and above let noise flip it): 5. The
    head-on tuning recordings and the bundled recordings' replays are unchanged by it.
    """

    def __init__(self, anchors: list[AnchorSpec], camera: Camera, filter: bool = True, *, roi: bool = True,
                 full_every: int = 10, track_markers: bool = True, outlier_px: float = 3.0, branch_decay: float = 0.8,
                 branch_switch: float = 6.0, smear_px: float = 10.0, smear_sharpness: float = 0.15,
                 cover_fraction: float = 0.2, cover_weight: float = 0.1, refit_weight: float = 0.3,
                 new_anchor_gate: float = 0.5, unblur_px: float | None = 2.0, lone_end_margin: float = 0.1,
                 cover_relax_s: float = 0.2, hold_sigmas: float = 2.0, desk: bool = True,
                 desk_ambiguous_px: float = 1.0, other_polarity_every: int = 8, branch_sigma_deg: float = 5.0,
                 **filter_params):
        if not anchors:
            raise ValueError("AnchorTracker needs at least one anchor (the session's anchors list is empty)")
        self.anchors = list(anchors)
        self.camera = camera
        self.models: list[AnchorModel] = build_models(self.anchors)
        self.world_from_anchor = [m.world_from_anchor for m in self.models]
        # each anchor's outline in world points (K,3), and all of them together
        self.outlines = [m.to_world(m.outline()) for m in self.models]
        self._outlines = np.concatenate(self.outlines)
        self.aruco = ArucoDetection(self.models, camera)
        self.qr = QRTracking(self.models, camera)
        self.filter_enabled = bool(filter)
        self.filter = PoseFilter(**filter_params)
        self.smear_px, self.smear_sharpness = float(smear_px), float(smear_sharpness)
        self.cover_fraction, self.cover_weight = float(cover_fraction), float(cover_weight)
        self.refit_weight = float(refit_weight)
        self.new_anchor_gate = float(new_anchor_gate)
        self.lone_end_margin = float(lone_end_margin)
        self.aruco.lone_end_margin = self.lone_end_margin
        # a print seen once does not turn over: after a miss the other polarity is read only every 8th miss
        # in a row (a pan smearing the board past reading would pay a second detector pass a frame)
        self.aruco.other_every = int(other_polarity_every)
        self.cover_relax_s = float(cover_relax_s)
        self.hold_sigmas = float(hold_sigmas)
        self.hold_rank_ratio = 0.1   # pose directions the corners show less than this (of the best) are not corrected
        self.cover_max_markers = 2
        self.cover_refit = True   # refit a covered lone marker's corners on its sides' uncovered parts
        self.refitted = 0         # markers so refitted this session (diagnostics, tests)
        self._refit_now: set[int] = set()
        self.roi = roi
        self.full_every = max(int(full_every), 1)
        self.track_markers = bool(track_markers)
        self.track_max_rms = 1.0  # px: a tracked (not detected) solution worse than this is re-detected
        self.deskew_extrapolate_min = 12  # points (three markers' corners): see _deskew
        self.unblur_px = None if unblur_px is None else float(unblur_px)
        self._tracked_only = False
        self.outlier_px = float(outlier_px)
        self.branch_decay = float(branch_decay)
        self.branch_switch = float(branch_switch)
        self.desk = DeskPlane(camera) if desk else None
        self.card: CardPoints | None = None   # a lone marker's card, set by the caller (card.py)
        self.desk_ambiguous_px = float(desk_ambiguous_px)
        self.branch_sigma_deg = float(branch_sigma_deg)
        self.reset()

    def reset(self) -> None:
        """Forget all temporal state (filter, tracked QR corners, frame counter)."""
        self.filter.reset()
        self.qr.reset()
        self.frame = 0
        self.last_raw: np.ndarray | None = None
        self._last_pts: dict = {}      # (anchor, object point key) -> last frame's detected pixel
        self._last_pts_t: float | None = None
        self._prev_pts: tuple = ({}, None)
        self._fields: dict = {}        # anchor -> (this frame's affine image-velocity field, its dt)
        self._prev_fields: dict = {}
        self.branch_evidence = 0.0
        self._alternative = None
        self._cover_last: tuple[float, float | None] = (1.0, None)   # (last cover weight, its time)
        self._state_sigma = float("inf")   # the best measurement noise (radians) the filter's state rests on
        self.tracked_keys: set[tuple[int, int]] = set()
        self.trusted: set[int] = set()   # anchors that have carried (or agreed with) the pose this session
        self.ambiguous = False   # the last frame's result was `ambiguous` (AnchorResult)
        self._projections: dict = {}     # this frame's _project_world results
        if getattr(self, "desk", None) is not None:
            self.desk.reset()
        if getattr(self, "card", None) is not None:
            self.card.reset()

    def _other_branch_wins(self, obs: list[Observation], sol) -> bool:
        """Accumulate evidence between the two IPPE branches when a single planar anchor carries the pose.

        Per frame the evidence is (cost of the other branch - cost of the kept one) / pixel_sigma^2, decayed
        by `branch_decay`; True when it falls below -`branch_switch` (the other branch keeps fitting better).
        `sol`: solve_pose's solution on `obs` (its `branches` are the anchor's two IPPE poses and errors).
        """
        if len(obs) != 1:
            self.branch_evidence = 0.0
            return False
        # solve_pose's hypotheses for this one observation, with their errors on its points
        sols = [cfw for cfw, _ in sol.branches]
        if len(sols) < 2:
            return False
        ang = [rotation_angle(s[:3, :3] @ sol.camera_from_world[:3, :3].T) for s in sols]
        kept, other = (0, 1) if ang[0] <= ang[1] else (1, 0)
        if rotation_angle(sols[0][:3, :3] @ sols[1][:3, :3].T) < np.radians(2.0):
            self.branch_evidence = 0.0
            return False
        c = [float(np.sum(r ** 2)) for _, r in sol.branches]
        self.branch_evidence = self.branch_decay * self.branch_evidence + (c[other] - c[kept]) / 0.25
        if self.branch_evidence < -self.branch_switch:
            self.branch_evidence = 0.0
            self._alternative = sols[other]
            return True
        return False

    def _solve(self, obs: list[Observation], pred_cfw: np.ndarray | None):
        """solve_pose on this frame's observations from the prediction `pred_cfw` (camera_from_world), with this
        tracker's outlier threshold and `branch_sigma_deg`."""
        return solve_pose(obs, self.world_from_anchor, self.camera, pred_cfw, outlier_px=self.outlier_px,
                          motion_sigma_deg=self.branch_sigma_deg)

    def _cover_relax(self, t: float, cover: float) -> float:
        """This frame's cover weight (`cover`: cover_weight and/or refit_weight, 1 when neither applies),
        relaxed back to 1 with time constant `cover_relax_s` after the last frame that had one.

        The frames right after the cover check stops flagging a marker are not yet as good as free
        ones (the fingertips leave over a few frames, first to the paper's edge, and their shadow later),
        and the filter, which followed the covered measurements slowly, would otherwise be pulled to the
        free ones at full gain in one step: the step spread over a few frames is a smaller frame-to-frame
        change."""
        if cover < 1.0:
            self._cover_last = (cover, t)
            return cover
        last, t_last = self._cover_last
        if t_last is None or self.cover_relax_s <= 0 or t <= t_last:
            return 1.0
        return float(1.0 - (1.0 - last) * np.exp(-(t - t_last) / self.cover_relax_s))

    def _smear_weight(self, gray, sol, raw) -> float:
        """Weight (0.04..1) of this frame's measurement in the filter: below 1 when the markers moved
        `smear_px` or more since the last frame and their edges are smeared along that motion; the
        weight falls with the square of the sharpness below `smear_sharpness`."""
        if not self.filter.initialised:
            return 1.0
        world = np.asarray(sol.world, float)
        motion = median(self._project_world(world, raw) - self._project_world(world, self.filter.pose()))
        if np.linalg.norm(motion) < self.smear_px:
            return 1.0
        sharp = edge_sharpness(gray, np.asarray(sol.img, float), motion)
        if not sharp < self.smear_sharpness:
            return 1.0
        return float(max(0.2, sharp / self.smear_sharpness) ** 2)

    def _project_world(self, world: np.ndarray, world_from_camera: np.ndarray) -> np.ndarray:
        """camera.project_world(world, world_from_camera), remembered for this frame: _unstretch and
        _smear_weight project the same solution's points under the same poses (the filter's, and the
        solution's when the stretch fit left it as it was)."""
        key = (id(world), world_from_camera.tobytes())
        hit = self._projections.get(key)
        if hit is not None and hit[0] is world:
            return hit[1]
        px = self.camera.project_world(world, world_from_camera)
        self._projections[key] = (world, px)   # (holding `world` keeps its id from being reused this frame)
        return px

    # ------------------------------------------------------------------------------------------------
    def process(self, image: np.ndarray, t: float, reference: np.ndarray | None = None) -> AnchorResult:
        """Detect the anchors in `image` (BGR or gray uint8, distorted as `camera` says) taken at time t (s).

        `reference`: the caller's own estimate of this frame's world_from_camera (a map, a motion model),
        used to screen anchors never seen before; without it the filter's prediction is used."""
        t0 = time.perf_counter()
        self._projections = {}
        gray = to_gray(image)
        if gray.shape != (self.camera.height, self.camera.width):
            raise ValueError(f"image is {gray.shape[1]}x{gray.shape[0]} but the camera is calibrated for "
                             f"{self.camera.width}x{self.camera.height}; use Camera.scaled() for resized images")
        pred = self.filter.predict(t)
        pred_cfw = None if pred is None else invert(pred)
        self._tracked_only = False
        fast = self._moving_fast(pred_cfw)
        ref_cfw = invert(reference) if reference is not None else pred_cfw
        obs, rejected, covered, sol = self._observe(gray, t, pred_cfw, ref_cfw, fast)
        self.frame += 1
        res = AnchorResult()
        desk = self._desk_update(gray, t, obs, sol)
        if sol is not None:
            self._measure(res, gray, t, obs, sol, covered, desk)
        else:
            self.tracked_keys = set()
            if self.card is not None:
                self.card.reset()   # (its points cannot be placed without the marker)
        res.rejected = rejected
        self.ambiguous = res.ambiguous
        res.ms = (time.perf_counter() - t0) * 1000.0
        return res

    def _observe(self, gray, t: float, pred_cfw, ref_cfw, fast: bool):
        """This frame's anchor observations and their pose: detected (or re-found where `pred_cfw` puts them,
        detected properly when that disagrees), screened (new anchors against `ref_cfw`, covered margins),
        deskewed to the centre row's time, solved, the IPPE branch switched when the image has favoured the
        other for a while, and unstretched along a smear. Returns (obs, rejected, covered, solution or None)."""
        aruco_obs = self._detect_aruco(gray, pred_cfw, fast)
        qr_obs = self.qr.process(gray, pred_cfw, self.qr.expected(pred_cfw)) if self.qr.models else []
        obs, rejected = self._screen_new(aruco_obs + qr_obs, ref_cfw)
        obs, covered = self._drop_covered(gray, obs, fast, pred_cfw)
        obs = self._deskew(obs, t)
        sol = self._solve(obs, pred_cfw)
        if self._tracked_only and (sol is None or sol.rms > self.track_max_rms
                                   or len(sol.world) < 0.8 * sum(len(o.obj) for o in obs)):
            # markers re-found by tracking did not agree well: detect them properly this frame
            self.tracked_keys = set()
            obs, rejected = self._screen_new(self._detect_aruco(gray, pred_cfw) + qr_obs, ref_cfw)
            obs, covered = self._drop_covered(gray, obs, fast, pred_cfw)
            obs = self._deskew(obs, t)
            sol = self._solve(obs, pred_cfw)
        if sol is not None and pred_cfw is not None and self._other_branch_wins(obs, sol):
            # the image has favoured the other IPPE branch for a while: the branch kept so far was the wrong
            # guess (e.g. the first frame's). Switch, and restart the filter so it does not smooth the jump.
            alt = self._alternative
            sol = self._solve(obs, alt)
            self.filter.reset()
        if sol is not None and self.unblur_px is not None:
            sol = self._unstretch(obs, sol)
        return obs, rejected, covered, sol

    def _measure(self, res: AnchorResult, gray, t: float, obs: list[Observation], sol, covered, desk) -> None:
        """Fill `res` from the frame's solution `sol` (and the desk's fit `desk`): the raw pose, the filter's
        update with the measurement's noise (radians) and weight, held to the corners."""
        raw = sol.world_from_camera if desk is None or not desk.decided else invert(desk.camera_from_world)
        depth = float(median((sol.world @ sol.camera_from_world[:3, :3].T + sol.camera_from_world[:3, 3])[:, 2]))
        # The measurement's noise in radians: pixel noise (the residual corrected for the 6 pose
        # parameters, at least 0.1 px) over the points' extent, times the lever f/extent that makes
        # out-of-plane tilt and depth of a small target uncertain, fewer with more points.
        n = len(sol.img)
        extent = max(float(np.linalg.norm(np.ptp(sol.img, axis=0))), 1.0)
        px_sigma = max(sol.rms * np.sqrt(2 * n / max(2 * n - 6, 1)), 0.1)
        card = None if self.card is None else self.card.update(gray, sol.world, sol.img, sol.camera_from_world,
                                                               self._lone(obs, sol), px_sigma)
        raw = raw if card is None else card[0]
        lever = np.sqrt(1.0 + (self.camera.fx / extent) ** 2)
        sigma = 2.0 * px_sigma / extent * lever / np.sqrt(max(n / 4.0, 1.0))
        covered = covered and bool(covered & set(sol.anchors))
        res.refitted = bool(self._refit_now & set(sol.anchors))
        cover = (self.cover_weight if covered else 1.0) * (self.refit_weight if res.refitted else 1.0)
        smear = self._smear_weight(gray, sol, raw)
        if smear < 1.0 and 2.0 * sigma < self._state_sigma:
            # the filter's state rests on measurements far noisier than this one (a board's few markers
            # at the image edge as it came back into view): smeared or not, this one counts in full
            smear = 1.0
        weight = smear * self._cover_relax(t, cover)
        # a pose on one square's four corners (a lone marker) shows the orbit mode about their centre
        # far worse than the rest: the filter gives that mode its own, lower gain (filter.py)
        centre = np.mean(sol.world, axis=0) if n <= 4 else None
        if desk is not None and desk.decided:
            # the desk's keypoints hold the tilt the corners cannot: the measurement is as good as its fit,
            # and its noise from frame to frame is the fit's with the reference held (the reference's error is
            # common to all frames: counted as noise it let the filter lag a degree behind the hand)
            sigma, centre = max(desk.noise, 1e-4), None
        if card is not None:   # so do the card's points, each place the mean of many frames (card.py)
            sigma, centre = max(card[1] / depth, 1e-4), None
        res.ambiguous = desk is not None and not desk.decided or (desk is None and self._desk_undecided())
        res.desk = desk is not None and desk.decided
        filt = self.filter.update(raw, t, depth, sigma, weight=weight, centre=centre)
        filt = self._hold_to_corners(filt, raw, sol.world, px_sigma / max(weight, 1e-3))
        # (a restart leaves the state on this measurement alone; a down-weighted one counts as noisier)
        self._state_sigma = (sigma if self.filter.n == 0
                             else min(self._state_sigma, sigma / max(weight, 1e-3)))
        self.trusted.update(sol.anchors)
        res.covered = bool(covered)
        res.raw_world_from_camera = raw
        res.world_from_camera = filt if self.filter_enabled else raw
        res.markers = sol.markers
        res.inliers = int(len(sol.world))
        res.reprojection_error = sol.rms
        res.object_points = sol.world
        res.image_points = sol.img
        res.anchors_seen = sol.anchors
        self.last_raw = raw
        self.tracked_keys = {(ob.anchor, g) for ob in obs if ob.anchor in sol.anchors
                             and self.models[ob.anchor].anchor_kind.detector == "aruco" for g in ob.groups.tolist()}

    def _desk_update(self, gray, t: float, obs: list[Observation], sol):
        """The desk's fit (`desk.DeskPlane.update`) when a lone square marker carries the pose and its two IPPE
        poses both fit its corners within `desk_ambiguous_px` RMS (or the desk is followed already); None
        otherwise (the desk is then forgotten when no lone marker is seen)."""
        if self.desk is None:
            return None
        if not (self._lone(obs, sol) and len(sol.branches) == 2):
            self.desk.reset()
            return None
        if not self.desk.active:
            rms = [float(np.sqrt(np.mean(r ** 2))) for _, r in sol.branches]
            if max(rms) > self.desk_ambiguous_px:
                return None
        return self.desk.update(gray, t, sol.world, sol.img, [cfw for cfw, _ in sol.branches])

    def _lone(self, obs: list[Observation], sol) -> bool:
        """Whether a lone square marker's four corners carry this frame's solution `sol`."""
        return (sol is not None and len(obs) == 1 and len(sol.world) == 4
                and self.models[obs[0].anchor].anchor_kind.single_square)

    def _desk_undecided(self) -> bool:
        return self.desk is not None and self.desk.active and not self.desk.decided

    def _hold_to_corners(self, filt: np.ndarray, raw: np.ndarray, world: np.ndarray, px_sigma: float) -> np.ndarray:
        """The filtered pose `filt` (world_from_camera), corrected just enough that the anchor points it rests
        on (`world`, N,3) project within `hold_sigmas` times the measurement's pixel noise `px_sigma` of
        where this frame's own solution `raw` projects them (further when the measurement was down-weighted:
        the caller divides `px_sigma` by its weight).

        A constant-velocity filter lags behind any acceleration by (1 - alpha) / beta times it, and its
        velocity gain is kept low so one noisy frame cannot fling the prediction: on a marker turned by
        hand the filtered pose drew the marker's own corners half a pixel to pixels from where they were
        seen, frame after frame. The correction is the least-squares pose change for the part of the
        corners' offset beyond that bound, in the pose directions the corners pin (a truncated SVD of the
        projection's Jacobian, translation counted as the angle it subtends): what the filter removes and
        the corners cannot see (a lone marker's tilt) stays removed. The filter's own state is left as it is."""
        if not self.filter_enabled or self.hold_sigmas <= 0 or len(world) < 3:
            return filt
        return hold_to_corners(self.camera, filt, raw, world, self.hold_sigmas * px_sigma, self.hold_rank_ratio)

    def _unstretch(self, obs: list[Observation], sol):
        """The solution refitted together with motion blur's stretch of the markers (blur.py), when five or
        more whole markers, spread in two directions, moved `unblur_px` pixels or more since the last
        filtered pose; its image points are then the corners with the stretch taken out."""
        # (the cheap checks first; the outcome does not depend on their order)
        if not self.filter.initialised:
            return sol   # nothing says whether the markers move
        groups = np.concatenate([ob.groups + 1_000_000 * (ob.anchor + 1) for ob in obs])[sol.inliers]
        markers = marker_groups(sol.img, groups)
        if int((markers[2] == 4).sum()) < MIN_MARKERS:
            return sol
        moved = median(row_norms(self._project_world(sol.world, sol.world_from_camera)
                                    - self._project_world(sol.world, self.filter.pose())))
        if moved < self.unblur_px or not spread_enough(sol.img, groups, markers=markers):
            return sol
        offsets, _ = marker_offsets(sol.img, groups, markers=markers)
        cfw, S = fit_pose_and_stretch(self.camera, sol.camera_from_world, sol.world, sol.img, offsets)
        img = sol.img - offsets @ S.T
        rms = float(np.sqrt(np.mean(residuals(self.camera, cfw, sol.world, img) ** 2)))
        return dataclasses.replace(sol, camera_from_world=cfw, img=img, rms=rms)

    def _deskew(self, obs: list[Observation], t: float) -> list[Observation]:
        """Move each detected point to where it would be at the frame's centre-row time, for a camera
        with a rolling shutter (`camera.readout` seconds, top row to bottom row).

        Row y is read `d = readout * ((y + 0.5) / height - 0.5)` seconds from the frame time; a point
        moving across the image at u' pixels/s was seen `u' d` from where the centre row would have
        seen it. u' is the point's own image velocity since the last frame (its detections in both
        frames), fitted as an affine field over the anchor's points: far less noisy than a velocity
        from two poses, whose tilt noise barely moves the image. That difference is the velocity half a
        frame before the point's row time; when the anchor's field was also fitted in the last frame, from
        at least `deskew_extrapolate_min` points (fewer make the difference of two fields too noisy), the
        change between the two fields carries it on to the middle of the stretch the point is moved over
        (the image acceleration of a hand-held camera is what the lag otherwise leaves in the corners).
        First order in d; points of an anchor not seen in the last frame are left as they are. Also
        remembers this frame's points and fields.
        """
        cam = self.camera
        if cam.readout <= 0:
            return obs
        if self._last_pts_t != t:   # (a second detection pass of the same frame compares with the last frame too)
            self._prev_pts = (self._last_pts, self._last_pts_t)
            self._prev_fields, self._fields = self._fields, {}
        prev, prev_t = self._prev_pts
        # a point's key: its anchor and its object coordinates in 10 um steps (python ints, one conversion)
        keys_of = [[(ob.anchor, *k) for k in np.round(ob.obj * 1e5).astype(int).tolist()] for ob in obs]
        self._last_pts = {k: px for ob, keys in zip(obs, keys_of) for k, px in zip(keys, ob.img)}
        self._last_pts_t = t
        dt = t - prev_t if prev_t is not None else 0.0
        if not prev or not 0 < dt <= 0.1:
            return obs
        out = []
        for ob, keys in zip(obs, keys_of):
            moved, field = deskew_observation(cam, ob, keys, prev, dt, self._prev_fields.get(ob.anchor),
                                              self.deskew_extrapolate_min)
            if field is not None:
                self._fields[ob.anchor] = field
            out.append(moved)
        return out

    def _screen_new(self, obs: list[Observation], ref_cfw: np.ndarray | None) -> tuple[list[Observation], list[int]]:
        """Leave out observations of anchors never trusted in this session whose corners are far from
        where the reference pose (camera_from_world) puts them: a new anchor that disagrees with the
        pose everything else holds is more likely a look-alike (a pattern on packaging decoding as the
        anchor's id) than a teleport. Without a reference (nothing holds the pose) all are kept.
        Returns (kept observations, rejected anchor indices)."""
        if self.new_anchor_gate <= 0 or all(ob.anchor in self.trusted for ob in obs):
            return obs, []
        if ref_cfw is None:
            if len({ob.anchor for ob in obs}) < 2:
                return obs, []
            # nothing holds the pose yet and several new anchors disagree or not: the one declared first
            # (the world anchor, if seen) is taken as the reference for the others
            first = min(obs, key=lambda ob: (ob.anchor, -len(ob.obj)))
            sols = planar_solutions(first, self.camera)
            if not sols:
                return obs, []
            ref_cfw = sols[0] @ invert(self.world_from_anchor[first.anchor])
        kept, rejected = [], []
        for ob in obs:
            if ob.anchor in self.trusted:
                kept.append(ob)
                continue
            world = transform_points(self.world_from_anchor[ob.anchor], ob.obj)
            px, z = project(self.camera, ref_cfw, world)
            size = float(np.sqrt(np.prod(np.ptp(ob.img, axis=0))))   # the anchor's own image size, pixels
            gap = float(np.median(np.linalg.norm(px - ob.img, axis=1))) if np.all(z > 0) else np.inf
            if gap <= self.new_anchor_gate * max(size, 20.0):
                kept.append(ob)
            else:
                rejected.append(ob.anchor)
        return kept, sorted(set(rejected))

    def _moving_fast(self, pred_cfw: np.ndarray | None) -> bool:
        """Whether the filter expects the anchors to move `smear_px` pixels or more since the last frame
        (then motion blur, not a hand, is what lowers a margin's contrast: the smear weighting handles it)."""
        if pred_cfw is None or not self.filter.initialised:
            return False
        now = project_pixels(self.camera, pred_cfw, self._outlines)
        last = project_pixels(self.camera, invert(self.filter.pose()), self._outlines)
        return bool(median(row_norms(now - last)) >= self.smear_px)

    def _drop_covered(self, gray: np.ndarray, obs: list[Observation], fast: bool = False,
                      pred_cfw: np.ndarray | None = None) -> tuple[list[Observation], set[int]]:
        """Screen ArUco markers for a partly covered white margin (occlusion.covered_fraction). A covered
        lone marker is first refitted on its edges from the prediction `pred_cfw` (_refit_covered; its
        anchor is then in `_refit_now`). Markers still covered are dropped while uncovered markers remain
        in the frame; otherwise all are kept and
        the anchors with covered markers are returned (their measurement is then down-weighted).
        Not while the camera moves fast (`fast`: blur lowers margins alike and is weighed separately),
        nor when more than `cover_max_markers` markers are in view (many markers outvote one marker's bad
        corners in the fit, and dropping markers would only cost precision)."""
        self._refit_now = set()
        if self.cover_fraction <= 0 or fast or sum(ob.markers for ob in obs) > self.cover_max_markers:
            return obs, set()
        flagged: dict[int, np.ndarray] = {}
        good = 0
        for k, ob in enumerate(obs):
            m = self.models[ob.anchor]
            # lone markers only: a board's corners come from a marker family drawn on one sheet (thin
            # margins between them, and its other markers outvote a covered one in the fit)
            if not m.anchor_kind.single_square or m.anchor_kind.detector != "aruco" or len(ob.img) != 4:
                good += len(ob.img) // 4
                continue
            bits = self.aruco.bits[m.spec.dictionary_id]
            quads = ob.img.reshape(-1, 4, 2).copy()
            bad = np.array([is_covered(covered_fraction(gray, q, bits), self.cover_fraction) for q in quads])
            if bad.any() and self.cover_refit and pred_cfw is not None:
                fixed = self._refit_covered(gray, m, ob.groups[::4][bad], quads[bad], bits, pred_cfw)
                if fixed is not None:
                    quads[bad] = fixed
                    bad[:] = False
                    self.refitted += 1
                    self._refit_now.add(ob.anchor)
                    obs[k] = ob = Observation(ob.anchor, ob.obj, quads.reshape(-1, 2), ob.groups, ob.markers,
                                              square=ob.square)
            good += int((~bad).sum())
            if bad.any():
                flagged[k] = bad
        if not flagged:
            return obs, set()
        if good == 0:
            return obs, {obs[k].anchor for k in flagged}
        out = []
        for k, ob in enumerate(obs):
            bad = flagged.get(k)
            if bad is None:
                out.append(ob)
            elif not bad.all():
                keep = np.repeat(~bad, 4)
                out.append(Observation(ob.anchor, ob.obj[keep], ob.img[keep], ob.groups[keep], int((~bad).sum()),
                                       square=ob.square))
        return out, set()

    def _refit_covered(self, gray, model: AnchorModel, ids, quads, bits: int, pred_cfw: np.ndarray):
        """`occlusion.refit_covered` with this tracker's camera and lone-marker edge margin."""
        return refit_covered(self.camera, gray, model, ids, quads, bits, pred_cfw, self.lone_end_margin)

    def _detect_aruco(self, gray: np.ndarray, pred_cfw: np.ndarray | None, fast: bool = False) -> list[Observation]:
        """The ArUco anchors' observations: re-found on their edges where `pred_cfw` puts them, else detected
        in a region around that, else in the whole frame. Not re-found while the camera moves `fast`
        (a prediction off by more than half a cell, as it is then, never re-finds them: time lost).
        (Looking only where the caller's map or flow puts the anchors while they are not tracked saved a
        whole-frame pass a frame on fast pans, but a marker moved in the room is then never found again: the
        map's pose, in the anchor's frame, says nothing of where a moved marker went.)"""
        if not self.aruco.models:
            return []
        if (self.track_markers and not fast and pred_cfw is not None and self.frame % self.full_every
                and self.tracked_keys):
            # between detections: the markers of the last frame, re-found on their edges where the
            # predicted pose puts them (no detector pass at all)
            obs = self.aruco.track(gray, self.tracked_keys, pred_cfw)
            if obs:
                self._tracked_only = True
                return obs
        roi = None
        # a region only when the last frame was tracked: after a loss the markers may be anywhere, and a
        # failed region search would just add to the full-frame one
        if self.roi and pred_cfw is not None and self.frame % self.full_every and self.tracked_keys:
            roi = self._aruco_roi(pred_cfw, gray.shape)
        if roi is not None:
            obs = self.aruco.detect(gray, roi)
            if obs:
                return obs
        return self.aruco.detect(gray)

    def _aruco_roi(self, cfw: np.ndarray, shape) -> tuple[int, int, int, int] | None:
        """Box around the predicted image of every ArUco anchor in front of the camera; None = whole frame."""
        pts, z = project(self.camera, cfw, np.concatenate([self.outlines[m.index] for m in self.aruco.models]))
        if np.any(z <= 0.01):
            return None
        h, w = shape
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        # slack for motion the prediction missed and for the marker border the detector needs to see
        pad = 0.2 * (hi - lo) + 24
        x0, y0 = np.maximum(np.floor(lo - pad), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(hi + pad), [w, h]).astype(int)
        if x1 - x0 < 32 or y1 - y0 < 32 or (x1 - x0) * (y1 - y0) > 0.7 * w * h:
            return None
        return int(x0), int(y0), int(x1), int(y1)

    def diagnose(self, image: np.ndarray) -> list[str]:
        """Plain-language reasons why the anchors are not (or badly) found in this image; [] when all is well."""
        return diagnose_image(self.anchors, self.camera, image)
