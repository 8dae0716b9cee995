"""The first-hour pieces in the main window (pytest-qt, offscreen): the welcome view until a source opens,
a plain video without calibration opening with the estimated camera and its banner, the lost-marker hint,
the Help menu, the calibration wizard on the open video, the printer set-up from the File menu."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from gui_helpers import TIMEOUT_MS



@pytest.fixture()
def window(threads_window):
    return threads_window


@pytest.fixture()
def blank_video(tmp_path):
    """3 s of a grey desk with no marker on it, no calibration file."""
    path = tmp_path / "desk.avi"
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    rng = np.random.default_rng(0)
    base = rng.integers(90, 160, (240, 320, 3), dtype=np.uint8)
    for _ in range(30):
        wr.write(base)
    wr.release()
    return path


def test_welcome_until_a_source_opens_then_the_estimated_camera_and_its_banner(qtbot, window, blank_video):
    fh = window.first_hour
    assert fh.welcome.isVisible() and not window.view.isVisible()
    window.open_source(f"file:{blank_video}")
    qtbot.waitUntil(lambda: window.session.source_info is not None, timeout=TIMEOUT_MS)
    assert not window.errors if hasattr(window, "errors") else True
    assert not fh.welcome.isVisible() and window.view.isVisible()
    assert fh.banner.isVisible() and "approximate" in fh.banner.label.text()
    assert window.session.source_info.camera.width == 320
    # nothing to track on a bare desk: after a second the hint says what is looked for
    qtbot.waitUntil(lambda: fh.hint.isVisible(), timeout=TIMEOUT_MS)
    assert fh.hint.text().startswith("Looking for ")
    assert "uncalibrated" in fh.hint.text()


def test_a_bundled_recording_from_the_welcome_view_shows_the_demo_model(qtbot, window, repo_root):
    fh = window.first_hour
    fh.welcome.recording_chosen.emit(str(repo_root / "recordings" / "board_orbit"))
    qtbot.waitUntil(lambda: window.session.model is not None and window.session.source_info is not None,
                    timeout=TIMEOUT_MS)
    assert window.session.model_path.endswith("vase.json")
    assert not fh.banner.isVisible()  # a recording carries its calibration


def test_help_menu_and_setup_entries(window):
    titles = {a.text().replace("&", ""): a.menu() for a in window.menuBar().actions() if a.menu()}
    assert [a.text() for a in titles["Help"].actions() if a.text()] == ["Getting started", "Keyboard shortcuts",
                                                                       "About arapp"]
    assert "Calibrate camera..." in [a.text() for a in titles["Tracking"].actions()]
    assert "Printer set-up..." in [a.text() for a in titles["File"].actions()]
    assert [a.text() for a in titles["File"].actions() if a.text()][-1] == "Quit"


def test_calibrate_opens_the_wizard_on_the_open_video_and_reopens_it(qtbot, window, blank_video):
    fh = window.first_hour
    spec = f"file:{blank_video}"
    window.open_source(spec)
    qtbot.waitUntil(lambda: window.session.source_info is not None, timeout=TIMEOUT_MS)
    fh.calibrate()
    wiz = fh.wizard
    assert wiz is not None and wiz.isVisible()
    wiz.start()
    qtbot.waitUntil(lambda: not wiz.collecting and wiz.start_button.isEnabled(), timeout=TIMEOUT_MS)
    assert wiz.camera_name == "video:desk.avi" and wiz.session.kept == 0 and not wiz.errors
    wiz.reject()
    qtbot.waitUntil(lambda: window.session.source_spec == spec and window.session.source_info is not None,
                    timeout=TIMEOUT_MS)


def test_calibrate_with_nothing_to_calibrate_says_so(window, monkeypatch):
    import arapp.engine.sourcespec as ss

    monkeypatch.setattr(ss, "list_devices", lambda: [])
    shown = []
    monkeypatch.setattr(window, "show_error", lambda t, m: shown.append((t, m)))
    window.first_hour.calibrate()
    assert shown and shown[0][0] == "No camera to calibrate"


def test_printer_setup_from_the_file_menu(qtbot, window):
    titles = {a.text().replace("&", ""): a.menu() for a in window.menuBar().actions() if a.menu()}
    entry = next(a for a in titles["File"].actions() if a.text() == "Printer set-up...")
    entry.trigger()
    dlg = window.first_hour.printer_dialog
    assert dlg is not None and dlg.isVisible() and dlg.port.currentData() == ""
    dlg.reject()


PROBE = r"""
import json, sys
from PySide6.QtCore import QEventLoop, QSettings, QTimer
from PySide6.QtWidgets import QApplication
app = QApplication(sys.argv[:1])
from arapp.gui.main_window import MainWindow
w = MainWindow(settings=QSettings(sys.argv[1], QSettings.Format.IniFormat))
w.show()
loop = QEventLoop(); QTimer.singleShot(1500, loop.quit); loop.exec()
def rect(widget):
    p = widget.mapToGlobal(widget.rect().topLeft())
    return [p.x(), p.y(), widget.width(), widget.height()]
screen = w.screen().geometry()
print(json.dumps({"screen": [screen.width(), screen.height()], "window": rect(w),
                  "status": rect(w.statusBar()), "replay": rect(w.replay) if w.replay.isVisible() else None,
                  "welcome": rect(w.first_hour.welcome)}))
w.close()
"""


@pytest.mark.skipif(__import__("shutil").which("xvfb-run") is None, reason="needs xvfb-run (make test installs it)")
@pytest.mark.parametrize("size", [(1366, 768), (1280, 720)])
def test_the_window_fits_a_laptop_screen_under_xvfb(tmp_path, size, config_dir):
    """Old code: the window could not be shorter than 1030 px (side panels did not scroll)."""
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "QT_QPA_PLATFORM": "xcb", "ARAPP_GUI_ENGINE": "threads"}
    out = subprocess.run(["xvfb-run", "-a", "-s", f"-screen 0 {size[0]}x{size[1]}x24", sys.executable, "-c", PROBE,
                          str(tmp_path / "s.ini")], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    geo = json.loads(out.stdout.strip().splitlines()[-1])
    assert geo["screen"] == list(size)
    x, y, w, h = geo["window"]
    assert w <= size[0] and y + h <= size[1], geo
    sx, sy, sw, sh = geo["status"]
    assert sy + sh <= size[1] and sx + sw <= size[0], geo  # the status bar is on the screen
