"""AnchorTracker against ground truth on rendered views (tracking.anchors.render, checked here too)."""

import cv2
import numpy as np
import pytest

from tracking.anchors import AnchorTracker, PoseFilter, plain_opencv_pose
from tracking.anchors.render import look_at, render_view
from tracking.camera import Camera
from tracking.errors import SessionError
from tracking.poses import invert, rotation_angle
from tracking.recording.schema import parse_anchors

# board frame: y down, z into the paper; a marker/QR lying on the same sheet: rotated 180 deg about x
FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


def on_board(x, y):
    T = FLIP.copy()
    T[0, 3], T[1, 3] = x, y
    return T.tolist()


BOARD = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
         "marker_length": 0.04, "separation": 0.01, "first_id": 0}
MARKER = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 20, "length": 0.05}
QR = {"kind": "qr", "text": "arapp anchor 1", "length": 0.06}


@pytest.fixture(scope="module")
def cam():
    return Camera([[700.0, 0, 319.5], [0, 700.0, 239.5], [0, 0, 1]], [0.06, -0.04, 0.001, -0.0005, 0.0], 640, 480)


def pos_err(T, gt):
    return float(np.linalg.norm(T[:3, 3] - gt[:3, 3]))


def rot_err_deg(T, gt):
    return np.degrees(rotation_angle(T[:3, :3] @ gt[:3, :3].T))


def test_renderer_puts_edges_where_the_camera_model_says(cam):
    """The test images themselves: a frontal marker's black edge sits at the projected position (area coverage)."""
    an = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.1}])
    flat = Camera([[1000.0, 0, 100.3], [0, 1000.0, 100.3], [0, 0, 1]], None, 200, 200)
    T = look_at([0, 0, 1.0], [0, 0, 0], up=(0, 1, 0))
    img = render_view(an, flat, T, supersample=5, blur=0).astype(float)
    left, right = flat.project_world(np.array([[-0.05, 0, 0], [0.05, 0, 0]]), T)[:, 0]
    # pixel 50 covers [49.5, 50.5]; the edge at 50.3 leaves 0.8 of it white
    assert left == pytest.approx(50.3) and right == pytest.approx(150.3)
    assert img[100, 50] == pytest.approx(255 * 0.8, abs=255 / 5 / 2 + 1)
    assert img[100, 150] == pytest.approx(255 * 0.2, abs=255 / 5 / 2 + 1)


def test_board_pose_with_distortion(cam):
    an = parse_anchors([BOARD])
    gt = look_at([0.02, 0.3, -0.45], [0.09, 0.07, 0.0], up=(0, -1, 0))
    img = render_view(an, cam, gt, noise_std=2.0, bgr=True)
    tr = AnchorTracker(an, cam)
    res = tr.process(img, 0.0)
    dist = np.linalg.norm(gt[:3, 3] - [0.09, 0.07, 0])
    assert res.world_from_camera is not None
    assert res.markers == 12 and res.inliers == 48 and res.anchors_seen == [0]
    assert pos_err(res.raw_world_from_camera, gt) < 0.002 * dist
    assert rot_err_deg(res.raw_world_from_camera, gt) < 0.2
    assert res.reprojection_error < 0.5
    # the reported correspondences are consistent with the pose through OpenCV's own projection
    cfw = invert(res.raw_world_from_camera)
    rvec, _ = cv2.Rodrigues(cfw[:3, :3])
    px, _ = cv2.projectPoints(res.object_points, rvec, cfw[:3, 3], cam.K, cam.dist)
    rms = np.sqrt(np.mean(np.sum((px.reshape(-1, 2) - res.image_points) ** 2, axis=1)))
    assert rms == pytest.approx(res.reprojection_error, rel=1e-6, abs=1e-9)
    # and better than (or as good as) the plain OpenCV way on the same image
    plain = plain_opencv_pose(an, cam, img)
    assert plain is not None
    assert pos_err(res.raw_world_from_camera, gt) <= pos_err(plain, gt) + 1e-4


def test_single_marker_pose(cam):
    an = parse_anchors([MARKER])
    gt = look_at([0.12, -0.08, 0.35], [0.0, 0.0, 0.0], up=(0, 1, 0))
    img = render_view(an, cam, gt, noise_std=2.0)
    res = AnchorTracker(an, cam).process(img, 0.0)
    assert res.world_from_camera is not None and res.markers == 1 and res.inliers == 4
    d = np.linalg.norm(gt[:3, 3])
    assert pos_err(res.raw_world_from_camera, gt) < 0.005 * d
    assert rot_err_deg(res.raw_world_from_camera, gt) < 1.0


