"""The committed synthetic recordings in recordings/: valid, complete, small, and their ground truth holds."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.poses import read_tum, transform_points
from tracking.session import load_session
from tracking.sources import RecordingSource
from tracking.synth import scene_from_arg
from tracking.synth.patterns import anchor_corners
from tracking.synth.presets import PRESETS
from tracking.synth.renderer import DeskRenderer

from conftest import ROOT

RECORDINGS = ROOT / "recordings"


def aruco_detector(dictionary_id):
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    p.relativeCornerRefinmentWinSize = 0.6
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary_id), p)


def detect(anchor, img):
    """{marker index within the anchor: detected corners (4, 2)} for aruco/board anchors; QR: {0: corners}."""
    if anchor.kind == "qr":
        ok, pts = cv2.QRCodeDetector().detect(img)
        return {0: pts.reshape(4, 2)} if ok else {}
    corners, ids, _ = aruco_detector(anchor.dictionary_id).detectMarkers(img)
    wanted = anchor.marker_ids()
    return {wanted.index(m): c.reshape(4, 2) for c, m in zip(corners, [] if ids is None else ids.ravel())
            if m in wanted}


def detect_precise(anchor, img):
    """Like `detect`, but QR keeps only its three finder-pattern corners (TL, TR, BL), refined with
    cornerSubPix: QRCodeDetector itself is not subpixel and guesses the BR corner by line intersection."""
    if anchor.kind == "qr":
        found = detect(anchor, img)
        if not found:
            return {}
        g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 0.001)
        pts = np.float32(found[0][[0, 1, 3]]).reshape(-1, 1, 2).copy()
        refined = cv2.cornerSubPix(g, pts, (4, 4), (-1, -1), crit).reshape(3, 2)
        full = np.full((4, 2), np.nan)
        full[[0, 1, 3]] = refined
        return {0: full}
    return detect(anchor, img)


def ground_truth_pixels(session, anchor, pose):
    obj = transform_points(anchor.world_from_anchor, anchor_corners(anchor))
    return session.camera.project_world(obj, pose)


@pytest.mark.parametrize("name", list(PRESETS))
def test_recording_is_complete_and_consistent(name):
    folder = RECORDINGS / name
    session = load_session(folder)
    assert session.source["kind"] == "synthetic"
    times, poses = read_tum(folder / "groundtruth.tum")
    with RecordingSource(folder) as src:
        frames = list(src)
    assert src.error is None
    assert len(frames) == src.frame_count == len(times) == round(PRESETS[name]["duration"] * PRESETS[name]["fps"])
    np.testing.assert_allclose([f.t for f in frames], times, atol=1e-6)
    # ground truth on frames of low motion (blur moves detections): detections sit on the projected corners
    speed = np.r_[0, np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)] * session.fps
    errs = []
    for anchor_index, anchor in enumerate(session.anchors):
        for f in frames[::5]:
            if speed[f.index] > 0.15:
                continue
            gt = ground_truth_pixels(session, anchor, poses[f.index])
            for k, c in detect_precise(anchor, f.image).items():
                errs.append(np.nanmax(np.abs(c - gt[k])))
    assert len(errs) >= 3, "the anchors were detected too rarely to check the ground truth"
    assert np.median(errs) < 0.5 and max(errs) < 1.0, (np.median(errs), max(errs))  # compressed, noisy frames


def test_set_is_small_and_covers_the_cases():
    total = sum(p.stat().st_size for p in RECORDINGS.rglob("*") if p.is_file())
    assert total < 20e6, f"recordings/ holds {total / 1e6:.1f} MB; the budget is 20 MB"
    sizes = {(load_session(RECORDINGS / n).camera.width, load_session(RECORDINGS / n).camera.height) for n in PRESETS}
    assert {(640, 480), (1280, 720)} <= sizes
    bed = load_session(RECORDINGS / "printer_bed").anchors[0]
    assert (bed.kind, bed.dictionary, bed.id, bed.length) == ("aruco", "DICT_4X4_50", 42, 0.04)
    assert load_session(RECORDINGS / "qr_anchor").anchors[0].kind == "qr"


def test_marker_occluded_timeline():
    """Marker covered by the hand for 2 s (from 1.0 s to 3.0 s), then out of view for more than 1 s, then back."""
    folder = RECORDINGS / "marker_occluded"
    session = load_session(folder)
    anchor = session.anchors[0]
    times, poses = read_tum(folder / "groundtruth.tum")
    cam = session.camera
    in_view = []
    for pose in poses:
        px = ground_truth_pixels(session, anchor, pose)[0]
        inside = (px[:, 0] >= 0) & (px[:, 0] < cam.width) & (px[:, 1] >= 0) & (px[:, 1] < cam.height)
        in_view.append(bool(inside.any()))
    in_view = np.array(in_view)
    # longest run with no marker corner in the image
    best, run = 0, 0
    for v in in_view:
        run = 0 if v else run + 1
        best = max(best, run)
    assert best / session.fps > 1.0
    assert in_view[times < 3.0].all() and in_view[-5:].all()
    with RecordingSource(folder) as src:
        seen = {round(f.t, 3): bool(detect(anchor, f.image)) for f in src if f.index % 6 == 0}
    covered = [v for t, v in seen.items() if 1.05 <= t <= 2.95]
    visible = [v for t, v in seen.items() if t < 0.7 or t > 6.6]
    assert len(covered) >= 8 and not any(covered)
    assert all(visible)


def test_committed_board_orbit_matches_its_generator():
    """`arapp synth board_orbit` still renders the committed frames (up to MJPEG compression)."""
    scene = scene_from_arg("board_orbit")
    r = DeskRenderer(scene)
    with RecordingSource(RECORDINGS / "board_orbit") as src:
        src.seek(frame=45)
        f = next(iter(src))
    img, pose, t = r.render(45)
    _, poses = read_tum(RECORDINGS / "board_orbit" / "groundtruth.tum")
    np.testing.assert_allclose(pose, poses[45], atol=1e-6)
    assert f.t == pytest.approx(t, abs=1e-6)
    assert np.abs(img.astype(float) - f.image).mean() < 4.0
