"""Calibration in the app: the Qt-free session and the wizard on a synthetic ChArUco recording.

The oracle is the recording's own camera (session.json, the intrinsics the
synthetic views were rendered with) and OpenCV's ChArUco detector for the
printed sheet.
"""

from __future__ import annotations

import threading

import cv2
import numpy as np
import pytest

from tracking.camera import Camera
from tracking.sources import RecordingSource, VideoFileSource

BOARD = {"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 7, "squares_y": 5,
         "square_length": 0.03, "marker_length": 0.022, "first_id": 0}
# camera positions around the board (desk z up), aimed so that the board lands in different parts of the
# picture, with the camera rolled so that the board is tilted towards different sides
EYES = [(-0.05, -0.30, 0.32), (0.20, -0.25, 0.30), (0.25, 0.05, 0.33), (0.12, 0.28, 0.30), (-0.20, 0.20, 0.32),
        (-0.28, -0.05, 0.30), (-0.10, -0.22, 0.40), (0.05, 0.0, 0.42)]
TARGETS = [(0.06, 0.04, 0), (-0.06, 0.05, 0), (-0.05, -0.05, 0), (0.07, -0.05, 0), (0.0, 0.06, 0), (0.06, 0.0, 0),
           (-0.07, -0.03, 0), (0.0, 0.0, 0)]
ROLLS = [0, 70, 0, -70, 160, 30, -30, 0]


@pytest.fixture(scope="module")
def charuco_recording(tmp_path_factory):
    from tracking.synth import synthesize
    from tracking.synth.scene import parse_scene

    keys = [{"t": k * 0.5, "eye": list(e), "target": list(t), "roll": r}
            for k, (e, t, r) in enumerate(zip(EYES, TARGETS, ROLLS))]
    scene = {"name": "charuco_calibration", "seed": 21, "fps": 6, "duration": 3.5,
             "camera": {"width": 640, "height": 480, "hfov_deg": 58, "dist": [-0.1, 0.05, 0.0, 0.0, 0.0]},
             "anchors": [BOARD], "desk": {"size": [1.0, 0.8], "ppm": 2000, "seed": 5},
             "trajectory": {"kind": "keyframes", "keys": keys},
             "effects": {"noise": 0.8}, "video": {"fourcc": "MJPG", "quality": 92}, "supersample": 1}
    out = tmp_path_factory.mktemp("charuco") / "charuco_calibration"
    session = synthesize(parse_scene(scene), out)
    return out, session.camera


def assert_close_to(cam: Camera, truth: Camera):
    # measured on this recording: fx, fy within 0.5 %, the centre within 3 px
    assert abs(cam.fx - truth.fx) / truth.fx < 0.015, (cam.fx, truth.fx)
    assert abs(cam.fy - truth.fy) / truth.fy < 0.015, (cam.fy, truth.fy)
    assert abs(cam.cx - truth.cx) < 8 and abs(cam.cy - truth.cy) < 8, (cam.cx, cam.cy, truth.cx, truth.cy)


def test_session_recovers_the_recordings_camera(charuco_recording):
    from arapp.app.calibration_session import CalibrationSession, collect_from_source

    folder, truth = charuco_recording
    session = CalibrationSession()
    seen = []
    with RecordingSource(folder) as src:
        collect_from_source(src, session, progress=lambda i, n, fb: seen.append((i, n, fb.verdict)))
    assert seen[0][1] == 21 and len(seen) == 21
    assert session.ready and session.kept >= 12
    assert session.tilt_coverage >= 0.8  # facing and tilted towards (nearly) every side
    res = session.solve()
    assert_close_to(res.camera, truth)
    assert res.rms < 0.6 and res.quality in ("good", "usable")


def test_collecting_stops_when_cancelled(charuco_recording):
    from arapp.app.calibration_session import CalibrationSession, collect_from_source

    cancel = threading.Event()
    session = CalibrationSession()

    def progress(i, n, fb):
        if i == 2:
            cancel.set()

    with RecordingSource(charuco_recording[0]) as src:
        looked = collect_from_source(src, session, cancel=cancel, progress=progress)
    assert looked == 3