def test_qr_pose_text_and_tracking(cam):
    an = parse_anchors([QR])
    gt = look_at([0.05, 0.04, 0.32], [0.0, 0.0, 0.0], up=(0, 1, 0))
    tr = AnchorTracker(an, cam)
    res = tr.process(render_view(an, cam, gt, noise_std=1.0), 0.0)
    assert res.world_from_camera is not None and res.markers == 1
    assert res.inliers >= 24  # finder-pattern corners, not just the 4 symbol corners
    d = np.linalg.norm(gt[:3, 3])
    assert pos_err(res.raw_world_from_camera, gt) < 0.005 * d
    assert tr.qr.decode_ms > 0
    # next frames: moved a little; the code is tracked, not decoded again
    for k in range(1, 4):
        gt_k = look_at([0.05 + 0.004 * k, 0.04, 0.32], [0.0, 0.0, 0.0], up=(0, 1, 0))
        res = tr.process(render_view(an, cam, gt_k, noise_std=1.0), k / 30)
        assert res.raw_world_from_camera is not None
        assert tr.qr.decode_ms == 0.0
        assert pos_err(res.raw_world_from_camera, gt_k) < 0.005 * d
    # a session naming another text does not accept this code
    other = parse_anchors([dict(QR, text="someone else")])
    assert AnchorTracker(other, cam).process(render_view(an, cam, gt), 0.0).world_from_camera is None


def test_two_anchors_fused_and_second_alone(cam):
    an = parse_anchors([BOARD, dict(MARKER, world_from_anchor=on_board(0.3, 0.05))])
    gt = look_at([0.15, 0.3, -0.5], [0.17, 0.07, 0.0], up=(0, -1, 0))
    res = AnchorTracker(an, cam).process(render_view(an, cam, gt, noise_std=2.0), 0.0)
    assert res.anchors_seen == [0, 1] and res.markers == 13
    assert pos_err(res.raw_world_from_camera, gt) < 0.001 * 0.55
    # only the second anchor in view: the pose is still in the world (board) frame
    gt2 = look_at([0.3, 0.12, -0.3], [0.3, 0.05, 0.0], up=(0, -1, 0))
    img = render_view(an[1:], cam, gt2, noise_std=2.0)
    res2 = AnchorTracker(an, cam).process(img, 0.0)
    assert res2.anchors_seen == [1]
    assert pos_err(res2.raw_world_from_camera, gt2) < 0.005 * 0.31


def test_other_anchor_resolves_ambiguity(cam):
    """No history: the frontal marker's solution is chosen by the board seen with it."""
    an = parse_anchors([BOARD, dict(MARKER, world_from_anchor=on_board(0.35, 0.05))])
    gt = look_at([0.34, 0.06, -0.4], [0.3, 0.06, 0.0], up=(0, -1, 0))
    res = AnchorTracker(an, cam).process(render_view(an, cam, gt, noise_std=2.0), 0.0)
    assert 1 in res.anchors_seen and 0 in res.anchors_seen
    assert rot_err_deg(res.raw_world_from_camera, gt) < 0.5


def test_board_partly_outside_the_image(cam):
    an = parse_anchors([BOARD])
    gt = look_at([0.0, 0.07, -0.3], [0.0, 0.07, 0.0], up=(0, -1, 0))  # board centre far right, cut by the edge
    img = render_view(an, cam, gt, noise_std=2.0)
    px = cam.project_world(np.array([[0.19, 0.07, 0.0]]), gt)
    assert px[0, 0] > cam.width  # the board really extends beyond the image
    res = AnchorTracker(an, cam).process(img, 0.0)
    assert 0 < res.markers < 12
    assert pos_err(res.raw_world_from_camera, gt) < 0.005 * 0.3


