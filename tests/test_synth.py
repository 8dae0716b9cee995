"""Synthetic scenes: exact ground truth (checked with OpenCV's own detectors), conventions, scene errors."""

from __future__ import annotations

import copy

import cv2
import numpy as np
import pytest

from tracking.errors import SessionError
from tracking.poses import invert, transform_points
from tracking.synth.patterns import anchor_corners
from tracking.synth.presets import BOARD, preset
from tracking.synth.renderer import DeskRenderer
from tracking.synth.scene import parse_scene

DIST = [-0.12, 0.05, 0.001, -0.001, 0.0]  # stronger than the presets: distortion must be exact too


def detector(dictionary_id: int) -> cv2.aruco.ArucoDetector:
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    p.relativeCornerRefinmentWinSize = 0.6  # window up to 60% of a bit: small markers get a usable window
    p.cornerRefinementMinAccuracy = 0.001
    p.cornerRefinementMaxIterations = 100
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary_id), p)


def clean_scene(anchors, trajectory, **kw):
    """A noise-free scene (no noise, blur, exposure, compression), with lens distortion."""
    data = {"anchors": anchors, "trajectory": trajectory, "fps": 30, "duration": 2.0, "seed": 5,
            "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": DIST},
            "desk": {"size": [0.9, 0.7], "ppm": 1500, "seed": 2}, "effects": {"optics_blur": 0.0}}
    data.update(kw)
    return parse_scene(data)


def corner_errors(renderer, frames, anchor_index=0):
    """Detected minus ground-truth-projected marker corners (N, 2) over the given frames."""
    a = renderer.scene.anchors[anchor_index]
    det = detector(a.dictionary_id)
    obj = transform_points(a.world_from_anchor, anchor_corners(a))
    ids_expected = a.marker_ids()
    errs, counts = [], []
    for i in frames:
        img, pose, _ = renderer.render(i)
        corners, ids, _ = det.detectMarkers(img)
        assert ids is not None, f"frame {i}: no marker detected"
        gt = renderer.scene.camera.project_world(obj, pose)
        found = [(c, mid) for c, mid in zip(corners, ids.ravel()) if mid in ids_expected]  # other anchors skipped
        assert found, f"frame {i}: none of ids {ids_expected} detected"
        counts.append(len(found))
        for c, mid in found:
            errs.append(c.reshape(4, 2) - gt[ids_expected.index(mid)])
    return np.concatenate(errs), counts


def test_board_ground_truth_is_exact_to_subpixel():
    sc = clean_scene([BOARD], {"kind": "orbit", "azimuth_start": -140, "azimuth_end": -40, "distance": 0.45,
                               "elevation": 55, "elevation_swing": 10})
    r = DeskRenderer(sc)
    err, counts = corner_errors(r, [0, 45])
    assert min(counts) == 12
    assert np.abs(err).max() < 0.5, np.abs(err).max()
    assert np.abs(err.mean(axis=0)).max() < 0.05  # no bias: pixel-centre and distortion conventions agree


