"""The first run: a camera without a calibration file, what the app looks for when lost, the welcome view.

Oracles: cv2.projectPoints with a K written here from the field of view, the
pixel-edge rule for the field of view, cv2.projectPoints for the marker's size
in pixels at the hinted distances.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tracking.recording.schema import parse_anchors


@pytest.fixture()
def plain_video(tmp_path):
    """A short video file with no calibration next to it (as a user's phone clip)."""
    path = tmp_path / "clip.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    rng = np.random.default_rng(0)
    for _ in range(5):
        w.write(rng.integers(0, 255, (240, 320, 3), dtype=np.uint8))
    w.release()
    return path


# -- the estimated camera -------------------------------------------------------------------------

@pytest.mark.parametrize("size,hfov", [((640, 480), 65.0), ((1280, 720), 70.0), ((1920, 1080), 60.0)])
def test_estimated_camera_projects_like_opencv(size, hfov):
    from tracking.default_intrinsics import estimated_camera

    w, h = size
    f = w / 2 / math.tan(math.radians(hfov) / 2)
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-0.3, 0.3, (50, 2)), rng.uniform(0.3, 2.0, 50)]
    want, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.zeros(5))
    cam = estimated_camera(w, h, hfov)
    assert np.allclose(cam.project(pts), want.reshape(-1, 2), atol=1e-9)
    # the field of view: a ray at hfov/2 left of the axis meets the image's left edge (pixel 0's outer border)
    ray = np.array([[-math.tan(math.radians(hfov) / 2), 0.0, 1.0]])
    assert abs(cam.project(ray)[0, 0] - (-0.5)) < 1e-9
    assert not cam.has_distortion


def test_default_field_of_view_is_a_webcams():
    from tracking.default_intrinsics import DEFAULT_HFOV_DEG, estimated_camera, is_estimated

    assert 60 <= DEFAULT_HFOV_DEG <= 70
    cam = estimated_camera(640, 480)
    assert is_estimated(cam)
    cam.K[0, 0] += 1.0
    assert not is_estimated(cam)


def test_estimated_camera_refuses_nonsense_in_one_line():
    from tracking.default_intrinsics import estimated_camera
    from tracking.errors import CalibrationError

    with pytest.raises(CalibrationError, match="between 1 and 170"):
        estimated_camera(640, 480, 180)
    with pytest.raises(CalibrationError, match="positive integer image size"):
        estimated_camera(0, 480)


def test_video_without_calibration_gets_the_estimated_camera(plain_video, config_dir):
    from tracking.default_intrinsics import estimated_camera
    from tracking.sources import open_source

    from arapp.store import camera_store

    src = open_source(str(plain_video))
    assert not src.has_camera
    assert camera_store.attach_camera(src) == camera_store.ESTIMATED
    assert np.allclose(src.camera.K, estimated_camera(320, 240).K)
    assert camera_store.calibration_kind(src.camera) == camera_store.ESTIMATED
    assert src.info["calibration"].startswith("estimated")  # what a recording made from it will say
    src.close()


def test_a_stored_calibration_wins_over_the_estimate_and_scales(plain_video, config_dir):
    from tracking.camera import Camera
    from tracking.sources import open_source

    from arapp.store import camera_store

    stored = Camera([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]], [-0.1, 0.01, 0, 0, 0], 640, 480)
    path = camera_store.save_camera("video:clip.avi", stored, rms_px=0.3)
    assert path.parent == config_dir / "cameras" and path.name == "video_clip.avi_640x480.yaml"
    src = open_source(str(plain_video))
    assert camera_store.attach_camera(src) == camera_store.STORED
    assert src.calibration_file == path
    assert np.allclose(src.camera.K, stored.scaled(320, 240).K)
    assert camera_store.calibration_kind(src.camera) == camera_store.OWN
    src.close()


def test_a_source_with_its_own_calibration_is_left_alone(repo_root, config_dir):
    from tracking.sources import open_source

    from arapp.store import camera_store

    src = open_source(str(repo_root / "recordings" / "board_orbit"))
    K = src.camera.K.copy()
    assert camera_store.attach_camera(src) == camera_store.OWN
    assert np.array_equal(src.camera.K, K)
    src.close()


