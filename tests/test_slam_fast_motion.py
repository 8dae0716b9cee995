"""The combined tracker under fast motion (tracking.fusion, tracking.slam.flow): the optical flow runs beside
the anchors' measurement, flow points are followed on across frames the anchors carry, plane seeds are placed
again from a new pose, no keypoints are extracted before there is a map to start, and the output settles on
a board's measurement soon after a map-only stretch. References: cv2.projectPoints, the recordings' ground
truth, the anchors-only tracker."""

import threading

import cv2
import numpy as np
import pytest

import tracking.fusion.flow_follow as flow_module
from scenes import bundled_recording as recording, run_tracker
from test_slam_flow import PLAIN, cv_project, look, texture, view  # noqa: F401  (texture: a fixture)
from tracking.poses import make_pose
from tracking.slam.features import FeatureExtractor
from tracking.slam.flow import Tracks, relift, seed_on_plane
from tracking.fusion import Tracker
from tracking.fusion.state import FrameState


def test_relift_places_plane_seeds_from_a_new_pose_and_keeps_map_points(texture):  # noqa: F811
    a = look([0.05, -0.25, 0.42])
    b = a @ make_pose(np.eye(3), [0.004, -0.002, 0.003])   # the same pixels, seen from a slightly other pose
    seeds = seed_on_plane(PLAIN, view(texture, a), a, n=200)
    assert len(seeds) >= 150 and seeds.planar_mask().all()
    mapped = np.array([[0.01, 0.02, 0.05], [-0.03, 0.01, 0.04]])   # two map points off the plane
    tracks = Tracks(seeds.image, np.vstack([seeds.xy, cv_project(PLAIN, a, mapped)]).astype(np.float32),
                    np.vstack([seeds.X, mapped]), planar=np.r_[seeds.planar_mask(), False, False])
    moved = relift(PLAIN, tracks, b)
    planar = moved.planar_mask()
    assert planar.sum() >= 0.95 * len(seeds) and (~planar).sum() == 2
    assert np.abs(moved.X[planar, 2]).max() < 1e-9                     # on the plane
    # seen from b, the re-placed seeds project onto the pixels they were measured at
    assert np.abs(cv_project(PLAIN, b, moved.X[planar]) - moved.xy[planar]).max() < 1e-3
    assert np.allclose(moved.X[~planar], mapped)                      # map points are not moved


def test_seed_top_up_keeps_away_from_the_points_kept(texture):  # noqa: F811
    a = look([0.05, -0.25, 0.42])
    img = view(texture, a)
    first = seed_on_plane(PLAIN, img, a, n=120)
    kept = Tracks(img, first.xy[:100], first.X[:100], planar=first.planar[:100])
    topped = seed_on_plane(PLAIN, img, a, n=300, keep=kept)
    assert len(topped) >= 250
    assert np.array_equal(topped.xy[:100], kept.xy)
    new = topped.xy[100:]
    gaps = np.linalg.norm(new[:, None] - kept.xy[None], axis=2).min(axis=1)
    assert gaps.min() >= 8.0   # min_distance 10 px, found on the half-resolution image (2 px grid)


def _spy(monkeypatch, tr):
    """Per frame: whether the anchors were measured off the main thread while the flow ran, and which
    points the flow followed (in) and kept (out)."""
    flow_started = threading.Event()
    log = {"anchors": [], "follow": []}
    process, follow = tr.anchor_tracker.process, flow_module.follow

    def anchors_process(*args, **kwargs):
        off_main = threading.current_thread() is not threading.main_thread()
        beside = off_main and flow_started.wait(0.3)   # the flow starts on the main thread meanwhile
        log["anchors"].append((tr.frame.index, off_main, beside))
        return process(*args, **kwargs)

    def spy_follow(camera, tracks, *args, **kwargs):
        flow_started.set()
        got = follow(camera, tracks, *args, **kwargs)
        log["follow"].append((tr.frame.index, tracks.xy.copy(), None if got is None else got[1].xy.copy()))
        return got

    monkeypatch.setattr(tr.anchor_tracker, "process", anchors_process)
    monkeypatch.setattr(flow_module, "follow", spy_follow)
    return flow_started, log


