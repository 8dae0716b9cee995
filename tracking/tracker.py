"""The combined tracker the pipeline uses: anchors (markers, QR) fused with SLAM-style keypoint tracking.

    tr = Tracker(camera, anchors, slam=True)   # settings: TrackerConfig (or its names as keywords)
    res = tr.process(image_bgr, t)      # TrackResult(world_from_camera, state, markers, inliers, ms)
    tr.close()                          # stops the mapping / bundle-adjustment thread

Poses are `world_from_camera` 4x4 in the first anchor's frame (metres, OpenCV
camera axes). States: `marker` (anchors measured this frame and used),
`slam` (pose from map keypoints only), `lost` (no pose).

While the anchors were measured on the last frame, each frame first asks the
anchor tracker (which re-finds the markers / QR corners where its prediction
puts them, cheaper than a detector pass): if it measures them, its pose is the
frame's pose, and keypoint work (ORB, map matching, keyframes) runs only every
`keypoint_every`-th frame to keep the map growing for when the anchors go.
Otherwise: markers are detected on a worker thread (every frame while lost or
while the map is young, else every `marker_every`-th frame) while ORB features
are extracted; map points are matched by projection from a constant-velocity
prediction; the pose is a robust joint fit of marker corners and map points
(anchors dominate), or of map points alone, or comes from relocalisation. When
all of that fails on a frame that follows a tracked one (motion blur smears
markers and descriptors alike), keypoints are followed from the last frame by
optical flow (`tracking.slam.flow`) and carry the pose. Under fast motion the flow
also checks the anchors for smear; when the motion model predicts it, it runs on
this thread while the anchors are measured on the worker (OpenCV releases the
interpreter; the results are those of running one after the other), and its
points are followed on from frame to frame while the anchors carry the pose
(plane seeds placed again from the anchors' pose) instead of being seeded anew.
When a board (12+ corners) returns after frames carried by the map or flow, the
output fades onto it over `precise_blend_frames`, fewer than other seams take.
New keyframes go to
the mapping thread (triangulation, culling, local bundle adjustment with anchor
corners as constraints); `process` never waits for it. Offline drivers, which
feed frames faster than a camera would, call `catch_up()` between frames so the
map keeps the pace it would have live, whatever the machine's load.

Anchors that move in the room (a card held up to a webcam, `anchors_moving`): on keypoint frames the
background (ORB features off the anchors between two checked frames, and the map's points off them) is
tested against the anchors' poses (`tracking.slam.anchor_motion`); once it disagrees, the map is dropped
and no longer built, only flow on points of the anchors' own plane within their outline carries unreadable
frames, and a frame nothing on the anchors carries is lost.

Anchor measurements that must not move the model: a lone marker whose white
margin is partly covered (a hand reaching in, `anchors.occlusion`) is not shown
as it is; the map, else flow, carries the pose, else the anchors' filter with
the measurement weighted little. An anchor never seen before in the session
that lands far from where the motion model puts the camera (a look-alike
pattern) is left out while anything else holds the pose (`TrackerConfig`).
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.poses import invert, rotation_angle
from tracking.session import AnchorSpec
from tracking.slam.features import FeatureExtractor, Features
from tracking.anchors.edges import edge_sharpness
from tracking.slam.anchor_motion import MIN_BACKGROUND, background_rigid, disagrees, on_anchor, outline_region
from tracking.slam.flow import Tracks, follow, relift, seed_on_plane
from tracking.slam.fusion import PoseBlender, fuse_pose
from tracking.slam.map import Map
from tracking.slam.mapping import KeyframeRequest, LocalMapper
from tracking.slam.relocalise import relocalise
from tracking.slam.tracking import (MotionModel, match_by_projection, plausible, pnp_ransac, position_spread,
                                    refine_pose)

# checks in a row on which the background map disagrees with the anchors (`anchor_motion.disagrees`) before
# the anchors count as moving in the room: one check can meet a flipped lone marker or a map point mismatch
MOVED_CHECKS = 2
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
MOVED_REF_FRAMES = 45   # frames after which the test's earlier frame is too old to compare with
# the most the flow's camera position on moving anchors may be expected to be off (its spread at 1 px), as a
# fraction of the camera's distance from its points: a board's ~100 points hold it to ~0.2 %, the few
# points of a lone marker's bits drift by centimetres within frames (then lost is the honest answer)
MOVING_FLOW_SPREAD = 0.03

MIN_SIDE = 48  # pixels: smaller frames carry nothing trackable
MAX_TRACKS = 200  # keypoints followed by optical flow between full frames
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
FLOW_SEEDS = 300  # points followed by optical flow when the anchors and the map both fail
# metres a frame the flow's camera position drifts from the anchors' pose it started from, to weigh the flow
# against a board's measurement (`_flow_holds_better`): on the tuning pans' flow stretches the error grows
# by 0.1-0.4 mm a frame; 0.2 and 0.3 mm gave the same tracking on them, 0.5 took bad boards back too often
FLOW_DRIFT_M = 0.0003


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


@dataclass
class _Fit:
    """A frame's pose fit on a full frame: `pose` world_from_camera, `state` ("marker" / "slam"),
    `inliers` count; the map points it used: `point_ids`, their features `feature_idx` and world
    positions `points` (N,3); `visible` the map points matched at all; `source`/`out_pose` what to
    show instead of `pose` (the anchors' own pose), when set."""

    pose: np.ndarray
    state: str
    inliers: int
    point_ids: np.ndarray
    feature_idx: np.ndarray
    points: np.ndarray
    visible: np.ndarray
    source: str | None = None
    out_pose: np.ndarray | None = None
    precise: bool = False   # `out_pose` is the anchors' pose measured on 12+ corners


def _has_content(gray) -> bool:
    """False for a frame that is black, blown out or blank (nothing to track in it)."""
    if gray is None:
        return False
    mean, std = cv2.meanStdDev(gray[::8, ::8])   # a seventh of numpy's mean + std here
    m, s = float(mean[0, 0]), float(std[0, 0])
    return 6.0 < m < 250.0 and s > 2.0


@dataclass
class TrackerConfig:
    """Every setting of `Tracker`, with its unit. `Tracker(camera, anchors, config=TrackerConfig(...))`, or
    the same names as keyword arguments (`Tracker(camera, anchors, marker_every=2)`), which override
    `config`'s fields."""

    slam: bool = True
    """False: marker-only tracking (the anchors' own filtered pose); no map, no keypoints."""
    marker_every: int = 4
    """frames: marker detection period once the map carries the pose."""
    n_features: int | None = None
    """ORB keypoints per frame; None scales with the resolution (400..1500)."""
    ba: bool = True
    """run local bundle adjustment on new keyframes."""
    threaded: bool = True
    """mapping on its own thread; False maps inline (deterministic, for tests)."""
    max_speed: float = 2.5
    """m/s: faster-looking camera jumps between frames are rejected as implausible."""
    max_angular: float = 5.0
    """rad/s: the same for rotation."""
    blend_frames: int = 8
    """frames over which the step at a seam between pose sources (anchors / fused / map) is faded."""
    precise_blend_frames: int = 5
    """frames over which a seam is faded when the output switches to the anchors measured on 12 or more
    corners (a board, a QR code, several markers; none partly covered), the first step taken on the switch
    frame itself: they are good to millimetres, while what the output fades from (the map, flow) may have
    drifted by centimetres."""
    fast_blend_frames: int = 1
    """frames over which a seam is faded while the view moves `smear_px` or more a frame (a fast pan): a step
    of a few pixels is lost in such motion, and each frame of fade keeps showing the old source's error
    (1: the new source is shown at once)."""
    min_inliers: int = 20
    """map points a keypoint-only pose needs."""
    radius: float = 12.0
    """pixels: search radius when matching map points by projection."""
    keyframe_parallax: float = 0.08
    """fraction of the scene depth the camera moves before a new keyframe."""
    corner_weight: float = 4.0
    """weight of an anchor corner against one map point in the joint fit."""
    corner_share: float = 1 / 3
    """least share of the joint fit's total weight held by the anchor corners (0.8 while the map is young)."""
    filter: bool = True
    """smooth the anchors' own pose (their PoseFilter) on marker-only frames."""
    max_pending: int = 2
    """keyframes waiting for the mapping thread beyond which a new keyframe is skipped (tracking never
    waits for mapping; the next frame asks again)."""
    max_lag: int = 3
    """frames: what `catch_up()` (offline drivers only) guarantees: a keyframe's mapping is finished this
    many frames after it was submitted (one frame while the anchors carry the pose). Live at 30 fps,
    3 frames = 100 ms covers it without any waiting."""
    klt: bool = True
    """between full frames, follow the last inlier keypoints by optical flow instead of detecting and
    matching ORB features (much cheaper per frame)."""
    flow: bool = True
    """when the anchors and the map both fail on a frame after a tracked one, follow keypoints (map
    points, else points seeded on the anchors' plane) from the last frame by optical flow."""
    anchor_first: bool = True
    """while the anchors are in view their tracker's pose is the output (raw for 12+ corners, filtered
    for a lone marker), and keypoints are extracted only every `keypoint_every`-th frame (and when the
    anchors are not found); False: the joint marker + keypoint fit on every detection frame."""
    keypoint_every: int = 10
    """frames: keypoint work period while the anchors carry the pose."""
    smear_px: float = 10.0
    """pixels: under fast motion markers are smeared and their corners can be off by pixels. When the
    anchors may have moved this far since the last frame, one frame of flow is computed as well; if the
    flow confirms the motion, the markers' edges across it are soft (`smear_sharpness`) and the flow pose
    puts the marker corners more than `smear_gate_px` from where they were detected, the flow pose is
    used, for at most `smear_hold_s` since the anchors were last accepted."""
    smear_sharpness: float = 0.15
    """`anchors.edges.edge_sharpness` below which edges count as smeared (about 1/pixels of smear)."""
    start_sharpness: float = 0.2
    """when nothing holds the pose (the first sighting, or after a loss), anchors whose edges are softer
    than this across x or y (`anchors.edges.edge_sharpness`: about 1/pixels of motion smear) do not start
    it: a board caught mid-pan with a few smeared markers reads centimetres off, and the next frames (or
    the map) start it better. 0 turns the check off."""
    smear_gate_px: float = 1.0
    """pixels: median gap between flow-projected and detected marker corners that distrusts the markers."""
    smear_hold_s: float = 1.0
    """seconds: the longest the flow overrules smeared markers (after that they win again, so flow drift
    is always bounded by the markers). 1 s: since the flow fits each point at the centre row's time
    (rolling shutter), its drift over a fast pan's second stays under the error of a board returning
    smeared (0.5 s let that board pull the pose 2 cm off on the tuning pans)."""
    flow_hold_s: float = 2.0
    """seconds: the longest that flow alone (neither anchors nor map confirming) carries the pose; after
    that the frame is lost until the anchors or the map take it up again."""
    cover_fraction: float = 0.2
    """fraction of a lone marker's side whose white margin looks covered (a hand reaching in,
    `anchors.occlusion`) from which its measurement is distrusted: the map or flow carry the pose, else
    the anchors' filter with the measurement weighted `cover_weight`. 0 turns the check off."""
    cover_weight: float = 0.1
    """weight (0..1) of a partly covered marker's measurement in the anchors' filter."""
    jump_px: float = 0.0
    """pixels: on a steady camera (the markers predicted to move under smear_px / 2 since the last frame),
    a lone marker with a corner this far from the motion model's prediction is checked against one
    frame of optical flow; if the flow pose agrees with the prediction and not with the
    corners (the marker jumped, the scene did not: a finger dragging a corner), the flow pose is used,
    for at most `smear_hold_s`. 0 (the default) turns the check off: at 1 px it catches a one-frame
    corner jump on a steady camera, but on a floor of identical tiles at 15 fps the flow pose agreed with
    the prediction and overruled a correct marker; the margin check (`cover_fraction`) is what is on."""
    new_anchor_gate: float = 0.5
    """an anchor never seen before in the session is used only if its corners lie within this many of its
    own image sizes of where the current pose (motion model, map) puts them: a look-alike pattern must
    not teleport the model. 0 turns the check off."""


def _config(config: TrackerConfig | None, overrides: dict) -> TrackerConfig:
    """`config` (default TrackerConfig()) with keyword overrides; unknown names fail with the list."""
    import dataclasses

    base = config if config is not None else TrackerConfig()
    names = {f.name for f in dataclasses.fields(TrackerConfig)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise TypeError(f"Tracker: unknown setting(s) {', '.join(unknown)}; "
                        f"TrackerConfig has {', '.join(sorted(names))}")
    return dataclasses.replace(base, **overrides)


class Tracker:
    """Anchors + keypoint SLAM. See the module docstring; settings: `TrackerConfig` (as `config`, or
    its field names as keyword arguments; `slam` may also be given positionally)."""

    def __init__(self, camera: Camera, anchors: list[AnchorSpec], slam: bool | None = None, *,
                 config: TrackerConfig | None = None, **settings):
        if slam is not None:
            settings["slam"] = slam
        cfg = self.config = _config(config, settings)
        slam, marker_every, n_features, ba = cfg.slam, cfg.marker_every, cfg.n_features, cfg.ba
        threaded, max_speed, max_angular = cfg.threaded, cfg.max_speed, cfg.max_angular
        blend_frames, min_inliers, radius = cfg.blend_frames, cfg.min_inliers, cfg.radius
        keyframe_parallax, corner_weight, corner_share = cfg.keyframe_parallax, cfg.corner_weight, cfg.corner_share
        filter, max_pending, max_lag, klt, flow = cfg.filter, cfg.max_pending, cfg.max_lag, cfg.klt, cfg.flow
        anchor_first, keypoint_every = cfg.anchor_first, cfg.keypoint_every
        smear_px, smear_sharpness = cfg.smear_px, cfg.smear_sharpness
        smear_gate_px, smear_hold_s, flow_hold_s = cfg.smear_gate_px, cfg.smear_hold_s, cfg.flow_hold_s
        from tracking.anchors import AnchorTracker  # the anchors package is built alongside

        if not anchors:
            raise ValueError("Tracker needs at least one anchor to define the world frame; "
                             "list the markers in session.json 'anchors'")
        self.camera = camera
        self.slam = bool(slam)
        self.marker_every = max(1, int(marker_every))
        self.max_speed, self.max_angular = max_speed, max_angular
        self.min_inliers = min_inliers
        self.radius = radius
        self.keyframe_parallax = keyframe_parallax
        self.corner_weight = corner_weight
        self.corner_share = corner_share
        self.max_pending = max(1, int(max_pending))
        self.max_lag = max(1, int(max_lag))
        self.klt = klt
        self.flow = flow
        self.smear_px, self.smear_sharpness = smear_px, smear_sharpness
        self.smear_gate_px, self.smear_hold_s = smear_gate_px, smear_hold_s
        self.flow_hold_s = flow_hold_s
        self.jump_px = cfg.jump_px
        self.start_sharpness = cfg.start_sharpness
        self.anchor_first = bool(anchor_first)
        self.keypoint_every = max(1, int(keypoint_every))
        self._kf_submissions: list[tuple[int, int]] = []   # (frame, mapper request number)
        self.K = camera.K.copy()
        # the anchors' own filter smooths the marker-only frames before the map carries the pose
        self._anchors = AnchorTracker(anchors, camera, filter=filter, cover_fraction=cfg.cover_fraction,
                                      cover_weight=cfg.cover_weight, new_anchor_gate=cfg.new_anchor_gate)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="anchors") if slam else None
        if n_features is None:
            n_features = int(np.clip(camera.width * camera.height / 300, 400, 1500))
        self.extractor = FeatureExtractor(camera, n_features=n_features)
        self.map = Map()
        self.mapper = LocalMapper(self.map, self.K, ba=ba, threaded=threaded) if slam else None
        self.blender = PoseBlender(blend_frames)
        self.precise_blend_frames = max(1, int(cfg.precise_blend_frames))
        self.fast_blend_frames = max(1, int(cfg.fast_blend_frames))
        self.motion = MotionModel()
        self._reset_state()

    # -- lifecycle ------------------------------------------------------------------
    def _reset_state(self) -> None:
        self._frame = 0
        self._since_detect = 10**9
        self._lost = 0
        self._last_good_t: float | None = None
        self._last_state = "lost"
        self._anchored = False
        self._since_anchor = 10**9
        self._source = None
        self._anchor_kfs = 0
        self._last_out: np.ndarray | None = None
        self._kf_frame = -(10**9)
        self._flow: Tracks | None = None   # points followed by flow, measured in the last frame
        self._gray: np.ndarray | None = None        # this frame's grey image
        self._prev_gray: np.ndarray | None = None   # the last tracked frame's grey image
        self._full_tracks = 0
        self._kf_inliers = 0
        self._depth = 0.5
        self._full_frame = -(10**9)
        self._anchor_t: float | None = None   # when the anchors last gave the pose
        self._anchor_spread_last: float | None = None   # the anchors' last pose's expected error (m; boards)
        self._anchors_now: tuple | None = None          # (frame, the anchors' result there)
        self._via_flow = False                 # the last frame's pose came from flow
        self._flow_start: float | None = None  # when flow alone began to carry the pose
        self._followed: tuple[int, tuple | None] | None = None   # (frame, `_follow_from_last`'s result there)
        self._anchor_corners: np.ndarray | None = None   # world corners (N,3) the anchors measured last
        self._sharpness: tuple[int, float] | None = None   # (frame, `_start_sharpness` there)
        self._moving = False   # the anchors were seen to move in the room (`_check_moved`): map off, flow on them
        self._moved_votes = 0  # background-map checks in a row that disagreed with the anchors
        self._moved_strong = False   # the last check that disagreed did so beyond doubt (MOVED_SURE)
        self._moved_ref: tuple | None = None   # (frame, Features, anchors' pose, their outline px) to compare with

    def reset(self) -> None:
        """Forget the map and the motion; the next frame starts from the anchors."""
        if self.mapper is not None:
            self.mapper.wait_idle()
        self.map.clear()
        self._kf_submissions = []
        self.motion.reset()
        self.blender.reset()
        self._anchors.reset()
        self._reset_state()

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
        from tracking.slam.map_io import adopt

        self.reset()
        adopt(self.map, saved)

    def export_map(self) -> Map:
        """The map as it stands once queued keyframes are mapped (to save in a scene file)."""
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
        nxt = self._frame + 1
        lag = 1 if self._last_state == "marker" and self.anchor_first else self.max_lag
        while self._kf_submissions and nxt - self._kf_submissions[0][0] >= lag:
            _, n = self._kf_submissions.pop(0)
            self.mapper.wait_done(n)

    # -- per frame ------------------------------------------------------------------
    def _prepare(self, image) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(image for the anchors, grey image) at the camera's size, or (None, None) if unusable."""
        if image is None:
            return None, None
        img = np.asarray(image)
        if img.ndim not in (2, 3) or img.shape[0] < MIN_SIDE or img.shape[1] < MIN_SIDE:
            return None, None
        if img.dtype != np.uint8:
            if np.issubdtype(img.dtype, np.floating):
                img = np.clip(np.nan_to_num(img) * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
            else:
                img = np.clip(img, 0, 255).astype(np.uint8)
        if img.ndim == 3 and img.shape[2] == 4:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
        elif img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        elif img.ndim == 3 and img.shape[2] != 3:
            return None, None
        h, w = img.shape[:2]
        if (w, h) != self.camera.size:
            # another resolution of the same lens only if the aspect ratio agrees
            if abs(w / h - self.camera.width / self.camera.height) > 0.02:
                return None, None
            img = cv2.resize(img, self.camera.size, interpolation=cv2.INTER_LINEAR)
        gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        bgr = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        return bgr, gray

    def process(self, image: np.ndarray, t: float) -> TrackResult:
        """Track one frame (BGR or grey uint8, camera size) taken at time t seconds."""
        t0 = time.perf_counter()
        self._frame += 1
        bgr, gray = self._prepare(image)
        self._gray = gray
        if not _has_content(gray):
            return self._lost_frame(t0, 0)
        if not self.slam:
            return self._marker_only(bgr, t, t0)
        if self._moving:
            return self._moving_anchor_frame(gray, t, t0)

        young = len(self.map.points) < 60 or len(self.map.keyframes) < 4
        detect = self._since_detect + 1 >= self.marker_every or self._lost > 0 or young or self.motion.last is None
        ar = None
        anchor_first = (self.anchor_first and self._last_state == "marker" and self._lost == 0
                        and self.motion.last is not None)
        if anchor_first:
            res, ar = self._anchors_first(gray, t, t0)
            if res is not None:
                return res
            detect = False
        elif not detect and self.klt:
            res = self._klt_frame(gray, t, t0)
            if res is not None:
                self._since_detect += 1
                return res
        got, flow_tried = None, False
        if self._via_flow and self._frame - self._full_frame < self.keypoint_every:
            # Flow carried the last frame (motion blur defeats markers and descriptors alike): flow
            # again beside the marker detection, and the full keypoint work only when both fail or
            # every `keypoint_every` frames, to get back onto the map.
            fut = self._pool.submit(self._anchors.process, gray, t, self._reference(t)) if detect else None
            got, flow_tried = self._follow_from_last(gray, t), True
            if fut is not None:
                ar = fut.result()
                self._note_anchors(ar)
                self._since_detect = 0
                detect = False
            else:
                self._since_detect += 1
            usable = self._anchor_usable(ar) and self._plausible(self._anchor_output(ar), self.motion.last, t)
            # a board seen in part as it comes back (one marker at the image edge, sharp at a pan's turn) can
            # read centimetres off (its tilt and the camera's shift trade off): it does not take over from the flow
            if got is not None and (not usable or self._smeared(ar, got, gray, t) or self._partial_view(ar)
                                    or self._flow_holds_better(ar, got, t)
                                    or (self._jumped(ar, t) and self._flow_disagrees(ar, got, t))):
                return self._flow_result(got, t, t0, int(ar.markers) if ar is not None else 0)
        self._full_frame = self._frame
        fut = self._pool.submit(self._anchors.process, gray, t, self._reference(t)) if detect else None
        # while the map is young, features are only needed on frames that may become keyframes
        # (and always when the anchors were just lost: the map has to take over on this very frame)
        need_feats = (not (young and (detect or ar is not None)) or self._frame - self._kf_frame >= 5
                      or len(self.map.keyframes) == 0 or (ar is not None and not self._anchor_usable(ar)))
        # an empty map (nothing to match, no keyframe on its way) needs this frame's features only if the
        # anchors are found in it, to start the map: not extracted beside the detection then, but after it
        defer = need_feats and fut is not None and len(self.map.keyframes) == 0 and self.mapper.pending == 0
        if need_feats and not defer and fut is None and self._fast_predicted(t):
            # the worker is free and the flow will most likely be needed: features there, flow here
            ffut = self._pool.submit(self.extractor.extract, gray)
            self._follow_from_last(gray, t)   # kept for this frame
            feats = ffut.result()
        else:
            feats = self.extractor.extract(gray) if need_feats and not defer else Features.empty()
        if fut is not None:
            if self._fast_predicted(t):
                self._follow_from_last(gray, t)   # while the detection runs (the result is kept for this frame)
            ar = fut.result()
            self._note_anchors(ar)
            self._since_detect = 0
        elif ar is None:
            self._since_detect += 1
        if defer and len(self._anchor_points(ar)[0]):
            feats = self.extractor.extract(gray)
        if (not flow_tried and self._anchor_usable(ar)
                and self._plausible(self._anchor_output(ar), self.motion.last, t)):
            jumped = self._jumped(ar, t)
            if jumped or self._moving_fast(ar, t):
                got, flow_tried = self._follow_from_last(gray, t), True
                if self._smeared(ar, got, gray, t) or (jumped and self._flow_disagrees(ar, got, t)):
                    return self._flow_result(got, t, t0, int(ar.markers))
                if self._flow_holds_better(ar, got, t):
                    return self._flow_result(got, t, t0, int(ar.markers), seam_from=self._anchor_output(ar))

        corners_w, corners_uv, markers = self._anchor_points(ar)
        if (len(corners_w) and (self._lost > 0 or self.motion.last is None)
                and (self._too_smeared_to_start(ar, gray) or self._partial_view(ar)
                     or self._start_uncertain(ar, gray))):
            corners_w, corners_uv = corners_w[:0], corners_uv[:0]   # the map may still relocalise
        pred = self.motion.predict(t)
        ids, X, D = self.map.arrays()
        if len(corners_w):
            fit = self._fuse_with_anchors(ar, corners_w, corners_uv, feats, pred, ids, X, D, young, t)
        else:
            fit = self._from_map(feats, pred, ids, X, D, t)
        if fit is None:
            return self._without_fit(gray, t, t0, got, flow_tried, ar, pred, markers)
        if self._moving:
            # the anchors were seen to move on this very frame (`_check_moved`): their pose is shown, the map is gone
            self._flow = None
            return self._finish(fit.pose if fit.out_pose is None else fit.out_pose, pred, "marker", "anchors", None,
                                markers, fit.inliers, t, t0, precise=self._precise(ar))
        self.map.count_matches(fit.visible, fit.point_ids)
        self._maybe_keyframe(t, fit.pose, feats, fit.point_ids, fit.feature_idx, corners_w, corners_uv, fit.state,
                             fit.points, fit.inliers)
        self._start_tracks(gray, feats, fit)
        return self._finish(fit.pose, pred, fit.state, fit.source, fit.out_pose, markers, fit.inliers, t, t0,
                            precise=fit.precise)

    @property
    def anchors_moving(self) -> bool:
        """Whether the anchors were seen to move in the room this session (a card held before the camera):
        the keypoint map is off, and only points on the anchors carry the pose across unreadable frames."""
        return self._moving

    def _check_moved(self, ar, anchor_pose, corners_w, feats, X, D) -> None:
        """Compare the anchors' pose this frame with the pose the map's points off the anchors give, fitted
        from it (`_track_map`); when they disagree beyond both fits' expected errors (`anchor_motion.
        disagrees`) on `MOVED_CHECKS` checks in a row, the anchors move in the room (a card held up to a
        webcam): the map, which holds the room, is dropped and no longer built (`_moving`)."""
        if self._moving or len(feats) < self.min_inliers or ar.covered:
            return
        # only a board that fits well holds its turn to a few hundredths of a degree; a lone marker's pose turns
        # by a degree with its noise (5-9 px at the image edge: a still desk then reads as moving)
        verdict = (self._background_verdict(anchor_pose, feats)
                   if self._lost == 0 and self.motion.steps >= 3 and self._board_fit(ar) is not None
                   and self._fits_well(ar) else None)
        off = ~on_anchor(X, self._anchors.outlines)
        if verdict is None and off.sum() >= self.min_inliers:
            p, pi, _, inl = self._track_map(anchor_pose, X[off], D[off], feats)
            if p is not None:
                map_spread = position_spread(self.K, p, X[off][pi[inl]], 1.0)
                spread = self._anchor_spread(ar)
                if spread is None:
                    spread = position_spread(self.K, anchor_pose, corners_w, MARKER_SIGMA_PX)
                verdict = disagrees(anchor_pose, p, spread, map_spread)
        if verdict is None:
            return   # the background is not matched here: no verdict either way
        if not verdict:
            self._moved_votes = 0
            return
        self._moved_votes += 1
        if self._moved_votes >= MOVED_CHECKS or self._moved_strong:
            self._moving = True
            if self.mapper is not None:
                self.mapper.wait_idle()
            self.map.clear()
            self._kf_submissions = []
            self._flow = None

    def _background_verdict(self, anchor_pose, feats) -> bool | None:
        """The background's two-view test (`anchor_motion.background_rigid`) between this frame and an earlier
        checked one: True when most background matches move as no point rigid with the anchors could, False
        when nearly all do while the anchors' pose changed enough to tell, None when it cannot say yet (the
        earlier frame is then kept, so the motion adds up)."""
        region = outline_region(self.camera, anchor_pose, self._anchors.outlines)
        now = (self._frame, feats, anchor_pose, region)
        ref = self._moved_ref
        if ref is None or self._frame - ref[0] > MOVED_REF_FRAMES:
            self._moved_ref = now
            return None
        turned = np.degrees(rotation_angle(ref[2][:3, :3].T @ anchor_pose[:3, :3]))
        shifted = float(np.linalg.norm(ref[2][:3, 3] - anchor_pose[:3, 3]))
        if not (turned > MOVED_TURN_DEG or shifted > MOVED_SHIFT_M):
            return None   # too little motion to tell from the anchors' own noise: the motion adds up
        n, miss = background_rigid(self.K, ref[1:], now[1:])
        if n < MIN_BACKGROUND:
            return None
        self._moved_ref = now
        if miss > MOVED_MISS:
            # nearly the whole background against the anchors, on many matches: no mismatch or hand does that
            self._moved_strong = miss > MOVED_SURE and n >= 3 * MIN_BACKGROUND
            return True
        return False if miss < 0.2 else None

    def _moving_anchor_frame(self, gray, t, t0) -> TrackResult:
        """A frame once the anchors move in the room (`anchors_moving`): the anchors' pose when they are measured
        (with the start and smear checks of the still case), else optical flow on points of the anchors
        themselves (`_follow_on_anchors`), else lost: nothing of the room carries the pose."""
        ref = self._reference(t)
        got = None
        if self._fast_predicted(t):
            fut = self._pool.submit(self._anchors.process, gray, t, ref)
            got = self._follow_on_anchors(gray, t)
            ar = fut.result()
        else:
            ar = self._anchors.process(gray, t, ref)
        self._note_anchors(ar)
        self._since_detect = 0
        markers = int(ar.markers)
        usable = self._anchor_usable(ar)
        if usable:
            pose = self._anchor_output(ar)
            if self._lost > 0 or self.motion.last is None:
                usable = not (self._too_smeared_to_start(ar, gray) or self._partial_view(ar)
                              or self._start_uncertain(ar, gray))
            elif not self._plausible(pose, self.motion.last, t) or self._start_uncertain(ar, gray):
                # a board smeared at a swing's start reads centimetres off: the points on it, else lost
                usable = False
            else:
                if got is None and self._moving_fast(ar, t):
                    got = self._follow_on_anchors(gray, t)
                if got is not None and (self._smeared(ar, got, gray, t) or self._partial_view(ar)
                                        or self._flow_holds_better(ar, got, t)):
                    usable = False   # the points on the anchors, followed from the last frame, hold better
        if usable:
            self._flow = None if got is None else relift(self.camera, got[1], pose)
            return self._finish(pose, self.motion.predict(t), "marker", "anchors", None, markers, int(ar.inliers),
                                t, t0, precise=self._precise(ar))
        if got is None:
            got = self._follow_on_anchors(gray, t)
        if got is not None:
            return self._flow_result(got, t, t0, markers)
        return self._lost_frame(t0, markers)

    def _follow_on_anchors(self, gray, t) -> tuple[np.ndarray, Tracks] | None:
        """`_follow_from_last` for moving anchors: only points on the anchors (their plane, within their
        outlines: `anchor_motion.on_anchor`) are followed, seeds are found only inside the anchors' outline in
        the last image; (pose, tracks) or None. Once a frame, like `_follow_from_last`."""
        if self._followed is not None and self._followed[0] == self._frame:
            return self._followed[1]
        got = None
        if (self.flow and self._lost == 0 and self.motion.velocity is not None and self._prev_gray is not None
                and self._prev_gray.shape == gray.shape
                and not (self._via_flow and t - self._flow_start > self.flow_hold_s)):
            outlines = self._anchors.outlines
            tracks = None if self._flow is None else self._flow.subset(on_anchor(self._flow.X, outlines))
            if tracks is None or len(tracks) < FLOW_SEEDS // 2:
                region = outline_region(self.camera, self.motion.last, outlines)
                if region is not None:
                    tracks = seed_on_plane(self.camera, self._prev_gray, self.motion.last, FLOW_SEEDS, keep=tracks,
                                           later=(self.motion.predict(t), t - self.motion.last_t), region=region)
            if tracks is not None and len(tracks):
                got = follow(self.camera, tracks, gray, self.motion.predict(t), self.min_inliers,
                             dt=t - self.motion.last_t, lifted_from=self.motion.last, before=self.motion.last_step())
                if got is not None and not self._plausible(got[0], self.motion.last, t):
                    got = None
                if got is not None:
                    X = got[1].X
                    far = float(np.linalg.norm(got[0][:3, 3] - X.mean(axis=0)))
                    if not position_spread(self.K, got[0], X, 1.0) <= MOVING_FLOW_SPREAD * far:
                        got = None   # too few points, too close together, to hold the pose
        self._followed = (self._frame, got)
        return got

    def _anchors_first(self, gray, t, t0):
        """Anchors were measured last frame: the anchor tracker re-finds them at their predicted place (no
        detector pass, a few ms) and its pose is the most accurate there is. Keypoint work (ORB, matching,
        keyframes) runs only every `keypoint_every` frames to grow the map, or when the anchors are not found.
        Returns (result, anchor result); result is None when the full frame's work must run.

        When the motion model moves the anchors' last corners `smear_px` or more, the flow this frame
        will need (`_moving_fast`) runs on this thread while the anchors are measured on the worker
        (OpenCV releases the interpreter): the same result as one after the other, in the time of the
        longer of the two."""
        ref = self._reference(t)
        if self._fast_predicted(t):
            fut = self._pool.submit(self._anchors.process, gray, t, ref)
            self._follow_from_last(gray, t)   # kept for this frame (`_follow_from_last` remembers it)
            ar = fut.result()
        else:
            ar = self._anchors.process(gray, t, ref)
        self._since_detect = 0
        self._note_anchors(ar)
        pose = self._anchor_output(ar) if self._anchor_usable(ar) else None
        if (pose is None or self._frame - self._full_frame >= self.keypoint_every
                or not self._plausible(pose, self.motion.last, t)):
            return None, ar
        jumped = self._jumped(ar, t)
        got = self._follow_from_last(gray, t) if self._moving_fast(ar, t) or jumped else None
        if self._smeared(ar, got, gray, t) or (jumped and self._flow_disagrees(ar, got, t)):
            return self._flow_result(got, t, t0, int(ar.markers)), ar
        if self._flow_holds_better(ar, got, t):
            return self._flow_result(got, t, t0, int(ar.markers), seam_from=pose), ar
        # the flow's points, now measured in this image, are followed on from here (their plane seeds
        # placed from the anchors' pose, as new seeds would be); without flow it restarts next time
        self._flow = None if got is None else relift(self.camera, got[1], pose)
        return self._finish(pose, self.motion.predict(t), "marker", "anchors", None, int(ar.markers),
                            int(ar.inliers), t, t0, precise=self._precise(ar)), ar

    def _without_fit(self, gray, t, t0, got, flow_tried, ar, pred, markers) -> TrackResult:
        """Neither anchors nor the map gave a pose: flow from the last frame, else the partly covered
        anchors as their filter weighed them, else lost."""
        if not flow_tried:
            got = self._follow_from_last(gray, t)
        if got is not None:
            return self._flow_result(got, t, t0, markers)
        if ar is not None and ar.covered and ar.world_from_camera is not None:
            cw, cuv, n = self._anchor_points(ar, covered_too=True)
            pose = np.asarray(ar.world_from_camera, float)
            return self._finish(pose, pred, "marker", "anchors", None, n, len(cw), t, t0)
        return self._lost_frame(t0, markers)

    def _start_tracks(self, gray, feats, fit) -> None:
        """Keypoints of this full frame to follow by optical flow until the next one."""
        self._flow = None
        n = fit.feature_idx.size
        if n:
            # a spread subset is plenty for the pose and keeps the flow cheap
            sel = np.arange(n) if n <= MAX_TRACKS else np.linspace(0, n - 1, MAX_TRACKS).astype(int)
            self._flow = Tracks(gray, feats.xy[fit.feature_idx[sel]].astype(np.float32), fit.points[sel].copy())
        self._full_tracks = int(min(n, MAX_TRACKS))

    def _anchor_points(self, ar, covered_too: bool = False) -> tuple[np.ndarray, np.ndarray, int]:
        """The anchors' measured corners this frame: world points (N,3), undistorted pixels (N,2) and the
        marker count; empty when the anchors gave no pose or (unless `covered_too`) rest on partly
        covered markers (their corners may be off by pixels: the map and flow carry the pose then)."""
        if (ar is None or ar.raw_world_from_camera is None or len(ar.object_points) < 4
                or (ar.covered and not covered_too)):
            return np.zeros((0, 3)), np.zeros((0, 2)), 0
        corners_uv = self.camera.undistort_points(np.asarray(ar.image_points, float).reshape(-1, 2))
        return np.asarray(ar.object_points, float).reshape(-1, 3), corners_uv, int(ar.markers)

    def _fuse_with_anchors(self, ar, corners_w, corners_uv, feats, pred, ids, X, D, young, t) -> _Fit:
        """Anchors seen: one robust fit of their corners and the map points matched near them (the
        corners dominate; where the map disagrees, the markers win and bundle adjustment corrects the
        map). The anchors' own pose is what is shown while they are in view."""
        anchor_pose = np.asarray(ar.raw_world_from_camera, float)
        init = anchor_pose
        if pred is not None and self._lost == 0 and not self._plausible(anchor_pose, pred, t):
            init = pred  # a flipped planar solution: let the corners pull from the tracked pose
        elif len(feats):
            self._check_moved(ar, anchor_pose, corners_w, feats, X, D)
        pi, fi = self._match(init, X, D, feats, self.radius)
        share = 0.8 if young else self.corner_share   # a young map must not pull the markers
        p, cin, min_, _ = fuse_pose(self.K, init, corners_w, corners_uv, X[pi], feats.und[fi], self.corner_weight,
                                    corner_share=share)
        if cin.any() and share < 0.8:
            cerr = np.linalg.norm(self.camera.project_world(corners_w, p) - self.camera.project_world(
                corners_w, anchor_pose), axis=1).max()
            if cerr > 1.5:   # map and markers disagree: the markers win, BA corrects the map
                p, cin, min_, _ = fuse_pose(self.K, init, corners_w, corners_uv, X[pi], feats.und[fi],
                                            self.corner_weight, corner_share=0.8)
        if cin.mean() < 0.75 and init is not anchor_pose:
            p, cin, min_, _ = fuse_pose(self.K, anchor_pose, corners_w, corners_uv, X[pi], feats.und[fi],
                                        self.corner_weight, corner_share=self.corner_share)
        if cin.mean() < 0.75:
            # the map disagrees with the markers: trust the markers, the map gets corrected by BA
            p, cin, _ = refine_pose(self.K, anchor_pose, corners_w, corners_uv)
            min_ = np.zeros(pi.size, bool)
        source, out_pose, precise = None, None, False
        if (self.anchor_first and self._anchor_usable(ar)
                and (self._lost > 0 or self._plausible(self._anchor_output(ar), self.motion.last, t))):
            # the anchors' pose is what is shown while they are in view (a jump the motion cannot
            # explain is left to the joint fit); the fit above places this frame in the map
            source, out_pose, precise = "anchors", self._anchor_output(ar), self._precise(ar)
        elif min_.sum() < self.min_inliers and ar.world_from_camera is not None and len(corners_w) < 12:
            # the map does not help yet and one marker's pose is noisy: the anchors' filtered pose
            # (a board's many corners are precise as they are; its filter would only add lag)
            source, out_pose = "anchors", np.asarray(ar.world_from_camera, float)
        return _Fit(p, "marker", int(cin.sum() + min_.sum()), ids[pi[min_]], fi[min_], X[pi[min_]], ids[pi],
                    source, out_pose, precise)

    def _from_map(self, feats, pred, ids, X, D, t) -> _Fit | None:
        """No anchors: the pose from map points alone (from the motion's prediction, else by
        relocalising against keyframes and confirming by projection matching), or None."""
        if X.shape[0] < self.min_inliers:
            return None
        if pred is not None:
            p, pi, fi, inl = self._track_map(pred, X, D, feats)
            if p is not None and self._plausible(p, self.motion.last, t):
                return _Fit(p, "slam", int(inl.sum()), ids[pi[inl]], fi[inl], X[pi[inl]], ids[pi])
        if len(feats) < self.min_inliers:
            return None
        p, _ = relocalise(self.map, feats, self.K, near=self.motion.last)
        if p is None:
            return None
        p2, pi, fi, inl = self._track_map(p, X, D, feats)
        if p2 is None or not (self.motion.last is None or self._plausible(p2, self.motion.last, t, lost=True)):
            return None
        return _Fit(p2, "slam", int(inl.sum()), ids[pi[inl]], fi[inl], X[pi[inl]], ids[pi])

    def _finish(self, pose, pred, state, source, out_pose, markers, inliers, t, t0,
                precise: bool = False, seam_from: np.ndarray | None = None) -> TrackResult:
        """Close a tracked frame: `pose` (world_from_camera) goes to the motion model, `out_pose` (else
        `pose`) is shown, faded at a change of `source` (over `precise_blend_frames` when `precise`; from
        `seam_from` when given, see `_output`)."""
        self._since_anchor = 0 if state == "marker" else self._since_anchor + 1
        if state == "marker":
            self._anchor_t = t
            # (the anchors measured this very frame when they give its pose)
            ar = self._anchors_now[1] if self._anchors_now is not None and self._anchors_now[0] == self._frame else None
            self._anchor_spread_last = None if ar is None else self._anchor_spread(ar)
        anchored = state == "marker" or (self._anchored and self._since_anchor < self.marker_every)
        if source is None:
            source = "fused" if anchored else "map"
        out = self._output(pose if out_pose is None else out_pose, pred, source, precise, seam_from)
        self._anchored = anchored
        self.motion.update(pose, t)
        self._lost = 0
        self._last_good_t = t
        self._last_state = state
        self._last_out = out
        self._prev_gray = self._gray
        self._via_flow = False
        return TrackResult(out, state, markers, inliers, (time.perf_counter() - t0) * 1000.0)

    # -- pieces ---------------------------------------------------------------------
    def _klt_frame(self, gray, t, t0) -> TrackResult | None:
        """Between full frames: follow last frame's inlier map points by optical flow and refine the
        pose on them (no detection, no descriptors). None when that is not good enough."""
        if self._flow is None or self.motion.last is None:
            return None
        # flow only from a well-supported full frame, and only while most of its tracks survive
        if self._full_tracks < 4 * self.min_inliers or len(self._flow) < 0.6 * self._full_tracks:
            return None
        pred = self.motion.predict(t)
        got = follow(self.camera, self._flow, gray, pred, self.min_inliers, min_inlier_ratio=0.8,
                     dt=t - self.motion.last_t)
        if got is None or not self._plausible(got[0], self.motion.last, t):
            return None
        self._flow = got[1]
        return self._finish(got[0], pred, "slam", None, None, 0, len(got[1]), t, t0)

    def _follow_from_last(self, gray, t) -> tuple[np.ndarray, Tracks] | None:
        """One frame of optical flow from the last tracked frame: its flow points or map inliers,
        topped up with points seeded on the anchors' plane in the last image. (pose, tracks now
        measured in `gray`), or None when the flow does not hold or the pose is implausible."""
        # computed at most once a frame (also ahead of need, beside the anchors): the state it reads does
        # not change within a frame before the pose is final
        if self._followed is not None and self._followed[0] == self._frame:
            return self._followed[1]
        got = self._follow_uncached(gray, t)
        self._followed = (self._frame, got)
        return got

    def _follow_uncached(self, gray, t) -> tuple[np.ndarray, Tracks] | None:
        # no velocity yet (just (re)acquired): a flow started at zero motion can lock onto a look-alike
        # of each point (tiles, any repeated texture) and give a wrong pose that holds together
        if (not self.flow or self._lost > 0 or self.motion.velocity is None or self._prev_gray is None
                or self._prev_gray.shape != gray.shape
                or (self._via_flow and t - self._flow_start > self.flow_hold_s)):
            return None
        tracks = self._flow
        if tracks is None or len(tracks) < FLOW_SEEDS // 2:
            tracks = seed_on_plane(self.camera, self._prev_gray, self.motion.last, FLOW_SEEDS, keep=tracks,
                                   later=(self.motion.predict(t), t - self.motion.last_t))
        got = follow(self.camera, tracks, gray, self.motion.predict(t), self.min_inliers,
                     dt=t - self.motion.last_t, lifted_from=self.motion.last, before=self.motion.last_step())
        if got is None or not self._plausible(got[0], self.motion.last, t):
            return None
        return got

    def _smeared(self, ar, got, gray, t) -> bool:
        """Whether the anchors' measurement this frame is to be distrusted in favour of the flow pose
        `got` (see smear_px / smear_sharpness / smear_gate_px / smear_hold_s): recently anchored, the
        image moved fast (the flow measures it without any pose), the markers' edges are smeared
        along that motion, and either the corners do not fit well (`_fits_well`) or the flow pose
        disagrees with them."""
        if got is None or self._anchor_t is None or t - self._anchor_t > self.smear_hold_s:
            return False
        motion = got[1].image_motion()
        if motion is None or np.linalg.norm(motion) < self.smear_px:
            return False
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        if not edge_sharpness(gray, seen, motion) < self.smear_sharpness:
            return False   # sharp (or unmeasurable) markers are measured where they are
        if not self._fits_well(ar) or self._partial_view(ar):
            # a smeared board's corners can sit within a pixel of the flow's and still tilt its pose by
            # a centimetre; a pose from a few markers' or from poorly fitting corners loses to the flow
            return True
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        gap = float(np.median(np.linalg.norm(self.camera.project_world(corners, got[0]) - seen, axis=1)))
        return gap > self.smear_gate_px

    def _anchor_spread(self, ar, min_px: float = 0.05) -> float | None:
        """The expected error (metres) of the camera position the anchors measured this frame: the
        position's spread (`position_spread`) with the fit's own RMS residual, scaled to its degrees of
        freedom (at least `min_px`), as the pixel noise. Only for boards: a lone marker's or QR code's four
        corners fit to hundredths of a pixel whatever their error, so their residual says nothing. None
        when not a board."""
        board = self._board_fit(ar)
        if board is None or len(board[1]) < 4 or not np.isfinite(ar.reprojection_error):
            return None
        pose, seen = board
        n = len(seen)
        sigma = max(ar.reprojection_error * np.sqrt(2 * n / max(2 * n - 6, 1)), min_px)
        return position_spread(self.K, pose, seen, sigma)

    def _flow_holds_better(self, ar, got, t: float) -> bool:
        """Whether the flow's pose `got` is expected closer to the truth than the anchors' this frame: the
        anchors' expected error (`_anchor_spread`) exceeds the flow's, which is that of the anchors' pose it
        started from plus `FLOW_DRIFT_M` for each frame since. A board going out of view (a pan speeding
        up: a few markers, smeared, at the image edge) reads millimetres to centimetres off while the
        flow, one frame after a sharp board, is within a millimetre; the flow's points would otherwise be
        placed on the plane again from the worse pose and carry its error through the whole pan. Only
        while the anchors' last pose is recent (`smear_hold_s`) and was a board's."""
        if (got is None or ar is None or self._anchor_spread_last is None or self._anchor_t is None
                or t - self._anchor_t > self.smear_hold_s):
            return False
        spread = self._anchor_spread(ar)
        return spread is not None and spread > self._anchor_spread_last + FLOW_DRIFT_M * (self._since_anchor + 1)

    def _too_smeared_to_start(self, ar, gray) -> bool:
        """Whether the anchors' edges are too soft across x or y (`start_sharpness`) to start the pose from
        them alone. Nothing says which way the camera moves yet, so both directions are measured."""
        if self.start_sharpness <= 0:
            return False
        return bool(self._start_sharpness(ar, gray) < self.start_sharpness)   # NaN (unmeasurable): start

    def _start_sharpness(self, ar, gray) -> float:
        """The anchors' edge sharpness this frame (`edge_sharpness`), the lower of across x and across y;
        measured once a frame for the start checks (`_too_smeared_to_start`, `_start_uncertain`)."""
        if self._sharpness is None or self._sharpness[0] != self._frame:
            seen = np.asarray(ar.image_points, float).reshape(-1, 2)
            sharp = [edge_sharpness(gray, seen, np.array(d)) for d in ((1.0, 0.0), (0.0, 1.0))]
            self._sharpness = (self._frame, min(sharp))
        return self._sharpness[1]

    def _jumped(self, ar, t) -> bool:
        """Whether a corner of a lone marker (4 points: one wrong corner does not show in its reprojection
        error, and 1 px on one corner tilts a 70-pixel marker's pose by centimetres at 45 cm) is more
        than `jump_px` from where the motion model predicts it: a jump to be checked
        against the image's own motion (optical flow) before it is shown."""
        if self.jump_px <= 0 or not self.flow or self.motion.last is None or len(ar.object_points) > 4:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        pred = self.camera.project_world(corners, self.motion.predict(t))
        # only on a steady camera: while it moves, a pixel is within what the prediction misses, and
        # flow over repeated texture can lock onto a look-alike that agrees with the prediction
        moved = np.linalg.norm(pred - self.camera.project_world(corners, self.motion.last), axis=1).max()
        if moved > 0.5 * self.smear_px:
            return False
        return float(np.linalg.norm(pred - seen, axis=1).max()) > self.jump_px   # a dragged corner moves alone

    def _flow_disagrees(self, ar, got, t) -> bool:
        """Whether the flow pose `got` (the image's own motion since the last frame) puts a jumped lone
        marker's corners more than `jump_px` from where they were detected while agreeing with the motion
        model's prediction better than the marker does: the marker moved, the scene did not. Only within
        `smear_hold_s` of the anchors' last accepted frame (after that they win again)."""
        if got is None or self._anchor_t is None or t - self._anchor_t > self.smear_hold_s:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        seen = np.asarray(ar.image_points, float).reshape(-1, 2)
        flow_px = self.camera.project_world(corners, got[0])
        pred_px = self.camera.project_world(corners, self.motion.predict(t))
        to_seen = float(np.linalg.norm(flow_px - seen, axis=1).max())
        to_pred = float(np.linalg.norm(flow_px - pred_px, axis=1).max())
        # the flow must confirm the prediction to within a pixel: a flow pose that merely leans toward it
        # (drifting over repeated texture) proves nothing against a marker
        return to_seen > self.jump_px and to_pred < min(0.5 * to_seen, self.jump_px)

    def _note_anchors(self, ar) -> None:
        """Remember the corners the anchors measured (for `_fast_predicted` on the next frame)."""
        if ar is not None and ar.raw_world_from_camera is not None and len(ar.object_points) >= 4:
            self._anchor_corners = np.asarray(ar.object_points, float).reshape(-1, 3)
            self._anchors_now = (self._frame, ar)

    def _corner_motion(self, corners: np.ndarray, *poses: np.ndarray) -> float:
        """How far (pixels, the most of any) world points `corners` (N,3) move in the image from the last
        pose (`motion.last`) to `poses` (world_from_camera; the most over them)."""
        last = self.camera.project_world(corners, self.motion.last)
        return max(float(np.linalg.norm(self.camera.project_world(corners, p) - last, axis=1).max()) for p in poses)

    def _view_motion(self, pred: np.ndarray) -> float:
        """How far (pixels) the view moved since the last frame: the most of the motion model's (`pred`, the
        motion of five image points, the centre and halfway to each corner, at the depth of the world
        origin) and, when the flow ran this frame, its points' median motion (`Tracks.image_motion`). Not this
        frame's pose: its motion holds the very step a seam is about."""
        followed = self._followed[1] if self._followed is not None and self._followed[0] == self._frame else None
        moved = None if followed is None else followed[1].image_motion()
        return max(0.0 if moved is None else float(np.linalg.norm(moved)), self._model_motion(pred))

    def _model_motion(self, pose: np.ndarray) -> float:
        """Pixels the view moves from `motion.last` to `pose` (see `_view_motion`)."""
        w, h = self.camera.size
        px = np.array([[w / 2, h / 2], [w / 4, h / 4], [3 * w / 4, h / 4], [w / 4, 3 * h / 4], [3 * w / 4, 3 * h / 4]])
        last = self.motion.last
        depth = max(float(invert(last)[2, 3]), 0.05)   # the world origin's depth in the camera
        world = self.camera.unproject(px, depth) @ last[:3, :3].T + last[:3, 3]
        return float(np.linalg.norm(self.camera.project_world(world, pose) - px, axis=1).max())

    def _fast_predicted(self, t) -> bool:
        """Whether the motion model alone moves the corners the anchors last measured `smear_px` or more in
        the image since the last frame: the flow will very likely be needed this frame, so it is worth
        starting before the anchors' measurement is in (it only ever runs ahead, never changes results)."""
        if (not self.flow or self._pool is None or self.motion.last is None or self._anchor_corners is None
                or self.motion.velocity is None or self._prev_gray is None):
            return False
        return self._corner_motion(self._anchor_corners, self.motion.predict(t)) >= self.smear_px

    def _moving_fast(self, ar, t) -> bool:
        """Whether the anchors may have moved more than smear_px in the image since the last frame, by the
        motion model or by their own raw measurement (the model lags when the camera turns around, and so
        does a lone marker's filtered pose)."""
        if not self.flow or self.motion.last is None:
            return False
        corners = np.asarray(ar.object_points, float).reshape(-1, 3)
        measured = ar.raw_world_from_camera if ar.raw_world_from_camera is not None else self._anchor_output(ar)
        return self._corner_motion(corners, self.motion.predict(t), np.asarray(measured, float)) >= self.smear_px

    def _flow_result(self, got, t, t0, markers: int, seam_from: np.ndarray | None = None) -> TrackResult:
        """A frame carried by the flow's pose `got`. `seam_from`: the anchors' pose this frame when they lost
        to the flow only for holding the position worse (`_flow_holds_better`); a seam then fades from there,
        not from the motion model's guess (a pan speeding up outruns that by millimetres), and as onto
        precise anchors (`precise_blend_frames`, from this frame on): the flow is the better pose."""
        start = self._flow_start if self._via_flow else t
        res = self._finish(got[0], self.motion.predict(t), "slam", None, None, markers, len(got[1]), t, t0,
                           precise=seam_from is not None, seam_from=seam_from)
        self._flow = got[1]
        self._via_flow, self._flow_start = True, start
        return res

    def _reference(self, t: float) -> np.ndarray | None:
        """This frame's pose as the motion model (anchors, map or flow) predicts it, for the anchor tracker
        to screen anchors it has never seen (None while lost: then nothing holds the pose)."""
        return self.motion.predict(t) if self._lost == 0 and self.motion.last is not None else None

    @staticmethod
    def _anchor_usable(ar) -> bool:
        """The anchors' own pose can be shown as it is: measured this frame on enough corners, none of
        them on a partly covered marker."""
        return (ar is not None and ar.world_from_camera is not None and ar.raw_world_from_camera is not None
                and len(ar.object_points) >= 4 and not ar.covered)

    @staticmethod
    def _precise(ar) -> bool:
        """The anchors' pose this frame rests on 12 or more corners, none partly covered (a board: the output
        fades onto it over `precise_blend_frames`)."""
        return ar is not None and not ar.covered and len(ar.object_points) >= 12

    def _partial_view(self, ar) -> bool:
        """Whether the anchors' corners seen this frame hold the camera position much worse than the anchors
        they belong to would whole: the position's spread per corner (`position_spread`, times the square
        root of the corner count) over that of the anchors' whole outline at the same pose exceeds
        `PARTIAL_VIEW`. A board's last few markers at the image edge read centimetres off (their tilt
        and the camera's shift trade off); a whole board is about 1. Only boards can be seen in part."""
        board = self._board_fit(ar)
        if board is None:
            return False   # markers and QR codes are seen whole or not at all
        pose, seen = board
        whole = np.concatenate([self._anchors.outlines[i] for i in ar.anchors_seen])
        spread_seen = position_spread(self.K, pose, seen, 1.0) * np.sqrt(len(seen))
        spread_whole = position_spread(self.K, pose, whole, 1.0) * np.sqrt(len(whole))
        # an outline partly behind the camera (inf) says nothing: not partial
        return bool(np.isfinite(spread_whole) and spread_seen > PARTIAL_VIEW * spread_whole)

    def _board_fit(self, ar) -> tuple[np.ndarray, np.ndarray] | None:
        """(the anchors' raw pose this frame, world_from_camera; the world corners (N,3) it was fitted to) when
        the anchors seen include a board; None otherwise."""
        pose = ar.raw_world_from_camera
        if pose is None or not any(len(self._anchors.models[i].markers) > 1 for i in ar.anchors_seen):
            return None
        return np.asarray(pose, float), np.asarray(ar.object_points, float).reshape(-1, 3)

    def _start_uncertain(self, ar, gray: np.ndarray | None = None) -> bool:
        """Whether a smeared board's pose this frame is expected to be off by more than `START_SPREAD` of the
        camera's distance from it: the camera position's spread (`position_spread`) with the fit's own RMS
        residual, scaled to the residual's degrees of freedom, as the pixel noise. With `gray` (the frame),
        boards whose edges are sharp across x and y (`START_SHARP`) are never held back. Markers and QR codes
        (four corners fit to a few hundredths of a pixel whatever their error) are left to `start_sharpness`."""
        spread = self._anchor_spread(ar, min_px=0.0)
        if spread is None:
            return False
        pose, seen = self._board_fit(ar)
        if not spread > START_SPREAD * float(np.linalg.norm(pose[:3, 3] - seen.mean(axis=0))):
            return False
        if gray is None:
            return True
        return bool(self._start_sharpness(ar, gray) < START_SHARP)   # NaN (unmeasurable): not held back

    @staticmethod
    def _fits_well(ar) -> bool:
        """The anchors' corners this frame are 12 or more and fit their pose to `PRECISE_RMS_PX`."""
        return len(ar.object_points) >= 12 and ar.reprojection_error <= PRECISE_RMS_PX

    @staticmethod
    def _anchor_output(ar) -> np.ndarray:
        """The anchors' pose to show: a board's or QR code's many corners are precise as measured (the
        filter would only add lag on a moving camera); a lone marker's four, or a board's corners that fit
        poorly (smeared), are smoothed by its filter, which weighs smeared measurements less."""
        return np.asarray(ar.raw_world_from_camera if Tracker._fits_well(ar) else ar.world_from_camera, float)

    def _plausible(self, pose, ref, t, lost: bool = False) -> bool:
        if ref is None:
            return True
        dt = (t - self._last_good_t) if self._last_good_t is not None else 0.0
        if lost:
            # after a gap the camera may have moved, but not further than walking pace allows
            return plausible(pose, ref, dt, self.max_speed, self.max_angular, 0.10, 0.5)
        return plausible(pose, ref, dt, self.max_speed, self.max_angular)

    def _match(self, pose, X, D, feats: Features, radius: float):
        return match_by_projection(self.K, self.camera.width, self.camera.height, pose, X, D, feats, radius)

    def _track_map(self, init, X, D, feats):
        """Pose from map points alone: projection matching, Huber refinement, RANSAC and wider search as fallbacks."""
        for radius in (self.radius, 3 * self.radius):
            pi, fi = self._match(init, X, D, feats, radius)
            if pi.size < self.min_inliers:
                continue
            p, inl, _ = refine_pose(self.K, init, X[pi], feats.und[fi])
            if inl.sum() < max(self.min_inliers, 0.4 * pi.size):
                pr, mask = pnp_ransac(self.K, X[pi], feats.und[fi], guess=init)
                if pr is None or mask.sum() < self.min_inliers:
                    continue
                p, inl, _ = refine_pose(self.K, pr, X[pi][mask], feats.und[fi][mask])
                full = np.zeros(pi.size, bool)
                full[np.nonzero(mask)[0][inl]] = True
                inl = full
            if inl.sum() >= self.min_inliers:
                return p, pi, fi, inl
        return None, None, None, None

    def _maybe_keyframe(self, t, pose, feats, inl_ids, inl_feat, corners_w, corners_uv, state, inl_xyz, inliers):
        if self.mapper is None or len(feats) < 50 or self._moving:
            return
        # scene depth from what we see: matched map points, else the anchors
        pts = inl_xyz if len(inl_xyz) else corners_w
        if len(pts):
            d = np.linalg.norm(pts - pose[:3, 3], axis=1)
            self._depth = float(np.median(d))
        nkf = len(self.map.keyframes)
        if self.mapper.pending >= self.max_pending:
            return   # mapping is behind: no waiting here, a later frame asks again
        if nkf == 0 and self.mapper.pending == 0:
            need = state == "marker"
        elif (state == "marker" and self._anchor_kfs < (4 if self.anchor_first else 8)
              and self._frame - self._kf_frame >= 5):
            need = True   # early on, every anchor keyframe averages marker noise out of the map
        else:
            if self._frame - self._kf_frame < 3:
                return
            near = self.map.nearest_keyframes(pose, 1)
            if not near:
                return
            kf = near[0]
            moved = np.linalg.norm(kf.centre - pose[:3, 3]) > self.keyframe_parallax * self._depth
            turned = rotation_angle(kf.pose[:3, :3].T @ pose[:3, :3]) > np.radians(8)
            # while the anchors carry the pose, the map only has to cover new views (no keyframe for a
            # thinning match count: each one costs a local bundle adjustment)
            thin = inliers < 0.7 * self._kf_inliers and not (self.anchor_first and state == "marker")
            need = moved or turned or thin
            if state == "slam":
                need = need and inliers >= 30  # do not grow the map from a weak keypoint-only pose
        if not need:
            return
        pid = np.full(len(feats), -1, int)
        pid[inl_feat] = inl_ids
        self.mapper.submit(KeyframeRequest(t, pose.copy(), feats, pid, corners_w if state == "marker" else None,
                                           corners_uv if state == "marker" else None))
        self._kf_submissions.append((self._frame, self.mapper.submitted))
        self._kf_frame = self._frame
        self._kf_inliers = max(inliers, 1)
        self._anchor_kfs += state == "marker"

    def _output(self, pose, pred, source: str, precise: bool = False,
                seam_from: np.ndarray | None = None) -> np.ndarray:
        """Seamless output: fade the step when the source (anchors / fused / map) changes; a switch to
        precise anchors, or precise anchors arriving during a fade, fades over `precise_blend_frames`.
        The step is from where the output would have gone: the last output moved by the predicted motion,
        or, given `seam_from`, the old source's own pose this frame (with the fade's offset so far)."""
        changed = source != self._source
        self._source = source
        # after lost frames nothing was shown: the new pose is taken as it is, not faded from a stale one;
        # nor is it faded while the velocity rests on a single frame difference (just started: a first pose
        # off by centimetres makes the predicted target as far off as the step it is meant to hide)
        if (self._last_out is not None and pred is not None and self._lost == 0 and changed
                and self.motion.steps >= 2):
            # where the output would have gone: the last output moved by the predicted camera motion
            if seam_from is None:
                target = self._last_out @ np.linalg.inv(self.motion.last) @ pred
            else:
                target = np.asarray(seam_from, float) @ self.blender.current_offset()
            if self._view_motion(pred) >= self.smear_px:
                # a fast pan hides a step of a few pixels; fading it would keep the old error for frames
                self.blender.switch(pose, target, self.fast_blend_frames, at_once=True)
            else:
                # onto precise anchors the fade starts on this very frame: they are the better pose
                self.blender.switch(pose, target, self.precise_blend_frames if precise else None, at_once=precise)
        elif precise:
            # the same source turned precise mid-fade (a board coming back into view after a lone marker
            # carried it): no reason left to keep showing the old offset for long
            self.blender.hurry(self.precise_blend_frames)
        return self.blender.apply(pose)

    def _lost_frame(self, t0: float, markers: int) -> TrackResult:
        self._lost += 1
        self._anchor_spread_last = None
        self._flow = None
        self._prev_gray = None
        self._via_flow = False
        self.motion.lose()
        self.blender.reset()
        self._last_state = "lost"
        return TrackResult(None, "lost", markers, 0, (time.perf_counter() - t0) * 1000.0)

    def _marker_only(self, bgr, t, t0) -> TrackResult:
        ar = self._anchors.process(bgr, t)
        if ar.world_from_camera is None:
            return self._lost_frame(t0, int(ar.markers))
        self._lost = 0
        return TrackResult(np.asarray(ar.world_from_camera, float), "marker", int(ar.markers), int(ar.inliers),
                           (time.perf_counter() - t0) * 1000.0)