def test_the_gui_opens_a_plain_video_without_a_calibration_file(plain_video, config_dir):
    """`arapp gui --source v4l2:0` failed with 'pass --calibration cam.yaml'; a plain video did too."""
    try:
        from arapp.engine import sourcespec  # after the app-model refactor
    except ImportError:
        from arapp.gui import sourcespec

    src = sourcespec.open_spec(f"file:{plain_video}")
    assert src.camera.width == 320  # old code: SourceError "... has no calibration; pass --calibration ..."
    src.close()


# -- what the app looks for ----------------------------------------------------------------------

def test_looking_for_names_the_marker_as_printed():
    from arapp.app.guidance import looking_for

    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 40, "length": 0.05}])
    assert looking_for(anchors) == "Looking for ArUco id 40, DICT_4X4_50, 50 mm"
    board = parse_anchors([{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                            "marker_length": 0.04, "separation": 0.01, "first_id": 0},
                           {"kind": "qr", "text": "arapp anchor 1", "length": 0.08,
                            "world_from_anchor": np.eye(4).tolist()}])
    assert looking_for(board) == ("Looking for ArUco board 4 x 3, DICT_4X4_50, ids 0-11, 40 mm markers or "
                                  'QR code "arapp anchor 1", 80 mm')


def test_lost_hint_distances_hold_against_projectpoints():
    from tracking.default_intrinsics import estimated_camera

    from arapp.app.guidance import MIN_MARKER_PX, distance_range_m, lost_hint

    spec = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 40, "length": 0.05}])[0]
    cam = estimated_camera(640, 480)
    near, far = distance_range_m(spec, cam)
    square = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float) * 0.025

    def side_px(d):
        px, _ = cv2.projectPoints(square + [0, 0, d], np.zeros(3), np.zeros(3), cam.K, cam.dist)
        return np.linalg.norm(px[1, 0] - px[0, 0])

    assert abs(side_px(far) - MIN_MARKER_PX) < 0.01       # at the far end the side spans MIN_MARKER_PX
    assert abs(side_px(near) - 0.8 * 480) < 0.01          # at the near end it fills 80 % of the height
    text = lost_hint([spec], cam, estimated=True)
    assert text.startswith("Looking for ArUco id 40, DICT_4X4_50, 50 mm.\n")
    assert f"{round(near * 100)} cm to {far:.1f} m from the camera" in text
    assert "uncalibrated" in text


# -- the welcome view ------------------------------------------------------------------------------

def test_welcome_view_offers_the_first_steps(qtbot, repo_root):
    from arapp.gui.first_hour.welcome import WelcomeView, bundled_recordings

    recs = bundled_recordings()
    names = [p.split("/")[-1] for p, _ in recs]
    assert "board_orbit" in names and "printer_bed" in names
    # the tracker's tuning and test recordings are data, not examples: a first-time user saw eleven of
    # them (tune_fast_pan_c, ...) listed without a word on what they show
    assert not any(n.startswith(("tune_", "test_")) for n in names)
    assert all(": " in line for _, line in recs)   # each says what it shows
    view = WelcomeView()
    qtbot.addWidget(view)
    for button, signal in ((view.camera_button, view.open_camera_requested),
                           (view.sheet_button, view.print_sheet_requested),
                           (view.calibrate_button, view.calibrate_requested),
                           (view.model_button, view.open_model_requested)):
        with qtbot.waitSignal(signal, timeout=1000):
            button.click()
    item = view.recordings.item(names.index("board_orbit"))
    with qtbot.waitSignal(view.recording_chosen, timeout=1000) as sig:
        view.recordings.itemDoubleClicked.emit(item)
    assert sig.args == [str(repo_root / "recordings" / "board_orbit")]


def test_lost_hint_shows_after_a_second_of_lost_tracking(qtbot):
    from arapp.gui.first_hour.welcome import LostHint

    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 40, "length": 0.05}])
    hint = LostHint(delay_s=1.0)
    qtbot.addWidget(hint)
    hint.update_state("lost", anchors, now=10.0)
    assert hint.isHidden()
    hint.update_state("lost", anchors, now=11.2)
    assert not hint.isHidden() and "ArUco id 40" in hint.text()
    hint.update_state("marker", anchors, now=11.3)
    assert hint.isHidden()


# -- help -------------------------------------------------------------------------------------------