def test_flow_runs_beside_the_anchors_and_follows_on_across_marker_frames(monkeypatch):
    """fast_motion: while the anchors carry the pose through fast motion, the flow that checks them for
    smear runs while they are measured (OpenCV lets both threads work), on the points it followed into the
    last frame."""
    frames, session = recording("fast_motion")
    states = []
    with Tracker(session.camera, session.anchors, threaded=False) as tr:
        flow_started, log = _spy(monkeypatch, tr)
        for t, img, _ in frames:
            flow_started.clear()
            states.append(tr.process(img, t).state)
    follows = {f: (xy_in, xy_out) for f, xy_in, xy_out in log["follow"]}
    # frames (1-based, as Tracker counts) the anchors carried right after a frame they carried, with flow
    fast_marker = [f for f in follows if states[f - 1] == "marker" and f >= 2 and states[f - 2] == "marker"]
    assert len(fast_marker) >= 3
    beside = {f for f, off_main, seen in log["anchors"] if off_main and seen}
    # where the motion model already predicts the fast motion (not at a turnaround, where it lags)
    assert len([f for f in fast_marker if f in beside]) >= max(2, len(fast_marker) // 2)
    # on the marker frames after one with flow, the flow starts from the points it kept there
    chained = [f for f in fast_marker if f - 1 in fast_marker and follows[f - 1][1] is not None]
    assert len(chained) >= 2
    for f in chained:
        before, now = follows[f - 1][1], follows[f][0]
        shared = (np.linalg.norm(now[:, None] - before[None], axis=2).min(axis=1) < 1e-3).sum()
        assert shared >= 0.8 * len(before)


def test_no_keypoints_before_the_anchors_are_first_seen(monkeypatch):
    """fast_motion opens with frames where the marker is not yet readable: with no map to match against and
    none to start, keypoints are not extracted there, only once the anchors are found."""
    frames, session = recording("fast_motion", slice(0, 12))
    calls = []
    extract = FeatureExtractor.extract

    def spy(self, gray):
        calls.append(tr.frame.index)
        return extract(self, gray)

    monkeypatch.setattr(FeatureExtractor, "extract", spy)
    with Tracker(session.camera, session.anchors, threaded=False) as tr:
        results = [tr.process(img, t) for t, img, _ in frames]
    states = [r.state for r in results]
    first = states.index("marker") + 1
    found = next(i for i, r in enumerate(results) if r.markers > 0) + 1   # (frame numbers count from 1)
    assert first > 3 and all(s == "lost" for s in states[:first - 1])
    # from the first frame the anchors are found on (a smeared one does not start the pose: start_sharpness)
    assert calls and found <= min(calls) <= first


@pytest.mark.parametrize("name", ["fast_motion", "tune_fast_pan"])
def test_output_settles_on_a_board_soon_after_a_map_only_stretch(name):
    """When a board (12+ corners) is measured again after frames carried by the map or flow, the output fades
    from where it was over `precise_blend_frames` (5, starting on the return frame), not `blend_frames` (8):
    by the 4th frame after the return it is as close to the truth as the anchors alone (the tracker with
    slam=False). (Some of those frames may be the flow's again: a board leaving the view as the pan turns
    back reads worse than the flow one frame after it, `Handover.flow_holds_better`.)"""
    frames, session = recording(name)
    with Tracker(session.camera, session.anchors, slam=False, filter=False) as tr:
        alone = run_tracker(tr, frames)["errors"]
    with Tracker(session.camera, session.anchors, threaded=False) as tr:
        assert tr.config.precise_blend_frames == 5 and tr.config.blend_frames == 8
        r = run_tracker(tr, frames)
    st, err = r["states"], r["errors"]
    k = 4
    returns = [i for i in range(1, len(st) - k) if st[i - 1] == "slam" and st[i] == st[i + 1] == "marker"
               and "lost" not in st[i:i + k + 1]]
    assert returns
    for i in returns:
        assert err[i + k] <= alone[i + k] + 0.0015, (i, err[i:i + k + 1], alone[i:i + k + 1])


def test_blender_fades_over_the_frames_a_switch_asks_for():
    from tracking.slam.fusion import PoseBlender

    bl = PoseBlender(frames=8)
    est = look([0, -0.3, 0.4])
    bl.switch(est, est @ make_pose(np.eye(3), [0.02, 0, 0]), frames=4)
    steps = [np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(5)]
    assert np.allclose(steps, [0.02, 0.015, 0.01, 0.005, 0.0], atol=1e-9)
    bl.switch(est, est @ make_pose(np.eye(3), [0.02, 0, 0]), frames=4, at_once=True)   # the first step now
    steps = [np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(4)]
    assert np.allclose(steps, [0.015, 0.01, 0.005, 0.0], atol=1e-9)
    bl.switch(est, est @ make_pose(np.eye(3), [0.02, 0, 0]))   # the default stays blend_frames
    steps = [np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(9)]
    assert np.allclose(steps[::2], [0.02, 0.015, 0.01, 0.005, 0.0], atol=1e-9)


def test_blender_hurries_a_long_fade_from_where_it_is():
    """A board coming back mid-fade (a lone marker carried the output, the fade from the map still running):
    the rest of the fade takes `frames` frames from the offset reached, without a jump."""
    from tracking.slam.fusion import PoseBlender

    bl = PoseBlender(frames=8)
    est = look([0, -0.3, 0.4])
    bl.switch(est, est @ make_pose(np.eye(3), [0.04, 0, 0]))
    first = [np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(2)]   # 40, 35 mm
    bl.hurry(3)
    rest = [np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(4)]
    assert np.allclose(first + rest, [0.04, 0.035, 0.02, 0.01, 0.0, 0.0], atol=1e-9)
    bl.switch(est, est @ make_pose(np.eye(3), [0.04, 0, 0]), frames=2)
    bl.hurry(3)   # already shorter: unchanged
    assert np.allclose([np.linalg.norm(bl.apply(est)[:3, 3] - est[:3, 3]) for _ in range(3)], [0.04, 0.02, 0.0])


def test_poses_do_not_depend_on_how_long_the_anchors_take(monkeypatch):
    """The flow started beside the anchors' measurement is only ever used where it would have been computed
    after it: with mapping inline (threaded=False) a slow anchors thread changes no pose."""
    import time

    frames, session = recording("fast_motion", slice(0, 36))
    runs = []
    for delay in (0.0, 0.015):
        with Tracker(session.camera, session.anchors, threaded=False) as tr:
            process = tr.anchor_tracker.process

            def slow(*args, delay=delay, **kwargs):
                time.sleep(delay)
                return process(*args, **kwargs)

            monkeypatch.setattr(tr.anchor_tracker, "process", slow)
            runs.append([tr.process(img, t).world_from_camera for t, img, _ in frames])
    assert sum(p is not None for p in runs[0]) >= 25
    for a, b in zip(*runs):
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b))


