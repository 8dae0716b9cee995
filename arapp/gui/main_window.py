"""The main window: widgets bound to the app model (arapp.app.session.Session), nothing else.

The session holds the source, model, edits, placement, display mode, print
preview and print; the window turns user actions into session calls and the
session's events into widget updates. Everything slow happens elsewhere:
frames in the engine's threads or child process, loading and re-tessellation
in worker threads (arapp.gui.tasks.QtRunner). Slots here only move small
objects around and paint.
"""

from __future__ import annotations

import gc
import os
from pathlib import Path

from PySide6.QtCore import QSettings, Qt, QTimer, Signal
from PySide6.QtWidgets import QDockWidget, QFileDialog, QLabel, QMainWindow, QVBoxLayout, QWidget

from arapp.app import sheets
from arapp.engine.editing import library_thumbnails
from arapp.app.paint_stats import PaintStats
from arapp.app.session import Session, as_bool
from arapp.gui.panels.anchor_offer import install as install_anchor_offer
from arapp.gui.errors import ErrorBoxes
from arapp.gui.first_hour.pieces import install as install_first_hour
from arapp.gui.habits import install_habits
from arapp.gui.overlays.marker_marks import install_marks
from arapp.gui.overlays.orbit_view import install_orbit
from arapp.gui.menus import build_menus, update_recent_menus
from arapp.geometry.library import library_files
from arapp.gui.panels.model import MODEL_FILTER, ModelPanel
from arapp.gui.panels.replay import ReplayBar
from arapp.gui.panels.tracking import AnchorsDialog, TrackingPanel
from arapp.gui.print.dialog import PrintDialog
from arapp.gui.print.panel import show_print_panel
from arapp.gui.panels.scan import install_scan
from arapp.gui.source_dialog import SourceDialog, ask_recording, ask_video_spec
from arapp.gui.tasks import QtRunner, Task, init_ui_bridge, on_ui
from arapp.gui.view import VideoView
from arapp.gui.hosts.local import make_engine


def app_settings() -> QSettings:
    return QSettings("arapp", "arapp")