@pytest.mark.parametrize("squares", [(5, 4), (6, 5)])   # even and odd row counts (OpenCV's two layouts)
def test_charuco_ground_truth_matches_the_charuco_detector(squares):
    board = {"kind": "charuco", "dictionary": "DICT_4X4_50", "squares_x": squares[0], "squares_y": squares[1],
             "square_length": 0.03, "marker_length": 0.022}
    sc = clean_scene([board], {"kind": "orbit", "azimuth_start": -130, "azimuth_end": -50, "distance": 0.42,
                               "elevation": 60, "elevation_swing": 10})
    r = DeskRenderer(sc)
    err, counts = corner_errors(r, [0, 30])            # the ArUco markers in the white squares
    assert min(counts) == squares[0] * squares[1] // 2
    # (their refined corners are pulled a little by the chessboard squares they touch: under a pixel)
    assert np.abs(err).max() < 1.0 and np.abs(err.mean(axis=0)).max() < 0.1
    # the chessboard corners, which carry a ChArUco pose, to a fraction of a pixel
    from tracking.anchors.model import charuco_board

    cb = charuco_board(sc.anchors[0])
    det = cv2.aruco.CharucoDetector(cb)
    chess = np.asarray(cb.getChessboardCorners(), float)
    for i in (0, 30):
        img, pose, _ = r.render(i)
        cc, ci, _, _ = det.detectBoard(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        assert ci is not None and len(ci) == (squares[0] - 1) * (squares[1] - 1)
        gt = sc.camera.project_world(chess[ci.ravel()], pose)
        assert np.abs(cc.reshape(-1, 2) - gt).max() < 0.3


def test_single_marker_ground_truth_and_world_side():
    marker = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.05}
    sc = clean_scene([marker], {"kind": "approach", "azimuth": -70, "elevation": 65, "distance_start": 0.5,
                                "distance_end": 0.25})
    r = DeskRenderer(sc)
    err, _ = corner_errors(r, [0, 30, 59])
    assert np.abs(err).max() < 0.5 and np.abs(err.mean(axis=0)).max() < 0.1
    # aruco world: z out of the paper, so the camera is above (z > 0) and looks down (-z)
    pose = r.world_from_camera(0.5)
    assert pose[2, 3] > 0.1 and pose[:3, 2][2] < -0.5


def test_board_world_is_seen_from_its_minus_z_side():
    sc = clean_scene([BOARD], {"kind": "static", "azimuth": -90, "distance": 0.4, "elevation": 60})
    r = DeskRenderer(sc)
    pose = r.world_from_camera(0.0)
    assert pose[2, 3] < -0.1  # GridBoard z points into the paper: the viewer is at negative z
    # board x axis appears to the right and board y downward in the image, as printed
    px = sc.camera.project_world(np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], float), pose)
    assert px[1, 0] - px[0, 0] > 40 and px[2, 1] - px[0, 1] > 20


def test_second_anchor_lies_where_world_from_anchor_says():
    # an aruco marker beside the board, printed upright: anchor x = board x, anchor y = -board y
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = [0.23, 0.06, 0.0]
    second = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 20, "length": 0.05, "world_from_anchor": T.tolist()}
    sc = clean_scene([BOARD, second], {"kind": "static", "azimuth": -90, "distance": 0.45, "elevation": 70,
                                       "target": [0.05, 0.0, 0.0]})
    r = DeskRenderer(sc)
    err, _ = corner_errors(r, [0], anchor_index=1)
    assert len(err) == 4 and np.abs(err).max() < 0.5


def refine_l_corners(img, pts):
    """cv2.cornerSubPix on QR finder-pattern corners (sharp black-on-white L corners)."""
    g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 0.001)
    return cv2.cornerSubPix(g, np.float32(pts).reshape(-1, 1, 2).copy(), (4, 4), (-1, -1), crit).reshape(-1, 2)


FINDER = [0, 1, 3]  # QR corners at finder patterns (TL, TR, BL); the BR corner is a data module, not a corner


def test_qr_ground_truth_matches_qr_detector():
    qr = {"kind": "qr", "text": "arapp anchor 1", "length": 0.08}
    sc = clean_scene([qr], {"kind": "orbit", "azimuth_start": -110, "azimuth_end": -70, "distance": 0.4,
                            "elevation": 65})
    r = DeskRenderer(sc)
    a = sc.anchors[0]
    for i in (0, 40):
        img, pose, _ = r.render(i)
        text, pts, _ = cv2.QRCodeDetector().detectAndDecode(img)
        assert text == "arapp anchor 1"
        gt = sc.camera.project_world(anchor_corners(a)[0], pose)
        pts = pts.reshape(4, 2)
        # QRCodeDetector returns the symbol corners (quiet zone excluded) TL, TR, BR, BL, without subpixel
        # refinement; refined, the three finder-pattern corners sit on the ground truth.
        assert np.abs(pts - gt).max() < 1.5
        assert np.abs(refine_l_corners(img, pts[FINDER]) - gt[FINDER]).max() < 0.5