def test_the_anchors_filter_does_not_hide_fast_motion_from_the_flow_check():
    """A lone marker's filtered pose lags the camera. Judged by it, a board leaving the view mid-pan (two
    smeared markers) looked slow, its poor measurement was taken instead of the flow's, and the flow then
    carried on from it: on fast_motion the output with the anchors' filter on was twice as far off as with
    it off (in make bench: ATE 6.1 against 2.8 mm). Motion is judged by the raw measurement now, so the filter changes
    nothing there."""
    frames, session = recording("fast_motion")
    ate = {}
    for filt in (True, False):
        with Tracker(session.camera, session.anchors, threaded=False, filter=filt) as tr:
            ate[filt] = run_tracker(tr, frames)["metrics"].ate_rmse_m
    assert ate[True] <= 1.1 * ate[False], ate


def test_a_smeared_board_is_shown_through_the_anchors_filter():
    """A board's own pose is shown as measured only while its corners fit it (PRECISE_RMS_PX); a board smeared
    by a pan fits them to 0.6-1 px and read up to 28 mm off on tune_fast_pan_b, where the filter, which
    weighs smeared measurements less, was 3 mm off."""
    from types import SimpleNamespace

    from tracking.fusion.handover import PRECISE_RMS_PX, anchor_output

    raw, filtered = np.eye(4), np.eye(4)
    raw[0, 3], filtered[0, 3] = 0.03, 0.003
    board = SimpleNamespace(object_points=np.zeros((56, 3)), raw_world_from_camera=raw, world_from_camera=filtered,
                            covered=False, reprojection_error=0.2)
    assert PRECISE_RMS_PX <= 0.6
    assert anchor_output(board)[0, 3] == 0.03
    board.reprojection_error = 0.8
    assert anchor_output(board)[0, 3] == 0.003
    lone = SimpleNamespace(object_points=np.zeros((4, 3)), raw_world_from_camera=raw, world_from_camera=filtered,
                           covered=False, reprojection_error=0.05)
    assert anchor_output(lone)[0, 3] == 0.003


