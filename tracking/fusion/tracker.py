"""The combined tracker the pipeline uses: anchors (markers, QR) fused with SLAM-style keypoint tracking.

    tr = Tracker(camera, anchors, slam=True)   # settings: TrackerConfig (or its names as keywords)
    res = tr.process(image_bgr, t)      # TrackResult(world_from_camera, state, markers, inliers, ms)
    tr.close()                          # stops the mapping / bundle-adjustment thread

Poses are `world_from_camera` 4x4 in the first anchor's frame (metres, OpenCV
camera axes). States: `marker` (anchors measured this frame and used),
`slam` (pose from map keypoints only), `lost` (no pose).

While the anchors were measured on the last frame, each frame first asks the anchor tracker (which re-finds
the markers / QR corners where its prediction puts them, cheaper than a detector pass): if it measures them,
its pose is the frame's pose, and keypoint work (ORB, map matching, keyframes) runs only every
`keypoint_every`-th frame to keep the map growing for when the anchors go. Otherwise: markers are detected on
a worker thread (every frame while lost or while the map is young, else every `marker_every`-th frame) while
ORB features are extracted; map points are matched by projection from a constant-velocity prediction; the
pose is a robust joint fit of marker corners and map points (anchors dominate), or of map points alone, or
comes from relocalisation. When all of that fails on a frame that follows a tracked one (motion blur smears
markers and descriptors alike), keypoints are followed from the last frame by optical flow
(`tracking.slam.flow`) and carry the pose (while a pan keeps the markers smeared past reading, the flow
frames after a detection pass that read none of them skip theirs: `SmearGate`, `smear_skip`). Under fast
motion the flow also checks the anchors for smear; when the motion model predicts it, it runs on this thread
while the anchors are measured on the worker (OpenCV releases the interpreter; the results are those of
running one after the other), and its points are followed on from frame to frame while the anchors carry the
pose (plane seeds placed again from the anchors' pose) instead of being seeded anew. When a board (12+
corners) returns after frames carried by the map or flow, the output fades onto it over
`precise_blend_frames`, fewer than other seams take. New keyframes go to the mapping thread (triangulation,
culling, local bundle adjustment with anchor corners as constraints); `process` never waits for it. Offline
drivers, which feed frames faster than a camera would, call `catch_up()` between frames so the map keeps the
pace it would have live, whatever the machine's load. A live view defers the keypoint work of a frame the
anchors carry (`TrackerConfig.defer_upkeep`): the frame returns the anchors' pose, and `upkeep()` does the
rest once the frame is shown (else the next `process` does it first).

Anchors that move in the room (a card held up to a webcam: `tracking.fusion.moving`; those frames:
`tracking.fusion.moving_frames`): the map is dropped, and only flow on points of the anchors' plane carries
unreadable frames, else they are lost. Anchor measurements that must not move the model (a hand over a lone
marker's margin, a look-alike pattern far from the prediction): `anchors.occlusion`, `TrackerConfig`; the
map, else flow, carries the pose meanwhile.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from tracking.camera import Camera
from tracking.fusion.config import TrackerConfig, make_config
from tracking.fusion.fits import Fit, PoseFits, anchor_points
from tracking.fusion.flow_follow import FlowFollower
from tracking.fusion.handover import Handover, anchor_output, anchor_usable, precise
from tracking.fusion.image import has_content, prepare
from tracking.fusion.keyframes import Keyframes
from tracking.fusion.moving import MovingAnchors
from tracking.fusion.moving_frames import MovingAnchorFrames
from tracking.fusion.output import Output
from tracking.fusion.smear_gate import SmearGate
from tracking.fusion.state import AnchorMemory, FrameState, TrackResult, TrackStatus
from tracking.anchors.card import CardPoints
from tracking.anchors.kinds import AnchorSpec
from tracking.slam.features import FeatureExtractor, Features
from tracking.slam.flow import relift
from tracking.slam.frame_pose import MotionModel
from tracking.slam.map import Map
from tracking.slam.map_io import adopt
from tracking.slam.mapping import LocalMapper


class Tracker(MovingAnchorFrames):
    """Anchors + keypoint SLAM. See the module docstring; settings: `TrackerConfig` (as `config`, or
    its field names as keyword arguments; `slam` may also be given positionally), read from `config`.

    Its parts: `anchor_tracker` (the anchors' own tracker), `map` / `mapper` / `extractor` / `motion` (the
    keypoint SLAM), `handover` (which source carries a frame), `fits` (the full frame's pose fits), `flow`
    (optical flow from the last frame), `output` (the pose shown, faded at seams), `keyframes`, `room`
    (whether the anchors move in the room); the state: `frame` (this frame's, replaced each frame),
    `status` and `anchor` (what the frames before left)."""

    def __init__(self, camera: Camera, anchors: list[AnchorSpec], slam: bool | None = None, *,
                 config: TrackerConfig | None = None, **settings):
        if slam is not None:
            settings["slam"] = slam
        cfg = self.config = make_config(config, settings)
        from tracking.anchors import AnchorTracker  # the anchors package is built alongside

        if not anchors:
            raise ValueError("Tracker needs at least one anchor to define the world frame; "
                             "list the markers in session.json 'anchors'")
        self.camera = camera
        # the anchors' own filter smooths the marker-only frames before the map carries the pose
        self.anchor_tracker = AnchorTracker(anchors, camera, filter=cfg.filter, cover_fraction=cfg.cover_fraction,
                                            cover_weight=cfg.cover_weight, new_anchor_gate=cfg.new_anchor_gate)
        self._desk = self.anchor_tracker.desk   # its desk judge, off while the anchors move in the room
        # the card a lone marker is printed on, followed from the first frame, its judge once the marker is seen
        # to move in the room (`_drop_map`; tracking.anchors.card)
        self.anchor_tracker.card = CardPoints(camera) if cfg.slam else None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="anchors") if cfg.slam else None
        n_features = cfg.n_features
        if n_features is None:
            n_features = int(np.clip(camera.width * camera.height / 300, 400, 1500))
        self.extractor = FeatureExtractor(camera, n_features=n_features)
        self.map = Map()
        self.mapper = LocalMapper(self.map, camera.K.copy(), ba=cfg.ba, threaded=cfg.threaded) if cfg.slam else None
        self.motion = MotionModel()
        self.handover = Handover(cfg, camera, self.anchor_tracker, self.motion)
        self.fits = PoseFits(cfg, camera, self.map, self.motion, self.handover)
        self._outlines = np.concatenate(self.anchor_tracker.outlines)   # every anchor's outline, world (N,3)
        self._fresh_state()

    # -- lifecycle ------------------------------------------------------------------
    def _fresh_state(self) -> None:
        """The state a session starts with (also after `reset`)."""
        cfg = self.config
        self.frame = FrameState()
        self.status = TrackStatus()
        self.anchor = AnchorMemory()
        self.flow = FlowFollower(cfg, self.camera, self.motion, self.handover)
        self.output = Output(cfg, self.camera, self.motion)
        self.keyframes = Keyframes(cfg, self.map, self.mapper)
        self.room = MovingAnchors(self.camera, self.handover, self.fits.track_map, cfg.min_inliers)
        self.smear_gate = SmearGate(self.camera, cfg.smear_px, cfg.smear_skip)
        self._pending = None   # the anchors' result of a frame whose keypoint work waits for `upkeep`

    def reset(self) -> None:
        """Forget the map and the motion; the next frame starts from the anchors."""
        if self.mapper is not None:
            self.mapper.wait_idle()
        self.map.clear()
        self.motion.reset()
        self.anchor_tracker.desk = self._desk   # (back on if the anchors were seen to move: `_drop_map`)
        if self.anchor_tracker.card is not None:
            self.anchor_tracker.card.carries = False
        self.anchor_tracker.reset()
        self._fresh_state()

    def close(self) -> None:
        """Stop the mapping thread and the detection worker."""
        if self.mapper is not None:
            self.mapper.close()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def load_map(self, saved: Map) -> None:
        """Start from a saved map (a scene file, tracking.slam.map_io): forget the motion, so the next
        frames relocalise against every saved keyframe; new keyframes extend it."""
        self.reset()
        adopt(self.map, saved)

    def export_map(self) -> Map:
        """The map as it stands once queued keyframes are mapped (to save in a scene file)."""
        self.upkeep()
        self.wait_mapping()
        return self.map

    def wait_mapping(self) -> None:
        """Block until queued keyframes are mapped (offline replay, tests)."""
        if self.mapper is not None:
            self.mapper.wait_idle()

    def catch_up(self) -> None:
        """For offline drivers, between frames: give the mapping thread the time a live camera's
        frame interval would. Blocks until every keyframe submitted `max_lag` or more frames before
        the next one is mapped (1 frame while the anchors carry the pose: the cheap anchor frames
        would otherwise share the interpreter with mapping). Results then do not depend on how fast
        or loaded the machine is; `process` itself never waits."""
        if self.mapper is None:
            return
        cfg = self.config
        lag = 1 if self.status.last_state == "marker" and cfg.anchor_first else cfg.max_lag
        self.keyframes.catch_up(self.frame.index + 1, lag)

    @property
    def anchors_moving(self) -> bool:
        """Whether the anchors were seen to move in the room this session (a card held before the camera):
        the keypoint map is off, and only points on the anchors carry the pose across unreadable frames."""
        return self.room.moving

    # -- per frame ------------------------------------------------------------------
    def process(self, image: np.ndarray, t: float) -> TrackResult:
        """Track one frame (BGR or grey uint8, camera size) taken at time t seconds."""
        self.upkeep()   # the last frame's deferred keypoint work, if a live view did not run it meanwhile
        t0 = time.perf_counter()
        bgr, gray = prepare(image, self.camera.size)
        self.frame = FrameState(self.frame.index + 1, t, t0, gray)
        if not has_content(gray):
            return self._lost_frame(0)
        if not self.config.slam:
            return self._marker_only(bgr)
        if self.room.moving or (self.room.suspects(self.frame.index) and self.status.last_state != "marker"):
            # (a check disagreed, unconfirmed, and the anchors went unread since: the card may be swinging,
            # so only points on it carry the pose until the anchors are read again and checked)
            return self._moving_anchor_frame()
        return self._slam_frame()

    def _slam_frame(self) -> TrackResult:
        """A frame of the full tracker: the anchors first while they carry the pose, else optical flow
        between full frames, flow again after a flow frame, else a full frame (anchors, keypoints, fit)."""
        cfg, st, frame = self.config, self.status, self.frame
        young = len(self.map.points) < 60 or len(self.map.keyframes) < 4
        detect = st.since_detect + 1 >= cfg.marker_every or st.lost > 0 or young or self.motion.last is None
        ar = None
        if cfg.anchor_first and st.last_state == "marker" and st.lost == 0 and self.motion.last is not None:
            res, ar = self._anchors_first(young)
            if res is not None:
                return res
            if self.room.suspects(frame.index) and not (
                    anchor_usable(ar) and self.handover.plausible(anchor_output(ar), self.motion.last, frame.t)):
                return self._unread_while_suspect(int(ar.markers))
            detect = False
        elif not detect and cfg.klt:
            res = self._klt_frame()
            if res is not None:
                st.since_detect += 1
                return res
        flow_tried = False
        if self.flow.via_flow and frame.index - st.full_frame < cfg.keypoint_every:
            res, ar, detect = self._flow_again(detect, ar)
            if res is not None:
                return res
            flow_tried = True
        st.full_frame = frame.index
        return self._full_frame(detect, ar, flow_tried, young)

    def _anchors_first(self, young: bool) -> tuple[TrackResult | None, object]:
        """Anchors were measured last frame: the anchor tracker re-finds them at their predicted place (no
        detector pass, a few ms) and its pose is the most accurate there is. Keypoint work (ORB, matching,
        keyframes) runs only every `keypoint_every` frames to grow the map, or when the anchors are not found.
        Returns (result, anchor result); result is None when the full frame's work must run.

        When the motion model moves the anchors' last corners `smear_px` or more, the flow this frame
        will need (`Handover.moving_fast`) runs on this thread while the anchors are measured on the worker
        (OpenCV releases the interpreter): the same result as one after the other, in the time of the
        longer of the two."""
        frame, t = self.frame, self.frame.t
        ar, _ = self._measure_anchors(self._follow_from_last)   # (the flow is kept for this frame)
        pose = anchor_output(ar) if anchor_usable(ar) else None
        # (every frame while a check that found the anchors moving in the room waits to be confirmed)
        due = frame.index - self.status.full_frame >= self.config.keypoint_every or self.room.checks_often(frame.index)
        if pose is None or not self.handover.plausible(pose, self.motion.last, t) or (
                due and (young or not self.config.defer_upkeep)):
            return None, ar
        jumped = self.handover.jumped(ar, t)
        got = self._follow_from_last() if self.handover.moving_fast(ar, t) or jumped else None
        verdict = self.handover.flow_over_anchors(ar, got, jumped, frame, self.anchor)
        if verdict is not None:
            return self._flow_result(got, int(ar.markers), seam_from=pose if verdict == "better" else None), ar
        # the flow's points, now measured in this image, are followed on from here (their plane seeds
        # placed from the anchors' pose, as new seeds would be); without flow it restarts next time
        self.flow.tracks = None if got is None else relift(self.camera, got[1], pose)
        if due:   # the full frame's keypoint work, once the frame is shown (`upkeep`); its ORB starts now, on
            # the worker (OpenCV releases the interpreter), beside the drawing of this frame
            self.status.full_frame = frame.index
            self._pending = (ar, self._pool.submit(self.extractor.extract, frame.gray))
        return self._finish(pose, self.motion.predict(t), "marker", "anchors", None, int(ar.markers),
                            int(ar.inliers), precise=precise(ar)), ar

    def _klt_frame(self) -> TrackResult | None:
        """Between full frames: the pose from last frame's inlier map points followed by optical flow (no
        detection, no descriptors). None when that is not good enough."""
        got = self.flow.between_full_frames(self.frame)
        if got is None:
            return None
        pose, pred = got
        return self._finish(pose, pred, "slam", None, None, 0, len(self.flow.tracks))

    def _flow_again(self, detect: bool, ar) -> tuple[TrackResult | None, object, bool]:
        """Flow carried the last frame (motion blur defeats markers and descriptors alike): flow again beside
        the marker detection, and the full keypoint work only when both fail or every `keypoint_every`
        frames, to get back onto the map. (result or None, the anchors' result, whether detection is
        still to run)."""
        st, t = self.status, self.frame.t
        # (a pan that smeared the anchors past reading on the last pass reads them no better while it does
        # not slow down: `SmearGate`; detection then still runs if the flow fails)
        fut = self._submit_detection() if detect and not self.smear_gate.skip(self._anchor_motion()) else None
        got = self._follow_from_last()
        if fut is not None:
            ar = fut.result()
            self._note_anchors(ar)
            st.since_detect = 0
            detect = False
        else:
            st.since_detect += 1
        usable = anchor_usable(ar) and self.handover.plausible(anchor_output(ar), self.motion.last, t)
        if self.handover.flow_keeps(ar, got, usable, self.frame, self.anchor):
            return self._flow_result(got, int(ar.markers) if ar is not None else 0), ar, detect
        return None, ar, detect

    def _full_frame(self, detect: bool, ar, flow_tried: bool, young: bool) -> TrackResult:
        """Anchors detected (on the worker, when `detect`) while this frame's keypoints are extracted; the
        anchors checked against the flow, then the pose fitted (`_fit_frame`)."""
        st, cfg = self.status, self.config
        fut = self._submit_detection() if detect else None
        feats, defer = self._features(fut, ar, detect, young)
        if fut is not None:
            if self._fast_predicted():
                self._follow_from_last()   # while the detection runs (the result is kept for this frame)
            ar = fut.result()
            self._note_anchors(ar)
            st.since_detect = 0
        elif ar is None:
            st.since_detect += 1
        if defer and len(anchor_points(ar, self.camera)[0]):
            feats = self.extractor.extract(self.frame.gray)
        t = self.frame.t
        if not flow_tried and anchor_usable(ar) and self.handover.plausible(anchor_output(ar), self.motion.last, t):
            jumped = self.handover.jumped(ar, t)
            if jumped or self.handover.moving_fast(ar, t):
                got = self._follow_from_last()
                verdict = self.handover.flow_over_anchors(ar, got, jumped, self.frame, self.anchor)
                if verdict is not None:
                    seam_from = anchor_output(ar) if verdict == "better" else None
                    return self._flow_result(got, int(ar.markers), seam_from=seam_from)
        return self._fit_frame(ar, feats, young)

    def _features(self, fut, ar, detect: bool, young: bool) -> tuple[Features, bool]:
        """This full frame's keypoints (possibly none), and whether their extraction waits for the anchors
        (`defer`: an empty map needs them only if the anchors are found, to start it)."""
        frame, kfs = self.frame, self.keyframes
        # while the map is young, features are only needed on frames that may become keyframes
        # (and always when the anchors were just lost: the map has to take over on this very frame)
        need_feats = (not (young and (detect or ar is not None)) or frame.index - kfs.last_frame >= 5
                      or len(self.map.keyframes) == 0 or (ar is not None and not anchor_usable(ar))
                      or self.room.checks_often(frame.index))   # (the anchors' check needs them)
        # an empty map (nothing to match, no keyframe on its way) needs this frame's features only if the
        # anchors are found in it, to start the map: not extracted beside the detection then, but after it
        defer = need_feats and fut is not None and len(self.map.keyframes) == 0 and self.mapper.pending == 0
        if need_feats and not defer and fut is None and self._fast_predicted():
            # the worker is free and the flow will most likely be needed: features there, flow here
            ffut = self._pool.submit(self.extractor.extract, frame.gray)
            self._follow_from_last()   # kept for this frame
            return ffut.result(), defer
        return (self.extractor.extract(frame.gray) if need_feats and not defer else Features.empty()), defer

    def _fit_frame(self, ar, feats, young: bool) -> TrackResult:
        """The full frame's pose: the anchors' corners with the map (`PoseFits.with_anchors`; not when they
        cannot start the pose), else the map alone, else `_without_fit`; then keyframe and flow tracks."""
        st, frame = self.status, self.frame
        corners_w, corners_uv, markers = anchor_points(ar, self.camera)
        if (len(corners_w) and (st.lost > 0 or self.motion.last is None)
                and self.handover.cannot_start(ar, frame)):
            corners_w, corners_uv = corners_w[:0], corners_uv[:0]   # the map may still relocalise
        pred = self.motion.predict(frame.t)
        arrays = self.map.arrays()
        if len(corners_w):
            fit = self._fit_on_anchors(ar, corners_w, corners_uv, feats, pred, arrays, young)
        else:
            fit = self.fits.from_map(feats, pred, arrays, frame.t)
        if fit is None:
            return self._without_fit(ar, pred, markers)
        if self._grow_map(ar, feats, fit, corners_w, corners_uv):
            return self._finish(fit.pose, pred, fit.state, fit.source, fit.out_pose, markers, fit.inliers,
                                precise=fit.precise)
        # the anchors were seen to move on this very frame: their pose is shown, the map is gone
        return self._finish(fit.pose if fit.out_pose is None else fit.out_pose, pred, "marker", "anchors", None,
                            markers, fit.inliers, precise=precise(ar))

    def _grow_map(self, ar, feats, fit: Fit, corners_w, corners_uv) -> bool:
        """The full frame's map work after its fit: matches counted, a keyframe considered, the flow's tracks
        started on its keypoints; False (none of it) once the anchors were seen to move in the room."""
        frame = self.frame
        if self.room.moving:
            self.flow.tracks = None
            return False
        self.map.count_matches(fit.visible, fit.point_ids)
        if ar is None or not ar.ambiguous:
            # (not while a lone head-on marker's tilt is undecided: the map's points would be triangulated
            # from a pose up to 20 degrees off, and once the desk decides, that map pulls the joint fit,
            # and with it the motion model, back to the wrong tilt until the anchors' pose reads as a jump)
            self.keyframes.consider(frame.index, frame.t, fit.pose, feats, fit.point_ids, fit.feature_idx,
                                    corners_w, corners_uv, fit.state, fit.points, fit.inliers)
        self.flow.start_tracks(frame.gray, feats, fit)
        return True

    def upkeep(self) -> bool:
        """The keypoint work a frame left for later (`TrackerConfig.defer_upkeep`): its features, the joint fit
        with the anchors (which checks the room and gives the keyframe's pose) and the map's growth, as its
        full frame would have done them; the frame's result stands. Returns whether there was any."""
        pending, self._pending = self._pending, None
        if pending is None:
            return False
        ar, feats = pending[0], pending[1].result()
        corners_w, corners_uv, _ = anchor_points(ar, self.camera)
        fit = self._fit_on_anchors(ar, corners_w, corners_uv, feats, self.motion.predict(self.frame.t),
                                   self.map.arrays(), False)
        if fit is not None:
            self._grow_map(ar, feats, fit, corners_w, corners_uv)
        return True

    def _fit_on_anchors(self, ar, corners_w, corners_uv, feats, pred, arrays, young: bool) -> Fit:
        """The joint fit of the anchors' corners and the map, from the anchors' raw pose, or from the motion
        model's prediction when that pose is implausible (a flipped planar solution: the corners pull from
        the tracked pose). Otherwise the background is checked against the anchors first (`room`)."""
        st, t = self.status, self.frame.t
        anchor_pose = np.asarray(ar.raw_world_from_camera, float)
        init = anchor_pose
        # (a lone head-on marker's pose from the desk around it, `ar.desk`, holds the tilt its four corners
        # cannot: it is the start even where it jumps from the motion, which followed the marker's own guess
        # of the tilt until the desk decided; from the motion the corners alone keep the wrong tilt)
        if pred is not None and st.lost == 0 and not ar.desk and not self.handover.plausible(anchor_pose, pred, t):
            init = pred
        elif len(feats):
            _, X, D = arrays
            steady = st.lost == 0 and self.motion.steps >= 3
            if self.room.check(ar, anchor_pose, corners_w, feats, X, D, self.frame.index, steady):
                self._drop_map()
        return self.fits.with_anchors(ar, anchor_pose, init, corners_w, corners_uv, feats, arrays, young, t, st.lost)

    def _drop_map(self) -> None:
        """The anchors move in the room: the map, which holds the room, is dropped and no longer built."""
        if self.mapper is not None:
            self.mapper.wait_idle()
        self.map.clear()
        self.keyframes.submissions = []
        self.flow.tracks = None
        # nor may the anchors' desk judge (a lone marker's tilt from the keypoints around it, taken to lie on
        # its plane: tracking.anchors.desk) follow the surroundings any longer: a wall behind a held card
        # moves in the image as no point on the card does, and its fit pulls the pose centimetres off
        if self.anchor_tracker.desk is not None:
            self.anchor_tracker.desk.reset()
            self.anchor_tracker.desk = None
        # a lone marker's tilt is judged by the card it is printed on instead (its points that move with it,
        # followed since the first frame: their places rest on many frames by now)
        if self.anchor_tracker.card is not None:
            self.anchor_tracker.card.carries = True

    def _without_fit(self, ar, pred, markers: int) -> TrackResult:
        """Neither anchors nor the map gave a pose: flow from the last frame, else the partly covered
        anchors as their filter weighed them, else lost."""
        got = self._follow_from_last()
        if got is not None:
            return self._flow_result(got, markers)
        if ar is not None and ar.covered and ar.world_from_camera is not None:
            cw, cuv, n = anchor_points(ar, self.camera, covered_too=True)
            pose = np.asarray(ar.world_from_camera, float)
            return self._finish(pose, pred, "marker", "anchors", None, n, len(cw))
        return self._lost_frame(markers)

    # -- pieces ---------------------------------------------------------------------
    def _measure_anchors(self, follow) -> tuple[object, tuple | None]:
        """The anchor tracker's result this frame, and `follow()`'s (one frame of flow) when the motion model
        predicts it will be needed (`_fast_predicted`): it then runs on this thread while the anchors are
        measured on the worker; else None."""
        frame, got = self.frame, None
        ref = self._reference()
        if self._fast_predicted():
            fut = self._pool.submit(self.anchor_tracker.process, frame.gray, frame.t, ref)
            got = follow()
            ar = fut.result()
        else:
            ar = self.anchor_tracker.process(frame.gray, frame.t, ref)
        self._note_anchors(ar)
        self.status.since_detect = 0
        return ar, got

    def _submit_detection(self):
        """The anchors' detection on the worker thread (a future of the anchor tracker's result)."""
        return self._pool.submit(self.anchor_tracker.process, self.frame.gray, self.frame.t, self._reference())

    def _follow_from_last(self):
        """`FlowFollower.follow_from_last` for this frame (once a frame)."""
        return self.flow.follow_from_last(self.frame, self.status.lost)

    def _follow_on_anchors(self):
        """`FlowFollower.follow_on_anchors` for this frame (once a frame)."""
        return self.flow.follow_on_anchors(self.frame, self.status.lost, self.anchor_tracker.outlines)

    def _note_anchors(self, ar) -> None:
        """Remember the corners the anchors measured (for `_fast_predicted` on the next frame), and their result
        on this frame (for `_finish`)."""
        if ar is not None:
            read = int(ar.markers) > 0
            self.smear_gate.passed(read, None if read else self._anchor_motion())
        if ar is not None and ar.raw_world_from_camera is not None and len(ar.object_points) >= 4:
            self.anchor.corners = np.asarray(ar.object_points, float).reshape(-1, 3)
            self.frame.anchors = ar

    def _anchor_motion(self) -> tuple[float, float] | None:
        """`SmearGate.measure` of every anchor this frame (once a frame), None without a velocity."""
        frame, motion = self.frame, self.motion
        if frame.anchor_motion is None and motion.last is not None and motion.velocity is not None:
            frame.anchor_motion = self.smear_gate.measure(self._outlines, motion.last, motion.predict(frame.t),
                                                          motion.last_step(), frame.t - motion.last_t)
        return frame.anchor_motion

    def _fast_predicted(self) -> bool:
        """Whether the motion model alone moves the corners the anchors last measured `smear_px` or more in
        the image since the last frame: the flow will very likely be needed this frame, so it is worth
        starting before the anchors' measurement is in (it only ever runs ahead, never changes results)."""
        motion, corners = self.motion, self.anchor.corners
        if (not self.config.flow or self._pool is None or motion.last is None or corners is None
                or motion.velocity is None or self.flow.prev_gray is None):
            return False
        return self.handover.corner_motion(corners, motion.predict(self.frame.t)) >= self.config.smear_px

    def _reference(self) -> np.ndarray | None:
        """This frame's pose as the motion model (anchors, map or flow) predicts it, for the anchor tracker
        to screen anchors it has never seen (None while lost: then nothing holds the pose)."""
        if self.status.lost == 0 and self.motion.last is not None:
            return self.motion.predict(self.frame.t)
        return None

    def _flow_result(self, got, markers: int, seam_from: np.ndarray | None = None) -> TrackResult:
        """A frame carried by the flow's pose `got`. `seam_from`: the anchors' pose this frame when they lost
        to the flow only for holding the position worse (`Handover.flow_holds_better`); a seam then fades from
        there, not from the motion model's guess (a pan speeding up outruns that by millimetres), and as onto
        precise anchors (`precise_blend_frames`, from this frame on): the flow is the better pose."""
        t = self.frame.t
        start = self.flow.stretch_start(t)
        res = self._finish(got[0], self.motion.predict(t), "slam", None, None, markers, len(got[1]),
                           precise=seam_from is not None, seam_from=seam_from)
        self.flow.carried(got[1], start)
        return res

    def _finish(self, pose, pred, state, source, out_pose, markers, inliers,
                precise: bool = False, seam_from: np.ndarray | None = None) -> TrackResult:
        """Close a tracked frame: `pose` (world_from_camera) goes to the motion model, `out_pose` (else
        `pose`) is shown, faded at a change of `source` (over `precise_blend_frames` when `precise`; from
        `seam_from` when given, see `Output.show`)."""
        frame, mem, st = self.frame, self.anchor, self.status
        mem.since = 0 if state == "marker" else mem.since + 1
        if state == "marker":
            mem.t = frame.t
            # (the anchors measured this very frame when they give its pose)
            mem.spread = None if frame.anchors is None else self.handover.anchor_spread(frame.anchors)
        anchored = state == "marker" or (mem.anchored and mem.since < self.config.marker_every)
        if source is None:
            source = "fused" if anchored else "map"
        out = self.output.show(pose if out_pose is None else out_pose, pred, source, frame, st.lost, precise,
                               seam_from)
        mem.anchored = anchored
        self.motion.update(pose, frame.t)
        st.lost = 0
        st.last_state = state
        self.flow.tracked(frame.gray)
        return TrackResult(out, state, markers, inliers, frame.ms(),
                           ambiguous=state == "marker" and self.anchor_tracker.ambiguous)

    def _lost_frame(self, markers: int) -> TrackResult:
        """A frame without a pose."""
        self.status.lost += 1
        self.anchor.spread = None
        self.smear_gate.reset()
        self.flow.lose()
        self.motion.lose()
        self.output.lose()
        self.status.last_state = "lost"
        return TrackResult(None, "lost", markers, 0, self.frame.ms())

    def _marker_only(self, bgr) -> TrackResult:
        """Marker-only tracking (`slam` off): the anchors' own filtered pose."""
        ar = self.anchor_tracker.process(bgr, self.frame.t)
        if ar.world_from_camera is None:
            return self._lost_frame(int(ar.markers))
        self.status.lost = 0
        return TrackResult(np.asarray(ar.world_from_camera, float), "marker", int(ar.markers), int(ar.inliers),
                           self.frame.ms(), ambiguous=ar.ambiguous)