def test_effects_change_pixels_but_not_ground_truth():
    base = preset("board_orbit")
    base["effects"] = {"optics_blur": 0.0}
    fx = copy.deepcopy(base)
    fx["effects"] = {"noise": 3.0, "motion_blur": 0.8, "blur_samples": 3, "exposure": {"amplitude": 0.3, "period": 1.0},
                     "jpeg_quality": 60, "vignette": 0.2, "optics_blur": 0.6}
    for d in (base, fx):
        d["desk"] = {"size": [0.9, 0.7], "ppm": 1200, "seed": 1}
        d["supersample"] = 2
    ra, rb = DeskRenderer(parse_scene(base)), DeskRenderer(parse_scene(fx))
    ia, pa, ta = ra.render(10)
    ib, pb, tb = rb.render(10)
    np.testing.assert_array_equal(pa, pb)
    assert ta == tb == pytest.approx(10 / 30)
    diff = np.abs(ia.astype(float) - ib.astype(float))
    assert diff.mean() > 3.0
    # exposure at t = 1/3 s with period 1 s: gain 1 + 0.3 sin(2pi/3) > 1, so brighter overall
    assert ib.mean() > ia.mean() * 1.05


def test_hand_occluder_covers_the_marker_only_while_active():
    marker = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 7, "length": 0.06}
    sc = clean_scene([marker], {"kind": "static", "azimuth": -90, "distance": 0.4, "elevation": 60},
                     effects={"occluder": {"start": 0.5, "end": 1.5, "ramp": 0.2, "anchor": 0}})
    r = DeskRenderer(sc)
    det = detector(sc.anchors[0].dictionary_id)
    seen = {}
    for t in (0.2, 1.0, 1.8):
        img, pose, _ = r.render(int(t * 30))
        _, ids, _ = det.detectMarkers(img)
        seen[t] = ids is not None
        if t == 1.0:
            centre, _ = r.anchor_pixel_extent(pose, 0)
            b, g, rr = img[int(centre[1]), int(centre[0])].astype(int)
            assert rr > g > b and rr > 120  # skin tone over the marker centre
    assert seen == {0.2: True, 1.0: False, 1.8: True}


def test_trajectories_are_smooth_and_deterministic():
    from tracking.synth.trajectory import make_trajectory

    for kind in ("orbit", "approach", "pan", "static", "leave_view"):
        sc = clean_scene([BOARD], {"kind": kind, "shake": {"pos_mm": 2, "rot_deg": 0.3}})
        f = make_trajectory(sc.trajectory, sc.duration, seed=3)
        g = make_trajectory(sc.trajectory, sc.duration, seed=3)
        ts = np.arange(0, sc.duration, 1 / 30)
        P = np.array([f(t) for t in ts])
        np.testing.assert_array_equal(P, np.array([g(t) for t in ts]))
        steps = np.linalg.norm(np.diff(P[:, :3, 3], axis=0), axis=1)
        assert steps.max() < 0.03, (kind, steps.max())  # under 3 cm per frame: no jumps
        for T in P:
            np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
            assert np.linalg.det(T[:3, :3]) > 0


def test_scene_errors_name_the_field():
    good = {"anchors": [BOARD], "trajectory": {"kind": "orbit"}}
    cases = [
        ({**good, "colour": 1}, r"scene.colour: unknown key"),
        ({"trajectory": {"kind": "orbit"}}, r"scene.anchors: missing"),
        ({**good, "trajectory": {"kind": "spiral"}}, r"scene.trajectory.kind: must be static, orbit"),
        ({**good, "trajectory": {"kind": "keyframes", "keys": [{"t": 0, "eye": [0, 0, 1]}]}},
         r"trajectory.keys: need at least two"),
        ({**good, "effects": {"rain": 1}}, r"scene.effects.rain: unknown effect"),
        ({**good, "fps": 0}, r"scene.fps: must be a positive number"),
        ({**good, "camera": {"width": 640, "height": 480, "hfov_deg": 200}}, r"scene.camera.hfov_deg"),
        ({**good, "desk": {"style": "marble"}}, r"scene.desk.style: must be one of"),
        ({**good, "anchors": [{"kind": "charuco", "dictionary": "DICT_4X4_50", "squares_x": 5, "squares_y": 4,
                               "square_length": 0.03, "marker_length": 0.04}]}, r"marker_length 0.04 must be smaller"),
    ]
    tilted = np.eye(4)
    tilted[:3, :3] = cv2.Rodrigues(np.array([0.3, 0.0, 0.0]))[0]
    cases.append(({**good, "anchors": [BOARD, {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 20,
                                               "length": 0.05, "world_from_anchor": tilted.tolist()}]},
                  r"scene.anchors\[1\].world_from_anchor: synth prints anchors on the desk"))
    face_down = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 20, "length": 0.05,
                 "world_from_anchor": np.diag([1.0, 1.0, 1.0, 1.0]).tolist()}  # z into the board world's desk
    cases.append(({**good, "anchors": [BOARD, face_down]}, r"anchors\[1\].world_from_anchor"))
    for data, msg in cases:
        with pytest.raises(SessionError, match=msg):
            parse_scene(data)