@pytest.mark.parametrize("name", ["tune_fast_pan", "tune_fast_pan_b", "tune_fast_pan_c", "tune_fast_pan_d"])
def test_flow_carries_a_rolling_shutter_pan_between_the_boards_visits(name):
    """Fast pans read out over 30 ms: between the board's visits the flow carries the pose. Fitted as if the
    whole frame were seen at once, each frame's shear moved the seeds placed on the plane and the pose by
    centimetres (median 14.7 / 8.1 mm, max 29 / 20 mm before); a board smeared by the pan whose corners fit
    it poorly was taken over the flow at its return. On _c three markers in a row at the image edge fitted
    well and read 22 mm off (max 33 mm), on _d one marker at the edge started the pose 51 mm off: a board
    seen in part (`Handover.partial_view`) neither starts the pose nor beats the flow when smeared.
    Measured now (a seam in a fast pan shown at once, the flow's velocity carried to the right time):
    median 2.8 / 1.5 / 2.2 / 1.8 mm, max 6.8 / 4.3 / 8.2 / 6.8 mm."""
    frames, session = recording(name)
    with Tracker(session.camera, session.anchors, threaded=False) as tr:
        r = run_tracker(tr, frames)
    err = r["errors"][np.isfinite(r["errors"])]
    assert "slam" in r["states"]
    assert np.median(err) < 0.005
    assert err.max() < 0.013


def test_no_fade_from_a_target_predicted_by_a_start_up_velocity():
    """tune_fast_pan_e's pose starts on four smeared markers 18 mm off, the next frame's board is right: the
    velocity from those two frames is the start's error, not motion. A fade at the next change of source
    started from where that velocity put the output and showed 16 mm for several frames; no fade is begun
    until the velocity rests on two frame differences (MotionModel.steps). Measured after the first two
    tracked frames: at most 9 mm."""
    from tracking.slam.frame_pose import MotionModel

    m = MotionModel()
    for k in range(3):
        m.update(make_pose(np.eye(3), [0.01 * k, 0.0, 0.0]), k / 30)
    assert m.steps == 2
    m.lose()
    assert m.steps == 0 and m.velocity is None
    frames, session = recording("tune_fast_pan_e")
    with Tracker(session.camera, session.anchors, threaded=False) as tr:
        r = run_tracker(tr, frames)
    tracked = np.nonzero(np.isfinite(r["errors"]))[0]
    assert r["errors"][tracked[2:]].max() < 0.012


@pytest.mark.parametrize("turn, flow_px, faded", [(0.9, None, False), (0.05, None, True), (0.05, 20.0, False)])
def test_a_seam_is_faded_only_where_the_view_moves_slowly(turn, flow_px, faded):
    """A change of pose source (anchors -> map) with a 3 mm step between them: on a camera turning slowly
    (0.05 rad/s, under a pixel a frame) the step is faded (this frame shows where the old source would have
    been); in a fast pan (0.9 rad/s, ~16 px a frame by the motion model, or 20 px measured by this frame's
    flow) the new pose is shown at once, as a fade would keep the old source's error for frames that the
    motion hides anyway (`fast_blend_frames`). Rule written here: the output is the new pose, or the
    predicted one."""
    from tracking.recording.schema import parse_anchors

    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.05}])
    with Tracker(PLAIN, anchors, threaded=False) as tr:
        start = look([0.0, -0.3, 0.4])
        for k in range(3):
            turned = cv2.Rodrigues(np.array([0.0, turn * k / 30, 0.0]))[0]
            tr.motion.update(start @ make_pose(turned, np.zeros(3)), k / 30)
        t = 3 / 30
        pred = tr.motion.predict(t)
        tr.output.last, tr.output.source = tr.motion.last.copy(), "anchors"
        frame = FrameState(7, t)
        if flow_px is not None:
            moved = np.tile([flow_px, 0.0], (50, 1))
            frame.flow_ran, frame.followed = True, (pred, Tracks(np.zeros((480, 640), np.uint8),
                                                           np.zeros((50, 2), np.float32), np.zeros((50, 3)), moved))
        new = pred @ make_pose(np.eye(3), [0.003, 0.0, 0.0])
        out = tr.output.show(new, pred, "map", frame, lost=0)
    shown = new if not faded else pred
    assert np.abs(out - shown).max() < 1e-9, (out[:3, 3], new[:3, 3], pred[:3, 3])


