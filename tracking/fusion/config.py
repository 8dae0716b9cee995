"""The tracker's settings (`TrackerConfig`), each with its unit, read from one place: `Tracker.config`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


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
    defer_upkeep: bool = False
    """while the anchors carry the pose, a frame due for keypoint work (`keypoint_every`, or the checks of
    anchors that may move in the room) returns the anchors' pose at once and leaves that work (ORB, the
    joint fit that checks the room and grows the map) to `Tracker.upkeep()`, which a live view calls
    once the frame is shown and `process` runs first otherwise: such a frame's latency is the anchors'
    few milliseconds instead of 25-50. The shown pose is the anchors' either way (`PoseFits.with_anchors`);
    the motion model then steps from it rather than from the joint fit (on the tuning recordings the poses
    were the same bit for bit but for marker_occluded's, within 0.11 mm). Off by default: offline drivers
    gain nothing by it (the work runs at the next frame's start), and a benchmark timing a peer between two
    frames would count the ORB running on the worker meanwhile as the peer's; the live view turns it on."""
    smear_px: float = 10.0
    """pixels: under fast motion markers are smeared and their corners can be off by pixels. When the
    anchors may have moved this far since the last frame, one frame of flow is computed as well; if the
    flow confirms the motion, the markers' edges across it are soft (`smear_sharpness`) and the flow pose
    puts the marker corners more than `smear_gate_px` from where they were detected, the flow pose is
    used, for at most `smear_hold_s` since the anchors were last accepted."""
    smear_skip: int = 3
    """frames: after a detection pass read none of the anchors in a fast pan (they moved `smear_px` or more
    since the last frame, in view), at most this many flow frames in a row whose motion of the anchors is no
    smaller skip the pass (`fusion.smear_gate`: the smear is no smaller either); 0: never. Chosen on the
    tuning pans (fast_motion, tune_fast_pan..._e): every frame's pose was the same with 2 to 6 as with 0;
    3 keeps a pass at least every fourth frame (a marker moved in the room is found as soon)."""
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


def make_config(config: TrackerConfig | None, overrides: dict) -> TrackerConfig:
    """`config` (default TrackerConfig()) with keyword overrides, counts clamped to at least 1 (the one place
    the tracker reads its settings from); unknown names fail with the list."""
    base = config if config is not None else TrackerConfig()
    names = {f.name for f in dataclasses.fields(TrackerConfig)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise TypeError(f"Tracker: unknown setting(s) {', '.join(unknown)}; "
                        f"TrackerConfig has {', '.join(sorted(names))}")
    cfg = dataclasses.replace(base, **overrides)
    counts = ("marker_every", "max_pending", "max_lag", "keypoint_every", "precise_blend_frames", "fast_blend_frames")
    return dataclasses.replace(cfg, slam=bool(cfg.slam), anchor_first=bool(cfg.anchor_first),
                               smear_skip=max(0, int(cfg.smear_skip)),
                               **{name: max(1, int(getattr(cfg, name))) for name in counts})