def test_pose_inverse_consistency_of_rays():
    # A desk point straight ahead of the camera projects to the principal point region, and back.
    sc = clean_scene([BOARD], {"kind": "static", "azimuth": -90, "distance": 0.4, "elevation": 60})
    r = DeskRenderer(sc)
    pose = r.world_from_camera(0.0)
    cam_from_world = invert(pose)
    target_world = r.world_from_desk @ np.append(r.centre, 1.0)
    pc = transform_points(cam_from_world, target_world[:3])
    assert abs(pc[0]) < 1e-9 and abs(pc[1]) < 1e-9 and pc[2] == pytest.approx(0.4)


def test_cli_synth_writes_a_valid_recording_and_refuses_overwrite(tmp_path, capsys):
    import json

    from arapp.cli import main
    from tracking.poses import read_tum
    from tracking.recording.schema import load_session

    scene = {"name": "tiny", "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 1, "length": 0.05}],
             "trajectory": {"kind": "orbit", "distance": 0.3}, "camera": {"width": 160, "height": 120},
             "desk": {"size": [0.5, 0.4], "ppm": 600}, "supersample": 1, "duration": 1.0}
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "tiny"
    assert main(["synth", str(path), "--out", str(out), "--frames", "4"]) == 0
    s = load_session(out)
    assert (s.camera.width, s.camera.height) == (160, 120) and s.source["kind"] == "synthetic"
    times, poses = read_tum(out / "groundtruth.tum")
    np.testing.assert_allclose(times, np.arange(4) / 30, atol=1e-6)  # TUM stores 6 decimals
    assert main(["synth", str(path), "--out", str(out)]) == 2
    assert "use --force" in capsys.readouterr().err
    assert main(["synth", "no_such_preset", "--out", str(tmp_path / "x")]) == 2
    assert "no synthetic preset 'no_such_preset'; presets: board_orbit" in capsys.readouterr().err
    path.write_text('{"anchors": [}')
    assert main(["synth", str(path), "--out", str(tmp_path / "y")]) == 2
    assert "tiny.json: invalid JSON at line 1" in capsys.readouterr().err


def test_leave_view_trajectory_takes_the_marker_out_of_view_and_back():
    from tracking.synth.trajectory import make_trajectory

    marker = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 7, "length": 0.06}
    traj = {"kind": "leave_view", "away": [0.5, 0.1], "leave_at": 0.5, "back_at": 2.5, "ramp": 0.5}
    sc = clean_scene([marker], traj, duration=3.0)
    f = make_trajectory(sc.trajectory, sc.duration)
    corners = anchor_corners(sc.anchors[0])[0]
    cam = sc.camera

    def in_view(t):
        px = cam.project_world(corners, f(t))  # aruco world: the desk frame is the world frame
        return bool(((px[:, 0] >= 0) & (px[:, 0] < cam.width) & (px[:, 1] >= 0) & (px[:, 1] < cam.height)).any())

    assert in_view(0.2) and in_view(2.9)
    assert not any(in_view(t) for t in np.arange(1.0, 2.0, 0.05))