def test_verdict_rule():
    from arapp.app.calibration_session import verdict

    assert verdict(0.3, 0.7, 0.8)[0] == "good"
    q, advice = verdict(0.3, 0.2, 0.8)
    assert q == "usable" and "edges" in advice
    assert verdict(1.5, 0.9, 1.0)[0] == "poor"


def test_board_sheet_is_found_by_opencvs_charuco_detector(tmp_path):
    from arapp.app.calibration_session import DEFAULT_BOARD, write_board_sheet

    paths = write_board_sheet(tmp_path)
    png = next(p for p in paths if p.suffix == ".png")
    img = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    board = cv2.aruco.CharucoBoard((7, 5), 0.03, 0.022, d)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(img)
    assert ids is not None and len(ids) == DEFAULT_BOARD.corner_count()
    # true scale: neighbouring corners 30 mm apart at 300 dpi
    pts = dict(zip(ids.ravel().tolist(), corners.reshape(-1, 2)))
    assert abs(np.linalg.norm(pts[1] - pts[0]) - 0.03 / 0.0254 * 300) < 2.0


def test_wizard_calibrates_saves_and_the_camera_is_used_next_time(qtbot, charuco_recording, config_dir):
    from arapp.store import camera_store
    from arapp.gui.first_hour.calibration_wizard import CalibrationWizard

    folder, truth = charuco_recording
    video = next(p for p in folder.iterdir() if p.suffix in (".avi", ".mkv", ".mp4"))
    opened = []

    def opener():
        src = VideoFileSource(video)  # a plain video without calibration, as a user's clip
        opened.append(src)
        return src

    wiz = CalibrationWizard(opener)
    qtbot.addWidget(wiz)
    wiz.show()
    assert wiz.pages.currentIndex() == 0
    wiz.to_collect_button.click()
    assert wiz.pages.currentIndex() == 1 and not wiz.solve_button.isEnabled()
    wiz.start_button.click()
    qtbot.waitUntil(lambda: not wiz.collecting and wiz.start_button.isEnabled(), timeout=60000)
    assert not wiz.errors
    assert wiz.solve_button.isEnabled()
    assert "Views kept" in wiz.stats.text() and wiz.progress.value() == wiz.session.kept
    assert not wiz.view.pixmap().isNull()
    with qtbot.waitSignal(wiz.calibrated, timeout=60000) as sig:
        wiz.solve_button.click()
        qtbot.waitUntil(lambda: wiz.save_button.isEnabled(), timeout=60000)
        assert "RMS reprojection error" in wiz.result_label.text()
        wiz.save_button.click()
    path, cam = sig.args
    assert path.startswith(str(config_dir))
    assert_close_to(Camera.load_yaml(path), truth)
    # next time the same video is opened, the stored calibration is its camera
    src = VideoFileSource(video)
    assert not src.has_camera
    assert camera_store.attach_camera(src) == camera_store.STORED
    assert np.allclose(src.camera.K, cam.K)
    src.close()


def test_wizard_cancel_drops_the_running_solve(qtbot, charuco_recording, config_dir):
    from arapp.app.calibration_session import CalibrationSession, collect_from_source
    from arapp.gui.first_hour.calibration_wizard import CalibrationWizard

    session = CalibrationSession()
    with RecordingSource(charuco_recording[0]) as src:
        collect_from_source(src, session)
    wiz = CalibrationWizard(lambda: RecordingSource(charuco_recording[0]), session=session)
    qtbot.addWidget(wiz)
    wiz.solve()
    wiz.cancel_solve()
    assert wiz.pages.currentIndex() == 1
    qtbot.waitUntil(lambda: not wiz.solving, timeout=30000)
    qtbot.wait(50)  # let the dropped result arrive
    assert wiz.result is None and not wiz.save_button.isEnabled()


def test_wizard_says_why_a_camera_cannot_be_opened(qtbot, config_dir):
    from tracking.sources import open_source

    from arapp.gui.first_hour.calibration_wizard import CalibrationWizard

    wiz = CalibrationWizard(lambda: open_source("v4l2:/dev/video99"))
    qtbot.addWidget(wiz)
    wiz.start()
    qtbot.waitUntil(lambda: not wiz.collecting and wiz.start_button.isEnabled(), timeout=10000)
    assert len(wiz.errors) == 1 and "no camera at /dev/video99" in wiz.errors[0]
    assert "\n" not in wiz.errors[0]
