"""Start the desktop app: QApplication, main window, optional source and model, and the screenshot mode."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from arapp.engine.toolpaths import preview_spec
from arapp.gui.main_window import MainWindow
from arapp.gui.hosts.remote import warm_up


def ensure_platform() -> None:
    """Headless machines: fall back to Qt's offscreen platform when there is no display at all."""
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def get_app():
    app = QApplication.instance()
    if app is None:
        app = QApplication(sys.argv[:1])
        app.setOrganizationName("arapp")
        app.setApplicationName("arapp")
    return app


class ScreenshotRun:
    """Watches painted frames; once frame `frames - 1` of the stream is on screen (or the recording ended, or
    `timeout_s` passed) grabs the whole window to `path` and quits the event loop. `exit_code` 0: success."""

    def __init__(self, window, frames: int, path: str | None, timeout_s: float = 120.0):
        self.window, self.frames, self.path = window, frames, path
        self.exit_code = None
        self.message = ""
        self.errors: list[str] = []
        self._ended_seen = False
        window.error_sink = self._error
        window.frame_painted.connect(self._painted)
        if window.engine is not None:
            window.engine.ended.connect(self._ended)
        self._timer = QTimer(window)
        self._timer.setSingleShot(True)
        self._timer.timeout.connect(lambda: self._finish(1, f"timed out after {timeout_s:g} s"))
        self._timer.start(int(timeout_s * 1000))

    def _error(self, title: str, message: str) -> None:
        self.errors.append(f"{title}: {message}")
        print(f"arapp gui: {title}: {message}", file=sys.stderr)
        if self.window.frames_painted == 0 or title == "Cannot show the print preview":
            self._finish(2, f"{title}: {message}")  # nothing to show: the picture would only be the error

    def _toolpaths_drawn(self) -> bool:
        """With a print preview requested, the frame on screen shows it (it is built in the background)."""
        w = self.window
        if w.toolpaths_spec is None:
            return True
        shown = w.last_shown
        info = None if shown is None else getattr(shown.result, "extra", {}).get("toolpaths")
        return info is not None and info.get("gen") == w.toolpaths_gen

    def _painted(self, _index: int) -> None:
        if not self._toolpaths_drawn():
            return
        if self.exit_code is None and self._ended_seen:
            self._ended()
            return
        # N frames of the stream have gone by once frame N-1 is on screen (frames the pipeline
        # was too slow for were dropped on the way, as in normal viewing)
        if self.exit_code is None and _index >= self.frames - 1:
            self.window.session.pause()
            # one more turn of the event loop so panels show this frame's numbers
            QTimer.singleShot(300, lambda: self._finish(
                0, f"{self.frames} frames played, {self.window.frames_painted} painted"))
            self.exit_code = -1

    def _ended(self) -> None:
        # The reader can reach the end before the (slower) pipeline shows anything: wait for a painted frame.
        self._ended_seen = True
        if self.window.frames_painted == 0:
            return
        if self.exit_code is None:
            QTimer.singleShot(300, lambda: self._finish(
                0, f"the recording ended after {self.window.frames_painted} frames"))
            self.exit_code = -1

    def _finish(self, code: int, message: str) -> None:
        if self.exit_code not in (None, -1):
            return
        self.window._refresh_status()
        self.exit_code = code
        self.message = message
        if self.path and self.window.frames_painted > 0:
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            if not self.window.grab().save(str(self.path)):
                self.exit_code = 2
                self.message = f"cannot write the screenshot {self.path}"
        QApplication.instance().exit(self.exit_code)


def run_gui(source: str | None = None, model: str | None = None, frames: int | None = None,
            screenshot: str | None = None, settings=None, toolpaths: str | None = None, printer: str | None = None,
            layer: int | None = None, anchors: list | None = None, scene: str | None = None) -> int:
    """Open the window; with `frames`, run that many frames, save `screenshot` (when given) and return.

    toolpaths: a G-code file shown on the printer bed (the print preview), placed by the printer profile
    `printer` (its bed anchor is the source's first anchor); layer: show layers up to this one (0-based);
    anchors: session.json anchor blocks to track from now on (as Tracking > Anchors sets them); scene: a saved
    scene file (.arscene) to track against, its model shown where it was placed."""
    if frames is not None and not source:
        raise ValueError("--frames needs --source (a recording, a video or a camera)")
    ensure_platform()
    app = get_app()
    window = MainWindow(settings=settings)
    if window.engine_kind == "process" and not source:
        warm_up()
    window.show()
    if anchors is not None:
        window.session.set_anchors_json(anchors)
    if toolpaths:
        window.set_toolpaths(preview_spec(toolpaths, printer, layer))
    if scene:
        window.session.scenes.open(scene)
    if model:
        window.open_model(model)
    if source:
        window.open_source(source)
    else:
        last = window.session.recent("recent_sources")
        if frames is None and last and Path(last[0]).is_dir():
            window.statusBar().showMessage(f"Last source: {last[0]} (File > Recent sources)", 8000)
    if not scene and frames is None and window.session.scenes.last():
        # offered, not forced: a scene made on another desk would only confuse a new session
        window.statusBar().showMessage(f"Last scene: {Path(window.session.scenes.last()).name} "
                                       "(File > Reopen last scene)", 8000)
    if frames is None:
        code = app.exec()
        return int(code)
    run = ScreenshotRun(window, frames, screenshot)
    app.exec()
    window.close()
    if run.message and run.message not in run.errors:
        print(f"arapp gui: {run.message}" + (f"; screenshot {screenshot}" if screenshot and run.exit_code == 0 else ""))
    if run.exit_code in (None, -1):
        return 1
    return run.exit_code or (1 if run.errors else 0)