class MainWindow(QMainWindow):
    """The arapp desktop window over a `Session` (`self.session`). `frame_painted(index)` fires after each
    new frame reaches the screen; `errors` lists every (title, message) shown to the user."""

    frame_painted = Signal(int)
    model_ready = Signal(object)

    def __init__(self, settings: QSettings | None = None, parent=None):
        super().__init__(parent)
        init_ui_bridge()
        self.settings = settings or app_settings()
        self.setWindowTitle("arapp")
        self.resize(1400, 860)
        self.setAcceptDrops(True)
        self.session = Session(self._make_engine, self.settings, QtRunner(self))
        # where capture, tracking and rendering run: "process" (a child process, the default: the UI never
        # waits for the pipeline's interpreter lock) or "threads" (worker threads in this process)
        self.engine_kind = os.environ.get("ARAPP_GUI_ENGINE", "process")
        self.full_frames = False  # also hand over full-size composited and raw frames (for checks)
        self.error_sink = None  # callable(title, message) replacing dialogs (screenshot mode)
        self.error_boxes = ErrorBoxes(self)
        self._awaiting_paint = None
        self.stats = PaintStats()
        self._print_dialog = None
        self._build_widgets()
        build_menus(self)
        self._connect_widgets()
        self._bind_session()
        self._restore_settings()
        self._status_timer = QTimer(self)
        self._status_timer.setInterval(250)
        self._status_timer.timeout.connect(self._refresh_status)
        self._status_timer.timeout.connect(self.session.tick)  # the session's clock: a silent source is given up
        self._status_timer.start()
        self.habits = install_habits(self)  # undo/redo, export, screenshot, AR video, title, controls enabled when they can act
        self.first_hour = install_first_hour(self)  # welcome, calibration banner + wizard, lost hint, printer set-up, Help
        self.anchor_offer = install_anchor_offer(self)  # "Found a 4x3 ... board: use it?" when the anchors give no pose
        install_scan(self)  # scan mode: the Scan dock and the dome of view directions over the view
        install_marks(self)  # detected markers outlined with their axes (View menu toggle)
        self.orbit_view = install_orbit(self)  # the model in 3D when there is nothing to put it on
        QTimer.singleShot(0, self._start_thumbnails)
        QTimer.singleShot(0, self.freeze_heap)

    def _build_widgets(self) -> None:
        self.view = VideoView()
        self.replay = ReplayBar()
        central = QWidget()
        cl = QVBoxLayout(central)
        cl.setContentsMargins(0, 0, 0, 0)
        cl.setSpacing(0)
        cl.addWidget(self.view, 1)
        cl.addWidget(self.replay)
        self.setCentralWidget(central)
        self.model_panel = ModelPanel()
        self.tracking_panel = TrackingPanel()
        docks = []
        for title, w, name in (("Model", self.model_panel, "model"), ("Tracking", self.tracking_panel, "tracking")):
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock_{name}")
            dock.setWidget(w)
            dock.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable
                             | QDockWidget.DockWidgetFeature.DockWidgetFloatable)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
            docks.append(dock)
        self.resizeDocks(docks, [340, 340], Qt.Orientation.Horizontal)
        self.status_source = QLabel("no source")
        self.status_state, self.status_fps, self.status_latency = QLabel(""), QLabel(""), QLabel("")
        sb = self.statusBar()
        sb.addWidget(self.status_source, 1)
        for w in (self.status_state, self.status_fps, self.status_latency):
            sb.addPermanentWidget(w)

    def _connect_widgets(self) -> None:
        s, v, r, m, t = self.session, self.view, self.replay, self.model_panel, self.tracking_panel
        v.painted.connect(self._painted)
        v.resized.connect(s.set_display_size)
        v.drag_started.connect(s.drag_start)
        v.drag_moved.connect(s.drag_move)
        v.drag_ended.connect(s.drag_end)
        v.wheel_steps.connect(s.scale_by)
        r.play_toggled.connect(s.toggle_play)
        r.step_requested.connect(s.step)
        r.seek_requested.connect(s.seek)
        r.speed_changed.connect(s.set_speed)
        r.loop_changed.connect(s.set_loop)
        r.record_toggled.connect(self.toggle_recording)
        m.model_chosen.connect(s.open_model)
        m.open_requested.connect(self.choose_model)
        m.placement_changed.connect(s.set_placement)
        m.mode_changed.connect(s.set_mode)
        m.occlusion_changed.connect(s.set_occlusion)
        m.point_edited.connect(s.edit_control_point)
        m.point_selected.connect(s.select_point)
        m.print_requested.connect(self.open_print_dialog)
        t.reset_requested.connect(s.reset_tracking)
        t.edit_anchors_requested.connect(self.edit_anchors)
        t.marker_sheets_requested.connect(self.save_marker_sheets)

    def _bind_session(self) -> None:
        ev = self.session.events
        ev.error.connect(self._show_error)
        ev.status.connect(lambda text, ms: self.statusBar().showMessage(text, ms))
        ev.source_opening.connect(self._source_opening)
        ev.source_opened.connect(self._source_opened)
        ev.frame.connect(self._frame)
        ev.playing_changed.connect(self.replay.set_playing)
        ev.model_loaded.connect(self._model_loaded)
        ev.model_edited.connect(self._model_edited)
        ev.placement_changed.connect(self.model_panel.set_placement)
        ev.recent_changed.connect(lambda: update_recent_menus(self))

    def _restore_settings(self) -> None:
        self.model_panel.mode.setCurrentText(self.session.mode)
        self.model_panel.occlusion.setCurrentText(self.session.occlusion)
        self.model_panel.set_library(library_files())
        self.replay.loop.setChecked(as_bool(self.settings.value("loop", False)))
        idx = self.replay.speed.findData(self.session.speed)
        if idx >= 0:
            self.replay.speed.setCurrentIndex(idx)
        geometry = self.settings.value("geometry")
        if geometry is not None:
            self.restoreGeometry(geometry)

    def _make_engine(self, spec: str, **options):
        """The session's engine factory: the process engine (default) or the thread engine."""
        return make_engine(self.engine_kind, spec, full_frames=self.full_frames, parent=self, **options)

    # -- errors ------------------------------------------------------------------------
    def show_error(self, title: str, message: str) -> None:
        self.session.report(title, message)

    def _show_error(self, title: str, message: str) -> None:
        """Tell the user, with the specific message (status bar, and a non-modal box, or `error_sink`)."""
        self.statusBar().showMessage(f"{title}: {message}", 10000)
        if self.error_sink is not None:
            self.error_sink(title, message)
        else:
            self.error_boxes.show(title, message)

    def open_error_boxes(self) -> list:
        return self.error_boxes.open_boxes()

    # -- sources -----------------------------------------------------------------------
    def open_source(self, spec: str) -> None:
        """Open a recording folder, a video (`file:PATH[?calibration=YAML]`), `v4l2:N` or `depthai[:id]`."""
        r = self.view.devicePixelRatioF()
        self.session.display_size = (int(self.view.width() * r), int(self.view.height() * r))
        self.session.open_source(spec)

    def _source_opening(self, name: str) -> None:
        self.stats.restart()
        # the last source's figures are not this one's (and stay wrong if it fails to open)
        self.tracking_panel.clear_stats()
        for label in (self.status_state, self.status_fps, self.status_latency):
            label.setText("")
        self.status_source.setText(f"opening {name}...")
        self.view.message = f"Opening {name}..."
        self.view.set_image(None)

    @staticmethod
    def freeze_heap() -> None:
        """Move the objects alive now (Qt wrappers, loaded models and meshes) out of the garbage collector's
        reach: a full collection over them stalls the UI thread for ~50 ms on this machine, while frames
        only make short-lived objects that the young generations handle in a millisecond."""
        gc.freeze()

    def _source_opened(self, info) -> None:
        self.freeze_heap()
        self.replay.set_source(seekable=info.seekable, frame_count=info.frame_count, fps=info.fps)
        self.tracking_panel.set_anchors(info.anchors)
        cam = info.camera
        size = f"{cam.width}x{cam.height}" if cam is not None else "?"
        kind = f"{info.frame_count} frames at {info.fps:g} fps" if info.seekable else "live"
        self.status_source.setText(f"{info.name}  ({size}, {kind})")

    def choose_source(self) -> None:
        dlg = SourceDialog(self.session.recent("recent_sources"), self)
        dlg.source_chosen.connect(self.open_source)
        dlg.open()
        self._source_dialog = dlg

    def choose_recording(self) -> None:
        folder = ask_recording(self)
        if folder:
            self.open_source(folder)

    def choose_video(self) -> None:
        spec = ask_video_spec(self, self.show_error)
        if spec:
            self.open_source(spec)

    # -- frames ------------------------------------------------------------------------
    def _frame(self, shown) -> None:
        self._awaiting_paint = shown
        self.view.set_image(shown.qimage)
        self.replay.set_position(shown.result.index, shown.result.t)

    def _painted(self, when: float) -> None:
        shown, self._awaiting_paint = self._awaiting_paint, None
        if shown is not None:
            self.stats.painted(shown, when)
            self.frame_painted.emit(shown.result.index)

    def _refresh_status(self) -> None:
        shown = self.session.last_shown
        if shown is None:
            return
        res, st = shown.result, self.stats
        self.tracking_panel.update_stats(res, st.fps, st.latency_ms, shown.dropped_capture + shown.dropped_paint)
        self.status_state.setText(f"{res.state}")
        self.status_fps.setText(f"{st.fps:5.1f} fps")
        self.status_latency.setText(f"latency {st.latency_ms:4.0f} ms")

    # -- replay, recording, anchors ---------------------------------------------------------
    def toggle_play(self) -> None:
        self.session.toggle_play()

    def step(self) -> None:
        self.session.step()

    def seek(self, frame: int) -> None:
        self.session.seek(frame)

    def toggle_fullscreen(self) -> None:
        self.showNormal() if self.isFullScreen() else self.showFullScreen()

    def toggle_recording(self, on: bool) -> None:
        if not self.session.can_record:
            self.replay.record_button.setChecked(False)
            return
        if on:
            self.session.start_recording()
            self.replay.record_button.setText("Stop recording")
        else:
            self.replay.record_button.setText("Record")
            self.session.stop_recording()

    def edit_anchors(self) -> None:
        dlg = AnchorsDialog(self.session.anchors_json(), self)
        if dlg.exec():
            self.session.set_anchors_json(dlg.anchors_json)

    def save_marker_sheets(self) -> None:
        info = self.session.source_info
        anchors = (info.anchors if info is not None else None) or self.session.anchors_json()
        folder = QFileDialog.getExistingDirectory(self, "Save marker sheets to", str(Path.cwd()))
        if folder:
            Task(sheets.save_sheets, anchors, folder,
                 done=lambda paths: self.statusBar().showMessage(f"Saved {', '.join(map(str, paths))}", 8000),
                 failed=lambda e: self.show_error("Cannot save marker sheets", str(e)), owner=self).start()

    # -- models --------------------------------------------------------------------------
    def choose_model(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open a model", str(Path.cwd() / "models"), MODEL_FILTER)
        if path:
            self.open_model(path)

    def open_model(self, path: str) -> None:
        """Load (and tessellate) in a worker thread; errors (a bad model file) come back as a dialog."""
        self.session.open_model(path)

    def _model_loaded(self, model, path: str, placement) -> None:
        self.model_panel.set_model(model, path, placement)
        self.freeze_heap()
        self.model_ready.emit(model)

    def _model_edited(self, model) -> None:
        self.model_panel.set_surfaces(model.surfaces)
        self.model_ready.emit(model)

    def _start_thumbnails(self) -> None:
        def each(result):
            on_ui(lambda r: self.model_panel.set_thumbnail(*r), result, self)

        self._thumb_task = Task(library_thumbnails, library_files(), each, name="arapp-thumbnails",
                                owner=self).start()

    # -- printing ------------------------------------------------------------------------
    def open_print_dialog(self) -> None:
        old = self._print_dialog
        if old is not None and old.printing:
            old.show()  # a print is running: its panel, not a new one
            if getattr(self, "print_dock", None) is not None:
                self.print_dock.show()
                self.print_dock.raise_()
            return
        ps = self.session.new_print_session()
        if ps is None:
            return
        self._print_dialog = PrintDialog(ps, settings=self.settings, parent=self)
        show_print_panel(self, self._print_dialog)  # beside the view, which shows the bed preview

    def set_toolpaths(self, spec: dict | None) -> None:
        """Show the print preview `spec` (arapp.engine.toolpaths.preview_spec) on the bed; None clears it."""
        self.session.set_toolpaths(spec)

    # -- drag and drop, closing ------------------------------------------------------------
    def dragEnterEvent(self, event):  # noqa: N802
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event):  # noqa: N802
        for url in event.mimeData().urls():
            self.open_path(url.toLocalFile())
        event.acceptProposedAction()

    def open_path(self, path: str) -> None:
        """A dropped or given path: a model file, a recording folder or a video."""
        kind, target = self.session.classify_path(path)
        self.open_model(target) if kind == "model" else self.open_source(target)

    def closeEvent(self, event):  # noqa: N802
        self.settings.setValue("geometry", self.saveGeometry())
        self.settings.sync()
        self.session.shutdown(wait=2.0)
        super().closeEvent(event)


def _session_view(name: str) -> property:
    return property(lambda self: getattr(self.session, name), doc=f"The session's `{name}` (read only).")


# read-only views of the session's state, for scripts and tests that look at the window
for _name in ("engine", "source_info", "source_spec", "last_shown", "model", "base_model", "model_path",
              "mesh_lines", "edits", "placement", "mode", "model_gen", "highlight", "toolpaths_spec",
              "toolpaths_gen", "toolpaths_info", "errors", "recording_folder"):
    setattr(MainWindow, _name, _session_view(_name))
for _name in ("frames_painted", "latencies_ms", "fps", "latency_ms"):
    setattr(MainWindow, _name, property(lambda self, n=_name: getattr(self.stats, n)))