def test_help_lists_the_windows_shortcuts_and_about(qtbot, config_dir):
    from PySide6.QtGui import QAction, QKeySequence
    from PySide6.QtWidgets import QMainWindow

    from arapp.gui.first_hour.help import ShortcutsDialog, about_text, add_help_menu, shortcuts

    win = QMainWindow()
    qtbot.addWidget(win)
    for text, key in (("Play / pause", "Space"), ("Reset tracking", "R"), ("Open source...", "Ctrl+O")):
        a = QAction(text, win)
        a.setShortcut(QKeySequence(key))
        win.addAction(a)
    menu = add_help_menu(win)
    rows = shortcuts(win)
    keys = dict(rows)
    assert keys["Space"] == "Play / pause" and keys["R"] == "Reset tracking" and keys["Ctrl+O"] == "Open source"
    assert keys["F1"] == "Keyboard shortcuts"
    assert any(k == "Mouse wheel" for k, _ in rows)
    dlg = ShortcutsDialog(rows)
    qtbot.addWidget(dlg)
    assert dlg.table.rowCount() == len(rows) and dlg.table.item(0, 1).text() == rows[0][1]
    assert [a.text() for a in menu.actions()] == ["Keyboard shortcuts", "About arapp"]
    text = about_text()
    assert "arapp 0." in text and "OpenCV" in text and str(config_dir) in text


def test_first_hour_dialogs_fit_a_1366x768_screen(qtbot, config_dir):
    """Each of these windows can be made small enough for a 768 px screen (less a panel and title bar)."""
    from arapp.gui.first_hour.calibration_wizard import CalibrationWizard
    from arapp.gui.first_hour.help import ShortcutsDialog
    from arapp.gui.print.printer_setup import PrinterSetupDialog
    from arapp.gui.first_hour.welcome import WelcomeView

    for w in (CalibrationWizard(lambda: None), PrinterSetupDialog(ports=[]), WelcomeView(),
              ShortcutsDialog([("F1", "Keyboard shortcuts")] * 30)):
        qtbot.addWidget(w)
        hint = w.minimumSizeHint()
        assert hint.width() <= 1280 and hint.height() <= 660, (type(w).__name__, hint)


def test_calibration_banner_shows_only_for_the_estimated_camera(qtbot):
    from tracking.camera import Camera
    from tracking.default_intrinsics import estimated_camera

    from arapp.gui.first_hour.welcome import CalibrationBanner

    banner = CalibrationBanner()
    qtbot.addWidget(banner)
    banner.set_camera(estimated_camera(1280, 720))
    assert not banner.isHidden() and "approximate" in banner.label.text()
    with qtbot.waitSignal(banner.calibrate_requested, timeout=1000):
        banner.button.click()
    banner.set_camera(Camera([[900.0, 0, 640], [0, 900.0, 360], [0, 0, 1]], None, 1280, 720))
    assert banner.isHidden()
    banner.set_camera(None)
    assert banner.isHidden()


def test_a_portrait_frame_is_the_same_sensor_turned():
    # a phone video held upright (OpenCV turns it by the file's rotation tag): the 65 degrees span its height,
    # so its focal length is the landscape frame's; a ray at half that angle above the axis meets the top edge
    from tracking.default_intrinsics import DEFAULT_HFOV_DEG, estimated_camera

    portrait, landscape = estimated_camera(1080, 1920), estimated_camera(1920, 1080)
    assert portrait.fx == portrait.fy == landscape.fx == pytest.approx(960 / math.tan(math.radians(32.5)))
    ray = np.array([[0.0, -math.tan(math.radians(DEFAULT_HFOV_DEG) / 2), 1.0]])
    assert abs(portrait.project(ray)[0, 1] - (-0.5)) < 1e-9


def test_no_display_is_said_in_one_line_before_any_window(monkeypatch, capsys):
    # `arapp` over ssh without X: a window on Qt's offscreen platform would run unseen until killed
    import sys

    from arapp.cli import main

    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    shown = []
    monkeypatch.setattr("arapp.gui.app.run_gui", lambda **kw: shown.append(kw) or 0)
    assert main(["gui"]) == 2 and not shown
    err = capsys.readouterr().err.strip()
    assert err.startswith("arapp gui: error: no display to show the window on") and "\n" not in err
    assert main(["gui", "--frames", "1"]) == 0 and len(shown) == 1   # headless pictures still run
    monkeypatch.setenv("QT_QPA_PLATFORM", "vnc")   # a platform chosen on purpose is taken
    assert main(["gui"]) == 0 and len(shown) == 2
