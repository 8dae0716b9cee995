"""The first-hour pieces put into the main window: the welcome view, the calibration banner, the
lost-marker hint, the calibration wizard, the printer set-up and the Help menu.

`install(window)` is the one call the main window makes; everything here
talks to the window through its app model (`window.session`: its events
source_opening / source_opened / frame, `source_spec`, `source_info`,
`close_source`, `model`) and a few window methods (open_source, choose_source,
choose_model, open_model, save_marker_sheets, show_error).
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QGuiApplication
from PySide6.QtWidgets import QDockWidget, QMenu

from tracking.default_intrinsics import is_estimated

from arapp.engine import sourcespec
from arapp.gui.first_hour.calibration_wizard import CalibrationWizard
from arapp.gui.first_hour.help import add_help_menu
from arapp.gui.print.printer_setup import PrinterSetupDialog
from arapp.gui.panels.side import scroll_side_panels
from arapp.gui.first_hour.welcome import CalibrationBanner, LostHint, WelcomeView

DEMO_MODEL = Path(__file__).resolve().parents[3] / "models" / "vase.json"


def fit_to_screen(window) -> None:
    """Side panels scroll instead of setting the window's minimum height, and the window is no larger than
    the screen's available area (a 1366x768 laptop screen showed neither the replay bar nor the status bar)."""
    scroll_side_panels(window)  # as wide as each panel needs (its fields unclipped), only its height scrolls
    screen = window.screen()
    # Qt's offscreen platform has no real screen (800x600 by default): keep the designed size there, so
    # pictures made headless (--screenshot) look as on a desktop
    if screen is not None and QGuiApplication.platformName() != "offscreen":
        avail = screen.availableGeometry()
        w, h = min(window.width(), avail.width()), min(window.height(), avail.height() - 40)  # 40: title bar
        window.resize(w, h)
    docks = [d for d in window.findChildren(QDockWidget) if d.isVisible() or not d.isHidden()]
    if len(docks) == 2:  # the Model panel has more to show than the Tracking panel
        window.resizeDocks(docks, [2 * window.height() // 3, window.height() // 3], Qt.Orientation.Vertical)


def calibratable(spec: str | None, info) -> bool:
    """Whether the open source can be calibrated: a camera or a plain video (not a recording, which
    carries its camera, nor an OAK device, calibrated at the factory)."""
    if not spec or info is None:
        return False
    base, _ = sourcespec.split_calibration(spec)
    return sourcespec.recording_folder(base) is None and not base.startswith("depthai")


class FirstHour:
    """Holds the pieces and their wiring for one main window (see the module doc)."""

    def __init__(self, window):
        self.w = window
        self.wizard: CalibrationWizard | None = None
        self.printer_dialog: PrinterSetupDialog | None = None
        layout = window.centralWidget().layout()
        self.welcome = WelcomeView()
        self.banner = CalibrationBanner()
        layout.insertWidget(0, self.welcome, 1)
        layout.insertWidget(1, self.banner)
        self.hint = LostHint(parent=window.view)
        window.view.resized.connect(lambda *_: self._place_hint())
        self._place_hint()
        self.show_welcome(True)
        fit_to_screen(window)

        ev = window.session.events
        ev.source_opening.connect(lambda _name: self.show_welcome(False))
        ev.source_opened.connect(self._opened)
        ev.frame.connect(self._frame)
        self.welcome.recording_chosen.connect(self.open_recording)
        self.welcome.open_camera_requested.connect(window.choose_source)
        self.welcome.print_sheet_requested.connect(window.save_marker_sheets)
        self.welcome.calibrate_requested.connect(self.calibrate)
        self.welcome.open_model_requested.connect(window.choose_model)
        self.banner.calibrate_requested.connect(self.calibrate)
        self._add_menu_entries()

    # -- menus ------------------------------------------------------------------------------------
    def _menu(self, title: str) -> QMenu | None:
        for action in self.w.menuBar().actions():
            if action.text().replace("&", "") == title and action.menu() is not None:
                return action.menu()
        return None

    def _add_menu_entries(self) -> None:
        track = self._menu("Tracking")
        if track is not None:
            track.addAction("Calibrate camera...", self.calibrate)
        file_menu = self._menu("File")
        if file_menu is not None:
            setup = self._action("Printer set-up...", self.printer_setup)
            quit_action = next((a for a in file_menu.actions() if a.text().replace("&", "") == "Quit"), None)
            if quit_action is None:
                file_menu.addAction(setup)
            else:
                file_menu.insertAction(quit_action, setup)
                file_menu.insertSeparator(quit_action)
        add_help_menu(self.w, extra=[("Getting started", lambda: self.show_welcome(True))])

    def _action(self, text, slot):
        a = QAction(text, self.w)
        a.triggered.connect(slot)
        return a

    # -- welcome, banner, hint ---------------------------------------------------------------------
    def show_welcome(self, on: bool) -> None:
        self.welcome.setVisible(on)
        self.w.view.setVisible(not on)
        self.w.replay.setVisible(not on)
        if on:
            self.banner.hide()
            self.hint.hide()

    def open_recording(self, folder: str) -> None:
        """A bundled recording, with the demo model when none is loaded: a model on a marker at once."""
        self.w.open_source(folder)
        if self.w.session.model is None and DEMO_MODEL.is_file():
            self.w.open_model(str(DEMO_MODEL))

    def _opened(self, info) -> None:
        self.show_welcome(False)
        self.banner.set_camera(info.camera)

    def _frame(self, shown) -> None:
        info = self.w.session.source_info
        if info is None:
            return
        self.hint.update_state(shown.result.state, info.anchors, info.camera, is_estimated(info.camera),
                               ambiguous=bool((getattr(shown.result, "extra", None) or {}).get("ambiguous")))
        if not self.hint.isHidden():
            self._place_hint()

    def _place_hint(self) -> None:
        v = self.w.view
        self.hint.setFixedWidth(max(200, min(v.width() - 24, 720)))
        self.hint.adjustSize()
        self.hint.move(12, 12)

    # -- calibration ------------------------------------------------------------------------------
    def calibrate(self) -> None:
        """The wizard on the open camera or video (the camera is released meanwhile and reopened after, with
        the new calibration); with none open, on the first attached camera."""
        s = self.w.session
        spec = s.source_spec if calibratable(s.source_spec, s.source_info) else None
        if spec is None:
            devices = [d for d, _ in sourcespec.list_devices() if d.startswith("v4l2")]
            if not devices:
                self.w.show_error("No camera to calibrate", "connect a webcam, or open a video of the "
                                  "calibration board first (File > Open source)")
                return
            spec = devices[0]
        base, _ = sourcespec.split_calibration(spec)
        was_open = s.source_spec == spec
        if was_open:
            s.close_source()  # a camera can be opened by one reader at a time
        wizard = CalibrationWizard(lambda: sourcespec.open_spec(base), parent=self.w)
        wizard.calibrated.connect(lambda _path, _cam: self.w.statusBar().showMessage(
            f"Calibration saved: {_path}", 10000))
        wizard.finished.connect(lambda _r: self.w.open_source(base) if was_open or wizard.saved_path else None)
        self.wizard = wizard
        wizard.open()

    # -- printer -----------------------------------------------------------------------------------
    def printer_setup(self) -> None:
        dlg = PrinterSetupDialog(self.w)
        dlg.saved.connect(lambda c: self.w.statusBar().showMessage(f"Printer set-up saved ({c['profile']})", 5000))
        self.printer_dialog = dlg
        dlg.open()


def install(window) -> FirstHour:
    """Put the first-hour pieces into `window` (a MainWindow); returns them (the window keeps them as
    `first_hour`)."""
    return FirstHour(window)
