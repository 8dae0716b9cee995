"""What users of desktop apps expect, bound to the app model: Undo/Redo, Export model, Save screenshot, Record
AR video, a window title naming the source, model and print, and controls enabled only when they can act.

`install_habits(window)` adds the actions to the main window's menus and
connects them to its `Session`; the decisions (title, what can act) are made
by `arapp.app.window_state` without Qt.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtGui import QKeySequence
from PySide6.QtWidgets import QFileDialog, QPushButton

from arapp.engine.capture import new_capture_path
from arapp.app.model_export import export_filter, export_suffixes
from arapp.app.window_state import control_state, window_title
from arapp.gui.menus import _action


def _menu(window, title: str):
    """The window's menu titled `title` (ampersands ignored), made when missing."""
    for a in window.menuBar().actions():
        if a.menu() is not None and a.text().replace("&", "") == title.replace("&", ""):
            return a.menu()
    return window.menuBar().addMenu(title)


class Habits:
    """The actions and bindings; `window.habits` after install_habits. `ask_path(title, default, filter)`
    chooses a file to write (a dialog; tests replace it)."""

    def __init__(self, window):
        self.w = window
        self.session = s = window.session
        self.ask_path = self._ask_path
        file_menu = _menu(window, "&File")
        edit_menu = _menu(window, "&Edit")
        self.undo_action = _action(window, "Undo", s.history.undo, QKeySequence.StandardKey.Undo, edit_menu)
        self.redo_action = _action(window, "Redo", s.history.redo, "Ctrl+Shift+Z", edit_menu)
        self.export_action = _action(window, "Export model...", self.export_model, "Ctrl+E")
        self.screenshot_action = _action(window, "Save screenshot", self.save_screenshot, "Ctrl+S")
        self.record_ar_action = _action(window, "Record AR video", self.toggle_ar_recording, "Ctrl+Shift+R")
        self.record_ar_action.setCheckable(True)
        # beside Record (the raw camera) in the replay bar: what is on screen, for any source
        self.record_ar_button = QPushButton("Record AR video")
        self.record_ar_button.setToolTip("Record the view as shown, the model drawn over the camera (Ctrl+Shift+R)")
        self.record_ar_button.setCheckable(True)
        self.record_ar_button.clicked.connect(lambda _c=False: self.record_ar_action.trigger())
        window.replay.layout().addWidget(self.record_ar_button)
        # after "Open model..." and before the recent menus: saving sits with opening
        anchor = next((a for a in file_menu.actions() if a.menu() is not None), None)
        for a in (self.export_action, self.screenshot_action, self.record_ar_action):
            file_menu.insertAction(anchor, a) if anchor is not None else file_menu.addAction(a)
        if anchor is not None:
            file_menu.insertSeparator(anchor)
        self._state: dict | None = None
        ev = s.events
        for name in ("source_opening", "source_opened", "source_failed", "model_loaded", "model_edited",
                     "placement_changed", "playing_changed", "print_session", "ar_recording_changed", "recorded"):
            getattr(ev, name).connect(lambda *_a: self.refresh())
        ev.frame.connect(self._frame)
        ev.source_failed.connect(self._source_failed)
        s.history.events.changed.connect(self.refresh)
        timer = getattr(window, "_status_timer", None)
        if timer is not None:
            timer.timeout.connect(lambda: window.setWindowTitle(window_title(s)))  # the print's progress
        self.refresh()

    # -- state ----------------------------------------------------------------------------
    def _frame(self, _shown) -> None:
        if self._state is None or not self._state["screenshot"]:
            self.refresh()  # the first frame makes the screenshot possible

    def refresh(self) -> None:
        """The title and every control's enabled state from the session."""
        w, s = self.w, self.session
        w.setWindowTitle(window_title(s))
        recording = s.ar_video_path is not None
        self.record_ar_action.setChecked(recording)
        self.record_ar_button.setChecked(recording)
        self.record_ar_button.setText("Stop AR video" if recording else "Record AR video")
        st = control_state(s)
        if st == self._state:
            return
        self._state = st
        r = w.replay
        r.play_button.setEnabled(st["play"])
        w.play_action.setEnabled(st["play"])
        if not st["play"]:
            for x in (r.step_button, r.slider, r.record_button):
                x.setEnabled(False)
        elif hasattr(r, "record_button"):
            r.record_button.setEnabled(st["record"])
        w.reset_action.setEnabled(st["reset"])
        w.tracking_panel.reset_button.setEnabled(st["reset"])
        w.print_action.setEnabled(st["print"])
        w.model_panel.set_model_loaded(st["placement"])
        self.export_action.setEnabled(st["export"])
        self.screenshot_action.setEnabled(st["screenshot"])
        self.record_ar_action.setEnabled(st["record_ar"])
        self.record_ar_button.setEnabled(st["record_ar"])
        self.undo_action.setEnabled(st["undo"])
        self.redo_action.setEnabled(st["redo"])

    def _source_failed(self, name: str, line: str = "") -> None:
        """Back to 'no source': no 'Opening...' left on the view, Play not 'Pause'; the view says `line`
        (what failed and what to do) when the session gave one."""
        w = self.w
        w.status_source.setText("no source")
        w.view.message = line or (f"Could not open {name}; see the message. " if name else "") + \
            "Open a recording or a camera (File menu), or drop a recording folder here"
        w.view.set_image(None)
        w.replay.set_playing(False)
        w.view.update()

    # -- actions --------------------------------------------------------------------------
    def _ask_path(self, title: str, default: Path, file_filter: str) -> str:
        path, _ = QFileDialog.getSaveFileName(self.w, title, str(default), file_filter)
        return path

    def export_model(self) -> None:
        s = self.session
        if s.model is None:
            return
        stem = Path(s.model_path).stem if s.model_path else "model"
        path = self.ask_path("Export the model as placed", Path.cwd() / f"{stem}-edited.stl", export_filter())
        if not path:
            return
        if Path(path).suffix.lower() not in export_suffixes():
            path += ".stl"  # a name typed without a suffix: STL, what slicers and printers take
        s.export_model(path)

    def save_screenshot(self) -> None:
        s = self.session
        if s.last_shown is None:
            return
        path = self.ask_path("Save a screenshot of the view", new_capture_path("screenshot", ".png").resolve(),
                             "PNG image (*.png);;JPEG image (*.jpg)")
        if path:
            s.save_screenshot(path if Path(path).suffix else path + ".png")

    def toggle_ar_recording(self) -> None:
        s = self.session
        if s.ar_video_path is not None:
            s.stop_ar_recording()
            return
        path = self.ask_path("Record the AR view to", new_capture_path("ar", ".mp4").resolve(),
                             "MP4 video (*.mp4);;AVI video (*.avi)")
        if path:
            s.start_ar_recording(path if Path(path).suffix else path + ".mp4")
        self.refresh()


def install_habits(window) -> Habits:
    return Habits(window)
