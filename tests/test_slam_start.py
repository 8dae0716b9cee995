"""The SLAM tracker does not start its pose from anchors whose edges are smeared.

A 5x3 GridBoard rendered by the synthesiser (still camera, ground truth); the first frames are smeared
here along x with a 6-pixel box kernel (what a pan at ~300 px/s does over a 20 ms exposure), the rest
are sharp. OpenCV's own detector confirms the board is still found in the smeared frames."""

import cv2
import numpy as np
import pytest

from scene_book import book_frames
from tracking.fusion import Tracker

SMEARED = 4   # frames


@pytest.fixture(scope="module")
def board_frames():
    frames, scene = book_frames("still_board")   # tests/scene_book.py
    kernel = np.ones((1, 6), np.float32) / 6
    out = [(t, cv2.filter2D(img, -1, kernel) if i < SMEARED else img, gt) for i, (t, img, gt) in enumerate(frames)]
    return out, scene


def _run(frames, scene, start_sharpness):
    errs, states = [], []
    with Tracker(scene.camera, scene.anchors, threaded=False, start_sharpness=start_sharpness) as tr:
        for t, img, gt in frames:
            res = tr.process(img, t)
            states.append(res.state)
            errs.append(np.nan if res.world_from_camera is None
                        else np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
    return np.array(errs), states


def test_smeared_anchors_do_not_start_the_pose(board_frames):
    frames, scene = board_frames
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    for _, img, _ in frames[:SMEARED]:
        _, ids, _ = det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        assert ids is not None and len(ids) >= 10   # the smeared board is still found
    errs, states = _run(frames, scene, 0.2)
    assert states[:SMEARED] == ["lost"] * SMEARED
    assert states[SMEARED] == "marker" and np.isfinite(errs[SMEARED:]).all()
    assert np.nanmax(errs) < 0.002
    # with the check off the smeared frames start it: measured 2.8 mm off, against 0.8 mm at most once sharp
    errs0, states0 = _run(frames, scene, 0.0)
    assert states0[0] == "marker" and np.nanmax(errs0[:SMEARED]) > 2 * np.nanmax(errs)


def _look(eye, target) -> np.ndarray:
    """world_from_camera at `eye` looking at `target` (world z up, image y down)."""
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.c_[x, np.cross(z, x), z]
    T[:3, 3] = eye
    return T


@pytest.mark.parametrize("markers, sigma, uncertain", [((0, 1, 4, 5), 1.0, True), ((0, 1, 4, 5), 0.15, False),
                                                         (tuple(range(12)), 1.0, False)])
def test_a_board_whose_first_pose_is_likely_centimetres_off_does_not_start_it(markers, sigma, uncertain):
    """Four markers of a 4x3 board at the image edge, their corners smeared to ~1 px of noise (a fast pan's
    first sighting), fit that noise and read about a centimetre off at 0.5 m; sharp, or the whole board, they
    read millimetres off. `Handover.start_uncertain` must tell the two apart from the fit's own residual.
    Oracle: the camera position's RMS error over 200 noise draws, each pose by cv2.solvePnP (SQPnP, then
    Levenberg-Marquardt), against the 1.5 % of the distance the rule stands for (measured 10.9 mm against a
    7.7 mm limit; 1.7 mm sharp; 3.7 mm for the whole board)."""
    from types import SimpleNamespace

    from tracking.camera import Camera
    from tracking.recording.schema import parse_anchors
    from tracking.fusion.handover import START_SPREAD

    K = np.array([[530.0, 0, 319.5], [0, 530.0, 239.5], [0, 0, 1]])
    board = [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
              "marker_length": 0.035, "separation": 0.008}]
    cam = Camera(K, np.zeros(5), 640, 480)
    rng = np.random.default_rng(1)
    with Tracker(cam, parse_anchors(board), threaded=False) as tr:
        model = tr.anchor_tracker.models[0]
        world = np.concatenate([model.to_world(model.markers[i]) for i in markers])
        centre = np.concatenate([model.to_world(c) for c in model.markers.values()]).mean(axis=0)
        pose = _look(centre + [0.25, -0.25, 0.35], centre + [0.12, 0.02, 0.0])
        uv = cam.project_world(world, pose)
        errors, said = [], []
        for _ in range(200):
            seen = uv + rng.normal(0.0, sigma, uv.shape)
            _, rv, tv = cv2.solvePnP(world, seen, K, None, flags=cv2.SOLVEPNP_SQPNP)
            _, rv, tv = cv2.solvePnP(world, seen, K, None, rv, tv, True, cv2.SOLVEPNP_ITERATIVE)
            cam_from_world = np.eye(4)
            cam_from_world[:3, :3], cam_from_world[:3, 3] = cv2.Rodrigues(rv)[0], tv.ravel()
            fitted = np.linalg.inv(cam_from_world)
            rms = float(np.sqrt(np.mean((cv2.projectPoints(world, rv, tv, K, None)[0].reshape(-1, 2) - seen) ** 2)))
            errors.append(np.linalg.norm(fitted[:3, 3] - pose[:3, 3]))
            said.append(tr.handover.start_uncertain(SimpleNamespace(raw_world_from_camera=fitted, anchors_seen=[0],
                                                            object_points=world, reprojection_error=rms)))
    limit = START_SPREAD * np.linalg.norm(pose[:3, 3] - world.mean(axis=0))
    rms_error = np.sqrt(np.mean(np.square(errors)))
    assert (rms_error > limit) == uncertain, (rms_error, limit)
    assert np.mean(said) > 0.9 if uncertain else np.mean(said) < 0.1, np.mean(said)