def test_wrong_dictionary_and_size_explained(cam):
    an = parse_anchors([BOARD])
    gt = look_at([0.02, 0.25, -0.45], [0.09, 0.07, 0.0], up=(0, -1, 0))
    img = render_view(an, cam, gt)
    wrong_dict = parse_anchors([dict(BOARD, dictionary="DICT_6X6_250")])
    tr = AnchorTracker(wrong_dict, cam)
    assert tr.process(img, 0.0).world_from_camera is None
    hints = tr.diagnose(img)
    assert any("DICT_4X4" in h and "anchors[0].dictionary" in h for h in hints), hints
    wrong_size = parse_anchors([dict(BOARD, marker_length=0.03)])
    hints = AnchorTracker(wrong_size, cam).diagnose(img)
    assert any("marker_length" in h for h in hints), hints
    assert AnchorTracker(an, cam).diagnose(img) == []
    # a marker declared at the wrong size next to a correct board
    two = [BOARD, dict(MARKER, world_from_anchor=on_board(0.3, 0.05))]
    img2 = render_view(parse_anchors(two), cam, look_at([0.15, 0.3, -0.5], [0.17, 0.07, 0.0], up=(0, -1, 0)))
    hints = AnchorTracker(parse_anchors([two[0], dict(two[1], length=0.06)]), cam).diagnose(img2)
    assert any("anchors[1]" in h and "length" in h for h in hints), hints
    # the image size must match the camera; duplicate ids are a session error
    with pytest.raises(ValueError, match="calibrated for 640x480"):
        AnchorTracker(an, cam).process(np.zeros((100, 100), np.uint8), 0.0)
    with pytest.raises(SessionError, match="marker id 3"):
        AnchorTracker(parse_anchors([BOARD, dict(MARKER, id=3)]), cam)


def test_filter_removes_jitter_without_lag(cam):
    """Static: the filtered pose jitters far less than the raw one. Constant motion: no lag builds up."""
    an = parse_anchors([BOARD])
    rng = np.random.default_rng(1)
    gt = look_at([0.05, 0.25, -0.5], [0.09, 0.07, 0.0], up=(0, -1, 0))
    tr = AnchorTracker(an, cam)
    raw, filt = [], []
    for k in range(20):
        r = tr.process(render_view(an, cam, gt, noise_std=4.0, rng=rng), k / 30)
        raw.append(r.raw_world_from_camera[:3, 3])
        filt.append(r.world_from_camera[:3, 3])
    jr = np.sqrt(np.mean(np.sum(np.diff(raw[5:], axis=0) ** 2, axis=1)))
    jf = np.sqrt(np.mean(np.sum(np.diff(filt[5:], axis=0) ** 2, axis=1)))
    assert jf < 0.5 * jr
    # constant velocity, synthetic measurements: after settling the filter follows with no lag
    f = PoseFilter()
    for k in range(60):
        T = np.eye(4)
        T[:3, 3] = [0.3 * k / 30, 0, 0.5]
        T[:3, :3] = cv2.Rodrigues(np.array([0.0, 0.5 * k / 30, 0.0]))[0]
        out = f.update(T, k / 30, distance=0.5)
    assert np.linalg.norm(out[:3, 3] - T[:3, 3]) < 1e-3
    assert rot_err_deg(out, T) < 0.05


def test_ambiguous_marker_stays_on_its_branch(cam):
    """Corner noise large enough that the lowest-error IPPE solution is often the flipped one.

    Corners are projected by OpenCV and perturbed directly (a blurry camera, a poor detector) and fed to
    the tracker in place of its detector, so the ambiguity is controlled. After a short settling (the
    first frame can only guess the lower-error branch), the tracker keeps the true branch in every frame,
    where picking the lowest-error solution would flip. Several noise seeds.
    """
    from tracking.anchors.detect import Observation
    from tracking.anchors.model import square_corners
    from tracking.anchors.pose import planar_solutions

    an = parse_anchors([MARKER])
    obj = square_corners(0.05)
    a = np.radians(12.0)  # the flipped solution is ~24 degrees off
    gt = look_at([0.5 * np.sin(a), 0.0, 0.5 * np.cos(a)], [0, 0, 0], up=(0, 1, 0))
    clean = cam.project_world(obj, gt)
    blank = np.zeros((cam.height, cam.width), np.uint8)
    total_lowest_wrong = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        tr = AnchorTracker(an, cam)
        wrong = []
        for k in range(60):
            ob = Observation(0, obj, clean + rng.normal(0, 0.45, clean.shape), np.full(4, 20), 1, square=True)
            tr._detect_aruco = lambda gray, pred, fast=False, ob=ob: [ob]
            res = tr.process(blank, k / 30)
            sols = [invert(s) for s in planar_solutions(ob, cam)]
            e = sorted((rot_err_deg(s, gt), i) for i, s in enumerate(sols))
            if len(sols) < 2 or not (e[0][0] < 8 and e[1][0] > 16):
                continue  # noise alone decides here: neither solution is clearly the true branch
            true, flip = sols[e[0][1]], sols[e[1][1]]
            total_lowest_wrong += e[0][1] != 0
            wrong.append(k >= 15 and any(rot_err_deg(p, flip) < rot_err_deg(p, true)
                                         for p in (res.raw_world_from_camera, res.world_from_camera)))
        assert not any(wrong), (seed, np.flatnonzero(wrong))
    assert total_lowest_wrong >= 10, "the noise must make the lowest-error solution flip in some frames"


