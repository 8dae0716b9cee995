"""The benchmarks' plain peers (benchmarks/peers.py): the plain pose is OpenCV's, the QR call choice follows
its rule, and the filtered peer smooths noise without lagging a steady motion."""

from __future__ import annotations

import sys

import cv2
import numpy as np

from tracking.poses import from_rvec_tvec, invert, make_pose
from scenes import load_recording

from conftest import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))
from peers import FilteredPeer, PlainPeer, QR_CALLS, choose_qr_call, measure_qr_calls  # noqa: E402


def test_plain_peer_is_detect_markers_and_one_solvepnp():
    frames, session = load_recording(ROOT / "recordings" / "board_orbit", slice(0, 3))
    peer = PlainPeer(session.anchors, session.camera)
    a = session.anchors[0]
    d = cv2.aruco.getPredefinedDictionary(a.dictionary_id)
    board = cv2.aruco.GridBoard((a.markers_x, a.markers_y), a.marker_length, a.separation, d,
                                np.array(a.marker_ids()))
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(d, p)
    for _, img, gt in frames:
        T = peer.pose(img)
        assert T is not None and np.linalg.norm(T[:3, 3] - gt[:3, 3]) < 0.005
        # OpenCV's own board matching and one solvePnP give the same pose
        corners, ids, _ = det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        assert len(ids) == 12
        obj, imgp = board.matchImagePoints(corners, ids)
        _, rvec, tvec = cv2.solvePnP(obj, imgp, session.camera.K, session.camera.dist)
        ref = a.world_from_anchor @ invert(from_rvec_tvec(rvec, tvec))
        np.testing.assert_allclose(T, ref, atol=1e-6)


def test_qr_call_choice_is_the_fastest_that_decodes_nearly_as_often_as_the_best():
    measured = {"a": (100, 30.0), "b": (95, 12.0), "c": (89, 5.0), "d": (60, 1.0)}
    assert choose_qr_call(measured) == "b"
    assert choose_qr_call({"a": (10, 3.0), "b": (10, 2.0)}) == "b"
    frames, session = load_recording(ROOT / "recordings" / "qr_anchor", slice(0, 4))
    m = measure_qr_calls(frames, session.anchors[0].text)
    assert set(m) == set(QR_CALLS) and max(h for h, _ in m.values()) == 4
    peer = PlainPeer(session.anchors, session.camera, choose_qr_call(m))
    assert all(peer.pose(img) is not None for _, img, _ in frames)


def test_filtered_peer_smooths_noise_and_follows_a_steady_motion():
    rng = np.random.default_rng(0)
    f = FilteredPeer()
    raw_err, filt_err = [], []
    for k in range(120):
        t = k / 30
        truth = make_pose(np.eye(3), [0.05 * t, 0.0, 0.45])  # 5 cm/s sideways, 45 cm away
        noisy = truth.copy()
        noisy[:3, 3] += rng.normal(0, 0.0005, 3)
        out = f.update(noisy, t)
        raw_err.append(noisy[:3, 3] - truth[:3, 3])
        filt_err.append(out[:3, 3] - truth[:3, 3])
    assert f.update(None, 5.0) is None
    raw, filt = np.array(raw_err[30:]), np.array(filt_err[30:])
    jit = lambda e: np.sqrt(np.mean(np.sum(np.diff(e, axis=0) ** 2, axis=1)))  # noqa: E731
    assert jit(filt) < 0.5 * jit(raw)
    assert np.linalg.norm(filt.mean(axis=0)) < 0.0003  # no lag behind the motion