def test_a_board_coming_back_in_part_does_not_take_over_from_the_flow():
    """The camera pans off a 5x3 board (the flow carries the pose) and back; on the way back the first frame
    shows two of its markers at the image edge, sharp. A pose on two markers there reads millimetres to
    centimetres off (5.3 mm measured here; 62 mm on an extra tuning pan, xt_fast_pan_j, whose lone
    returning marker took over); while the flow holds, such a partial view does not replace it
    (`Handover.partial_view`), and the board takes over once more of it is seen (at the end, where it
    fits less well than a frame of flow after it is expected to hold, the flow may carry the last frames:
    `Handover.flow_holds_better`). Oracles: OpenCV's own
    detector for how many markers are in view, the render's ground truth for the error (0.6 mm measured on
    the two-marker frame)."""
    from scene_book import book_frames

    frames, scene = book_frames("partial_return")   # tests/scene_book.py
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    seen = [0 if (ids := det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))[1]) is None else len(ids)
            for _, img, _ in frames]
    with Tracker(scene.camera, scene.anchors, threaded=False) as tr:
        r = run_tracker(tr, frames)
    states, errors = r["states"], r["errors"]
    back = [i for i in range(1, len(frames)) if states[i - 1] == "slam" and 0 < seen[i] <= 3]
    assert back, seen                   # the board does come back in part after a flow stretch
    for i in back:
        assert states[i] == "slam" and errors[i] < 0.002, (i, seen[i], states[i], errors[i])
    # the board carries the pose again once more of it is seen
    assert "marker" in states[back[-1]:] and np.isfinite(errors).all() and errors.max() < 0.004


def test_a_hand_over_to_the_better_flow_fades_from_the_anchors_pose():
    """When the flow takes a frame from a board it holds better (`Handover.flow_holds_better`), the seam fades from
    the anchors' own pose this frame, not from where the motion model would have put the output (a pan
    speeding up outruns that), and as onto precise anchors: over `precise_blend_frames`, this frame taking
    the first step. Rule written here: on a slowly turning camera, the output is the flow's pose moved
    (1 - 1/precise_blend_frames) of the way toward the anchors' (offsets along the camera's x axis)."""
    from tracking.recording.schema import parse_anchors

    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.05}])
    with Tracker(PLAIN, anchors, threaded=False) as tr:
        start = look([0.0, -0.3, 0.4])
        for k in range(3):
            turned = cv2.Rodrigues(np.array([0.0, 0.05 * k / 30, 0.0]))[0]
            tr.motion.update(start @ make_pose(turned, np.zeros(3)), k / 30)
        pred = tr.motion.predict(3 / 30)
        tr.output.last, tr.output.source = tr.motion.last.copy(), "anchors"
        flow = pred @ make_pose(np.eye(3), [0.003, 0.0, 0.0])
        board = pred @ make_pose(np.eye(3), [-0.002, 0.0, 0.0])
        out = tr.output.show(flow, pred, "fused", FrameState(7, 3 / 30), lost=0, precise=True, seam_from=board)
        a = 1.0 - 1.0 / tr.config.precise_blend_frames
    assert np.allclose(out[:3, 3], flow[:3, 3] + a * (board[:3, 3] - flow[:3, 3]), atol=1e-9), out[:3, 3]