def test_charuco_pose(cam):
    an = parse_anchors([{"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 5, "squares_y": 4,
                         "square_length": 0.03, "marker_length": 0.022}])
    gt = look_at([0.02, 0.12, -0.35], [0.075, 0.06, 0.0], up=(0, -1, 0))
    res = AnchorTracker(an, cam).process(render_view(an, cam, gt, noise_std=2.0), 0.0)
    assert res.world_from_camera is not None
    assert res.inliers == 12  # the 4x3 inner chessboard corners
    assert pos_err(res.raw_world_from_camera, gt) < 0.002 * 0.36
    assert res.reprojection_error < 0.5


def test_board_and_qr_fused(cam):
    an = parse_anchors([BOARD, dict(QR, world_from_anchor=on_board(0.26, 0.07))])
    gt = look_at([0.14, 0.25, -0.45], [0.16, 0.07, 0.0], up=(0, -1, 0))
    tr = AnchorTracker(an, cam)
    res = tr.process(render_view(an, cam, gt, noise_std=2.0), 0.0)
    assert res.anchors_seen == [0, 1] and res.markers == 13
    assert pos_err(res.raw_world_from_camera, gt) < 0.001 * 0.5
    # the QR code's points are in the world frame: they reproject onto its drawn corners
    qr_world = np.asarray(an[1].world_from_anchor) @ np.array([[-0.03, 0.03, 0, 1.0], [0.03, -0.03, 0, 1.0]]).T
    assert any(np.allclose(p, qr_world[:3, 0], atol=0.002) for p in res.object_points)


def test_smeared_markers_count_less_in_the_filter():
    """fast_motion: markers read at the edges of the blurred sweeps have corners off by pixels; their
    measurements are down-weighted in the filter, which halves the plain way's jitter there."""
    from pathlib import Path

    from tracking.evaluation import evaluate
    from scenes import load_recording

    frames, session = load_recording(Path(__file__).resolve().parents[1] / "recordings" / "fast_motion")
    gt_t = np.array([f[0] for f in frames])
    gt = np.array([f[2] for f in frames])

    def score(poses):
        ok = [i for i, p in enumerate(poses) if p is not None]
        return evaluate(gt_t[ok], np.array([poses[i] for i in ok]), gt_t, gt)

    def track(unblur=None, **kw):
        tr = AnchorTracker(session.anchors, session.camera, **kw)
        tr.unblur_px = unblur   # the weighting alone: the blur stretch fit (test_blur_stretch.py) takes much of the bias out first
        return score([tr.process(img, t).world_from_camera for t, img, _ in frames])

    weighted, unweighted = track(), track(smear_sharpness=0.0)   # 0 turns the weighting off
    both = track(unblur=2.0)
    assert both.jitter_m < weighted.jitter_m
    plain = score([plain_opencv_pose(session.anchors, session.camera, img) for _, img, _ in frames])
    assert weighted.tracked == unweighted.tracked == plain.tracked
    assert weighted.jitter_m < 0.85 * unweighted.jitter_m
    assert weighted.jitter_m <= 0.5 * plain.jitter_m


def test_filter_weight_scales_the_pull_of_a_measurement():
    f1, f2 = PoseFilter(), PoseFilter()
    start = np.eye(4)
    for f in (f1, f2):
        f.update(start, 0.0, 0.5)
        f.update(start, 1 / 30, 0.5)
    moved = np.eye(4)
    moved[0, 3] = 0.01
    full = f1.update(moved, 2 / 30, 0.5)[0, 3]
    light = f2.update(moved, 2 / 30, 0.5, weight=0.2)[0, 3]
    assert 0 < light < full and light == pytest.approx(0.2 * full, rel=1e-6)
