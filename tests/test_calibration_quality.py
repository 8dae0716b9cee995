"""Calibration quality (issue 25): k3 fixed unless the views reach the image corners, standard
deviations reported, and a result whose uncertainty makes it worse than the estimated camera refused
with the corners that need views; the wizard asks for the missing corners.

The oracle is a known camera: board corners projected with cv2.projectPoints (plus Gaussian noise) are
the views, and results are judged by where the true camera and the solved one put the same rays. The
standard deviations are checked against cv2.calibrateCameraExtended's own.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.calibration import View, solve
from tracking.calibration_quality import CORNERS, corner_regions, intrinsic_covariance, missing_corners
from tracking.camera import Camera
from tracking.errors import CalibrationError

W, H = 640, 480
# a wide webcam lens with a real k3 (the oracle)
TRUE = Camera([[600.0, 0, 318.0], [0, 598.0, 243.0], [0, 0, 1]], [-0.28, 0.09, 0.0008, -0.0005, -0.015], W, H)
NX, NY, SQ = 9, 6, 0.03
BOARD = np.array([[x * SQ, y * SQ, 0.0] for y in range(NY) for x in range(NX)])
BOARD -= BOARD.mean(axis=0)


def board_view(rng, at_px, distance, tilt_deg, noise=0.2, camera=TRUE):
    """A View of the board centred on the ray through pixel `at_px`, `distance` m away, tilted by up to
    `tilt_deg` about x and y; corners outside the image are dropped (as a detector would)."""
    ray = camera.unproject(np.asarray(at_px, float))
    t = ray / np.linalg.norm(ray) * distance
    ax, ay = np.radians(rng.uniform(-tilt_deg, tilt_deg, 2))
    R = cv2.Rodrigues(np.array([ax, ay, rng.uniform(-0.3, 0.3)]))[0]
    img, _ = cv2.projectPoints(BOARD, cv2.Rodrigues(R)[0], t, camera.K, camera.dist)
    img = img.reshape(-1, 2) + rng.normal(0, noise, (len(BOARD), 2))
    inside = (img[:, 0] >= 0) & (img[:, 0] <= W - 1) & (img[:, 1] >= 0) & (img[:, 1] <= H - 1)
    ids = np.flatnonzero(inside)
    return View(BOARD[ids].copy(), img[ids], ids, 100.0)


def centre_views(seed=1, n=12):
    """Views whose corners stay in the middle 40 % of the image (what a user holding the board in front of
    the webcam gives)."""
    rng = np.random.default_rng(seed)
    return [board_view(rng, (W / 2 + rng.uniform(-40, 40), H / 2 + rng.uniform(-30, 30)), 0.9, 35) for _ in range(n)]


def whole_views(seed=2):
    """Views reaching every part of the image, the four corners included, tilted."""
    rng = np.random.default_rng(seed)
    targets = [(x, y) for x in (90, 320, 550) for y in (70, 240, 410)] * 2
    return [board_view(rng, t, rng.uniform(0.45, 0.6), 35) for t in targets]


DIST_TOL_PX = 0.75  # measured 0.55 px, at the top-right corner


def grid(step: int = 40) -> np.ndarray:
    """Pixels over the whole image, the four image corners last."""
    g = np.stack(np.meshgrid(np.arange(0, W, step), np.arange(0, H, step)), axis=-1).reshape(-1, 2).astype(float)
    return np.vstack([g, [[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]]])


def ray_errors(cam: Camera, truth: Camera = TRUE) -> np.ndarray:
    """Pixel distance between where `cam` and `truth` put the rays `truth` sees on grid()."""
    g = grid()
    return np.linalg.norm(cam.project(truth.unproject(g)) - g, axis=1)


def test_corner_regions_are_the_outer_quarter_of_width_and_height():
    """The rule as written in tracking.calibration_quality: x < W/4 (or >= 3W/4) and y < H/4 (or >= 3H/4)."""
    assert corner_regions([[159, 119]], W, H) == {"top-left"}
    assert corner_regions([[161, 119], [159, 121], [W / 2, H / 2]], W, H) == set()
    assert corner_regions([[480, 360], [479, 0]], W, H) == {"bottom-right"}
    assert missing_corners([np.array([[0.0, 0], [W - 1, 0]]), np.array([[0.0, H - 1]])], W, H) == ["bottom-right"]


def test_views_in_the_centre_fix_k3_instead_of_fitting_it():
    views = centre_views()
    assert missing_corners([v.img for v in views], W, H) == list(CORNERS)
    res = solve(views, W, H, refuse=False)
    assert res.fixed == ["k3"] and res.camera.dist[4] == 0.0 and res.missing_corners == list(CORNERS)
    assert "k3 held fixed: no view reached the top-left, top-right, bottom-left, bottom-right corners" in res.report()
    free = solve(views, W, H, flags=0, refuse=False)
    # freed, k3 is not determined by these views: its own standard deviation is far above any real lens's k3
    assert free.std["k3"] > 1.0, free.std
    # and the free fit is what the refusal is for: its 2 sigma spread at the corners is past the estimate's
    assert free.refusal is not None and max(free.spread_corners_px) > max(free.estimate_corners_px)
    with pytest.raises(CalibrationError, match="calibration refused.*top-left"):
        solve(views, W, H, flags=0)


def test_views_over_the_whole_image_recover_the_true_distortion():
    views = whole_views()
    res = solve(views, W, H)
    assert res.fixed == [] and res.missing_corners == [] and res.refusal is None
    # the distortion as the oracle has it: the rays the true camera sees over the whole image, corners included,
    # distorted by the solved terms instead of the true ones, land within DIST_TOL_PX of the true pixels
    rays = TRUE.unproject(grid())
    moved = Camera(TRUE.K, res.camera.dist, W, H).project(rays) - TRUE.project(rays)
    assert np.linalg.norm(moved, axis=1).max() < DIST_TOL_PX, np.linalg.norm(moved, axis=1).max()
    assert ray_errors(res.camera).max() < 3.0  # everything together (the centre's cy is 1.6 px off)
    # each parameter within 4 of its reported standard deviations of the truth
    truth = dict(zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"),
                     [TRUE.fx, TRUE.fy, TRUE.cx, TRUE.cy, *TRUE.dist]))
    got = dict(zip(truth, [res.camera.fx, res.camera.fy, res.camera.cx, res.camera.cy, *res.camera.dist]))
    for name in truth:
        assert abs(got[name] - truth[name]) < 4 * res.std[name], (name, got[name], truth[name], res.std[name])
    assert abs(res.camera.dist[4] - TRUE.dist[4]) < 0.03


def test_the_fixed_k3_is_better_at_the_corners_than_the_free_fit():
    views = centre_views(seed=3)
    fixed = solve(views, W, H, refuse=False)
    free = solve(views, W, H, flags=0, refuse=False)
    corners = ray_errors(fixed.camera)[-4:], ray_errors(free.camera)[-4:]
    assert corners[0].max() < corners[1].max(), corners


def test_covariance_matches_opencvs_standard_deviations():
    views = whole_views(seed=4)
    obj = [v.obj.astype(np.float32).reshape(-1, 1, 3) for v in views]
    img = [v.img.astype(np.float32).reshape(-1, 1, 2) for v in views]
    for flags in (0, cv2.CALIB_FIX_K3):
        _, K, dist, rvecs, tvecs, std, _, _ = cv2.calibrateCameraExtended(obj, img, (W, H), None, None, flags=flags)
        cov, free = intrinsic_covariance(obj, img, rvecs, tvecs, K, dist.ravel()[:5], flags)
        ours = np.sqrt(np.diag(cov))
        theirs = std.ravel()[free]
        assert np.allclose(ours, theirs, rtol=0.02), (ours, theirs)


def test_a_poor_set_is_refused_with_what_to_do():
    """Four frontal views far away in the middle: the focal length is barely determined."""
    rng = np.random.default_rng(7)
    views = [board_view(rng, (W / 2 + dx, H / 2 + dy), 1.6, 4, noise=0.5) for dx, dy in
             ((-20, -15), (20, -15), (-20, 15), (20, 15))]
    res = solve(views, W, H, min_views=4, refuse=False)
    assert res.refusal is not None
    with pytest.raises(CalibrationError) as e:
        solve(views, W, H, min_views=4)
    line = str(e.value)
    assert "\n" not in line and line.startswith("calibration refused")
    assert "worse than the estimated camera" in line
    assert "add views with the board near the top-left, top-right, bottom-left, bottom-right corners" in line


def test_the_calibrate_command_refuses_a_poor_set_in_one_line_and_writes_nothing(tmp_path, capsys):
    from arapp.cli import main
    from tracking.anchors.render import look_at, render_view
    from tracking.recording.schema import parse_anchors

    an = parse_anchors([{"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 7, "squares_y": 5,
                         "square_length": 0.03, "marker_length": 0.022}])
    rng = np.random.default_rng(3)
    centre = np.array([0.105, 0.075, 0.0])
    for i, (dx, dy) in enumerate(((-0.03, -0.02), (0.03, -0.02), (-0.03, 0.02), (0.03, 0.02), (0.0, 0.0))):
        T = look_at(centre + [dx, dy, -0.75], centre + [dx, dy, 0], up=(0, -1, 0))  # facing, far: small, central
        cv2.imwrite(str(tmp_path / f"v{i}.png"), render_view(an, TRUE, T, noise_std=1.0, rng=rng))
    out = tmp_path / "cam.yaml"
    assert main(["calibrate", "--images", str(tmp_path), "--min-views", "4", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "calibration refused" in err[0] and "corners of the image" in err[0], err
    assert not out.exists()


def test_the_wizard_asks_for_the_missing_corners(qtbot):
    from arapp.app.calibration_session import CalibrationSession, Feedback, draw_feedback
    from arapp.gui.first_hour.calibration_wizard import CalibrationWizard

    session = CalibrationSession()
    session.collector.width, session.collector.height = W, H
    session.collector.views.append(View(BOARD[:4], np.array([[10.0, 10], [40, 10], [10, 40], [40, 40]]),
                                        np.arange(4), 100.0))  # a view in the top-left corner only
    assert session.missing_corners == ["top-right", "bottom-left", "bottom-right"]
    wiz = CalibrationWizard(lambda: None, session=session)
    qtbot.addWidget(wiz)
    fb = Feedback("kept", None, 1, session.coverage, 0.0, None, np.zeros((H, W, 3), np.uint8))
    wiz._update_stats(fb, 0, None)
    assert "Still needed: the board near the top-right, bottom-left and bottom-right corners of the image" \
        in wiz.stats.text()
    drawn = draw_feedback(np.zeros((H, W, 3), np.uint8), session, fb)
    orange = np.all(drawn == (0, 200, 255), axis=-1)
    q = (W // 4, H // 4)
    assert not orange[:q[1], :q[0]].any()  # the reached corner is not outlined
    assert orange[:q[1], W - q[0]:].any() and orange[H - q[1]:, :q[0]].any() and orange[H - q[1]:, W - q[0]:].any()


def test_the_real_caliscope_clip_gives_a_calibration_better_than_the_estimate():
    """The clip behind the issue's k3 = 54.6: 9 views in the middle of a 1280x720 webcam picture. k3 is held,
    the result is kept, and against the clip's own measured calibration (caliscope's config.toml, RMS 0.54 px;
    the oracle) it puts rays nearer than the estimated camera does. The rule's constants were not tuned on it."""
    import json
    from pathlib import Path

    from tracking.calibration import BoardSpec, ViewCollector
    from tracking.default_intrinsics import estimated_camera
    from tracking.recording.schema import parse_anchors
    from tracking.sources import VideoFileSource

    data = Path(__file__).resolve().parent / "data" / "realvideo"
    board = BoardSpec.from_anchor(parse_anchors(json.loads((data / "caliscope_anchors.json").read_text()))[0])
    col = ViewCollector(board)
    with VideoFileSource(data / "caliscope_charuco_cam0.mp4") as src:
        for frame in src:
            if 60 <= frame.index <= 100:  # where the board is held up (frames outside it show none: measured)
                col.add(frame.image)
    res = solve(col.views, col.width, col.height, col.coverage, min_views=8)
    assert res.fixed == ["k3"] and res.refusal is None
    truth = Camera.load_yaml(data / "caliscope_cam0.yml")
    g = np.stack(np.meshgrid(np.arange(0, 1280, 80), np.arange(0, 720, 80)), axis=-1).reshape(-1, 2).astype(float)
    rays = truth.unproject(g)
    ours = np.linalg.norm(res.camera.project(rays) - g, axis=1)
    guess = np.linalg.norm(estimated_camera(1280, 720).project(rays) - g, axis=1)
    print("mean ray error, calibrated / estimated:", ours.mean(), guess.mean())
    assert ours.mean() < 0.6 * guess.mean()  # measured 52 px against 115 px
    # freed, k3 is what the refusal catches on these views (measured: +/- 666 px at a corner)
    free = solve(col.views, col.width, col.height, col.coverage, min_views=8, flags=0, refuse=False)
    assert free.refusal is not None and "top-left" in free.refusal
