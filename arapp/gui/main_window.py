"""The main window: live view, replay bar, model and tracking panels, status bar, menus and shortcuts.

Everything slow happens elsewhere: frames in `workers.Engine`'s threads,
model loading, thumbnails and re-tessellation in `tasks`. Slots here only
move small objects around and paint.
"""

from __future__ import annotations

import gc
import json
import os
from collections import deque
from pathlib import Path

import numpy as np

from PySide6.QtCore import QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDockWidget,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QVBoxLayout,
    QWidget,
)

from arapp.gui import sourcespec
from arapp.gui.panels.model import MODEL_FILTER, ModelPanel, library_files
from arapp.gui.panels.replay import ReplayBar
from arapp.gui.panels.tracking import AnchorsDialog, TrackingPanel
from arapp.gui.source_dialog import ask_recording, ask_video
from arapp.gui.tasks import LatestTask, Task, init_ui_bridge
from arapp.gui.view import VideoView
from arapp.gui.workers import Engine, SourceInfo

MESH_SUFFIXES = {".stl", ".obj", ".ply", ".3mf", ".glb"}
RECENT_MAX = 8
DEFAULT_ANCHORS = [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                    "marker_length": 0.04, "separation": 0.01, "first_id": 0}]


def app_settings() -> QSettings:
    return QSettings("arapp", "arapp")


class MainWindow(QMainWindow):
    """The arapp desktop window. `frame_painted(index)` fires after each new frame reaches the screen;
    `errors` lists every (title, message) shown to the user."""

    frame_painted = Signal(int)
    model_ready = Signal(object)

    def __init__(self, settings: QSettings | None = None, parent=None):
        super().__init__(parent)
        init_ui_bridge()
        self.settings = settings or app_settings()
        self.setWindowTitle("arapp")
        self.resize(1400, 860)
        self.setAcceptDrops(True)

        self.engine: Engine | None = None
        self.source_info: SourceInfo | None = None
        self.source_spec: str | None = None
        self.model = None
        self.model_path: str | None = None
        self.placement: dict | None = None
        self.mode = str(self.settings.value("mode", "shaded"))
        self.base_model = None  # the model as loaded; `model` is it with `edits` applied
        self.edits: dict = {}  # (surface, i, j) -> ((x, y, z), weight)
        self.mesh_lines = None  # (mesh, lines) of `model`, tessellated in a worker
        self.errors: list[tuple[str, str]] = []
        # where capture, tracking and rendering run: "process" (a child process, the default: the UI never
        # waits for the pipeline's interpreter lock) or "threads" (worker threads in this process)
        self.engine_kind = os.environ.get("ARAPP_GUI_ENGINE", "process")
        self.full_frames = False  # also hand over full-size composited and raw frames (for checks)
        self.model_gen = 0
        self.recording_folder = None
        self.highlight = None  # (surface, i, j): the control point being edited, ringed in the view
        self.error_sink = None  # callable(title, message) replacing dialogs (screenshot mode)
        self._open_boxes: dict[tuple[str, str], QMessageBox] = {}
        self.last_shown = None
        self._awaiting_paint = None
        self.frames_painted = 0
        self._engine_frames = 0
        self._painted_frame = self._painted_capture = None
        self.latencies_ms: list[float] = []
        self._paint_times: deque[float] = deque(maxlen=120)
        self.fps = 0.0
        self.latency_ms = 0.0
        self._print_dialog = None
        self._model_task: Task | None = None
        # the print preview on the bed: the request (arapp.gui.toolpaths.preview_spec) and what the view drew
        self.toolpaths_spec: dict | None = None
        self.toolpaths_gen = 0
        self.toolpaths_info: dict | None = None

        self.view = VideoView()
        self.view.painted.connect(self._painted)
        self.view.resized.connect(lambda w, h: self.engine.set_display_size(w, h) if self.engine else None)
        self.view.drag_started.connect(self._drag_started)
        self.view.drag_moved.connect(self._drag_moved)
        self.view.drag_ended.connect(self._drag_ended)
        self.view.wheel_steps.connect(self._wheel_scaled)
        self._drag = None   # (mode, grabbed paper point mm, placement at the grab, pose at the grab)
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
        self.status_state = QLabel("")
        self.status_fps = QLabel("")
        self.status_latency = QLabel("")
        sb = self.statusBar()
        sb.addWidget(self.status_source, 1)
        for w in (self.status_state, self.status_fps, self.status_latency):
            sb.addPermanentWidget(w)

        self._build_actions()
        self._connect_panels()
        self.model_panel.mode.setCurrentText(self.mode)
        self.model_panel.set_library(library_files())
        self.replay.loop.setChecked(self.settings.value("loop", False, type=bool))
        speed = float(self.settings.value("speed", 1.0))
        idx = self.replay.speed.findData(speed)
        if idx >= 0:
            self.replay.speed.setCurrentIndex(idx)
        geometry = self.settings.value("geometry")
        if geometry is not None:
            self.restoreGeometry(geometry)
        self._edit_task = LatestTask(self._retessellate, self._edit_done, self._edit_failed, name="arapp-edit",
                                     owner=self)
        self._status_timer = QTimer(self)
        self._status_timer.setInterval(250)
        self._status_timer.timeout.connect(self._refresh_status)
        self._status_timer.start()
        QTimer.singleShot(0, self._start_thumbnails)
        QTimer.singleShot(0, self.freeze_heap)

    # -- actions, menus, shortcuts -----------------------------------------------------
    def _action(self, text: str, slot, shortcut=None, menu=None) -> QAction:
        a = QAction(text, self)
        if shortcut is not None:
            a.setShortcut(QKeySequence(shortcut))
            a.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
        a.triggered.connect(slot)
        self.addAction(a)
        if menu is not None:
            menu.addAction(a)
        return a

    def _build_actions(self) -> None:
        mb = self.menuBar()
        file_menu = mb.addMenu("&File")
        self._action("Open source...", self.choose_source, QKeySequence.StandardKey.Open, file_menu)
        self._action("Open recording folder...", self.choose_recording, None, file_menu)
        self._action("Open video with calibration...", self.choose_video, None, file_menu)
        self._action("Open model...", self.choose_model, "Ctrl+M", file_menu)
        self.recent_sources_menu = file_menu.addMenu("Recent sources")
        self.recent_models_menu = file_menu.addMenu("Recent models")
        file_menu.addSeparator()
        self.print_action = self._action("Print...", self.open_print_dialog, "P", file_menu)
        file_menu.addSeparator()
        self._action("Quit", self.close, QKeySequence.StandardKey.Quit, file_menu)
        view_menu = mb.addMenu("&View")
        self.play_action = self._action("Play / pause", self.toggle_play, "Space", view_menu)
        self._action("Step", self.step, ".", view_menu)
        self.fullscreen_action = self._action("Full screen", self.toggle_fullscreen, "F", view_menu)
        track_menu = mb.addMenu("&Tracking")
        self.reset_action = self._action("Reset tracking", self.reset_tracking, "R", track_menu)
        self._action("Anchors...", self.edit_anchors, None, track_menu)
        self._update_recent_menus()

    def _connect_panels(self) -> None:
        r = self.replay
        r.play_toggled.connect(self.toggle_play)
        r.step_requested.connect(self.step)
        r.seek_requested.connect(self.seek)
        r.speed_changed.connect(self._speed_changed)
        r.loop_changed.connect(self._loop_changed)
        r.record_toggled.connect(self.toggle_recording)
        m = self.model_panel
        m.model_chosen.connect(self.open_model)
        m.open_requested.connect(self.choose_model)
        m.placement_changed.connect(self.set_placement)
        m.mode_changed.connect(self.set_mode)
        m.point_edited.connect(self.edit_control_point)
        m.point_selected.connect(self._point_selected)
        m.print_requested.connect(self.open_print_dialog)
        t = self.tracking_panel
        t.reset_requested.connect(self.reset_tracking)
        t.edit_anchors_requested.connect(self.edit_anchors)
        t.marker_sheets_requested.connect(self.save_marker_sheets)

    # -- errors ------------------------------------------------------------------------
    def show_error(self, title: str, message: str) -> None:
        """Tell the user, with the specific message. Non-modal, so frames keep flowing; a message already
        on screen is not stacked again."""
        self.errors.append((title, message))
        self.statusBar().showMessage(f"{title}: {message}", 10000)
        if self.error_sink is not None:
            self.error_sink(title, message)
            return
        key = (title, message)
        if key in self._open_boxes:
            return
        box = QMessageBox(QMessageBox.Icon.Critical, title, message, QMessageBox.StandardButton.Ok, self)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose, True)
        box.finished.connect(lambda _r, k=key: self._open_boxes.pop(k, None))
        self._open_boxes[key] = box
        box.open()

    def open_error_boxes(self) -> list[QMessageBox]:
        return list(self._open_boxes.values())

    # -- sources -----------------------------------------------------------------------
    def anchors_json(self) -> list:
        text = self.settings.value("anchors")
        if text:
            try:
                return json.loads(text)
            except ValueError:
                pass
        return DEFAULT_ANCHORS

    def open_source(self, spec: str) -> None:
        """Open a recording folder, a video (`file:PATH[?calibration=YAML]`), `v4l2:N` or `depthai[:id]`."""
        from tracking.session import parse_anchors

        self.close_source()
        try:
            anchors = parse_anchors(self.anchors_json())
        except ValueError as exc:
            self.show_error("Anchors are not valid", str(exc))
            anchors = parse_anchors(DEFAULT_ANCHORS)
        self.source_spec = spec
        name = sourcespec.display_name(spec)
        if self.engine_kind == "threads":
            engine = Engine(lambda: sourcespec.open_spec(spec), self._make_pipeline, name=name,
                            default_anchors=anchors, speed=self.replay.speed.currentData(),
                            loop=self.replay.loop.isChecked(), parent=self)
        else:
            from arapp.gui.remote import RemoteEngine

            engine = RemoteEngine(spec, name=name, anchors_json=[a.to_dict() for a in anchors],
                                  speed=self.replay.speed.currentData(), loop=self.replay.loop.isChecked(),
                                  full_frames=self.full_frames, parent=self)
        engine.recorded.connect(self._recorded)
        engine.opened.connect(self._source_opened)
        engine.frame_ready.connect(self._frame_ready)
        engine.error.connect(self.show_error)
        engine.ended.connect(self._ended)
        engine.toolpaths_shown.connect(self._toolpaths_shown)
        self.engine = engine
        r = self.view.devicePixelRatioF()
        engine.set_display_size(int(self.view.width() * r), int(self.view.height() * r))
        self._engine_frames = 0
        self._painted_frame = self._painted_capture = None
        self.latency_ms = 0.0
        self.status_source.setText(f"opening {name}...")
        self.view.message = f"Opening {name}..."
        self.view.set_image(None)
        engine.start()
        self._push_model_state()
        if self.highlight is not None:
            engine.set_highlight(self.highlight)
        if self.toolpaths_spec is not None:
            engine.set_toolpaths(self.toolpaths_spec, self.toolpaths_gen)
        self.replay.set_playing(True)
        self._remember("recent_sources", spec)

    def close_source(self) -> None:
        if self.engine is not None:
            self.engine.frame_ready.disconnect(self._frame_ready)
            self.engine.stop()
            self._old_engines = [e for e in getattr(self, "_old_engines", []) if e.running] + [self.engine]
            self.engine = None
            self.source_info = None

    @staticmethod
    def _make_pipeline(source, info: SourceInfo):
        """Runs in the processing thread: the pipeline without a model; the model arrives as a command."""
        from arapp.pipeline import Pipeline

        return Pipeline(info.camera, info.anchors, status_line=False)

    @staticmethod
    def freeze_heap() -> None:
        """Move the objects alive now (Qt wrappers, loaded models and meshes) out of the garbage collector's
        reach: a full collection over them stalls the UI thread for ~50 ms on this machine, while frames
        only make short-lived objects that the young generations handle in a millisecond."""
        gc.freeze()

    def _source_opened(self, info: SourceInfo) -> None:
        self.freeze_heap()
        self.source_info = info
        self.replay.set_source(seekable=info.seekable, frame_count=info.frame_count, fps=info.fps)
        self.replay.set_playing(self.engine.playing if self.engine else False)
        self.tracking_panel.set_anchors(info.anchors)
        cam = info.camera
        size = f"{cam.width}x{cam.height}" if cam is not None else "?"
        kind = f"{info.frame_count} frames at {info.fps:g} fps" if info.seekable else "live"
        self.status_source.setText(f"{info.name}  ({size}, {kind})")

    def choose_source(self) -> None:
        from arapp.gui.source_dialog import SourceDialog

        dlg = SourceDialog(self._recent("recent_sources"), self)
        dlg.source_chosen.connect(self.open_source)
        dlg.open()
        self._source_dialog = dlg

    def choose_recording(self) -> None:
        folder = ask_recording(self)
        if folder:
            self.open_source(folder)

    def choose_video(self) -> None:
        chosen = ask_video(self)
        if chosen is None:
            return
        video, calib = chosen
        if not calib:
            self.show_error("Calibration needed", f"{video}: tracking needs the camera's calibration; "
                            "choose the YAML written by 'arapp calibrate' or OpenCV's calibration tools")
            return
        self.open_source(sourcespec.video_spec(video, calib))

    # -- frames ------------------------------------------------------------------------
    def _frame_ready(self) -> None:
        if self.engine is None:
            return
        shown = self.engine.take()
        if shown is None:
            return
        self.last_shown = shown
        self._awaiting_paint = shown
        self.view.set_image(shown.qimage)
        res = shown.result
        self.replay.set_position(res.index, res.t)

    def _painted(self, when: float) -> None:
        shown, self._awaiting_paint = self._awaiting_paint, None
        if shown is None:
            return
        self.frames_painted += 1
        self._engine_frames += 1
        redraw = (self._painted_frame is not None and shown.result.index == self._painted_frame
                  and shown.captured_at == self._painted_capture)
        self._painted_frame, self._painted_capture = shown.result.index, shown.captured_at
        # the first frame of a source waits for GL start-up, and a paused frame drawn again with new
        # settings was captured long ago: neither is a latency
        counts = self._engine_frames > 1 and not redraw
        latency = (when - shown.captured_at) * 1e3
        if counts:
            self.latencies_ms.append(latency)
            self.latency_ms = latency if self.latency_ms == 0 else 0.8 * self.latency_ms + 0.2 * latency
        self._paint_times.append(when)
        if len(self._paint_times) >= 2:
            span = self._paint_times[-1] - self._paint_times[0]
            recent = [t for t in self._paint_times if t >= when - 1.0]
            if len(recent) >= 2 and recent[-1] > recent[0]:
                self.fps = (len(recent) - 1) / (recent[-1] - recent[0])
            elif span > 0:
                self.fps = (len(self._paint_times) - 1) / span
        self.frame_painted.emit(shown.result.index)

    def _refresh_status(self) -> None:
        shown = self.last_shown
        if shown is None:
            return
        res = shown.result
        dropped = shown.dropped_capture + shown.dropped_paint
        self.tracking_panel.update_stats(res, self.fps, self.latency_ms, dropped)
        self.status_state.setText(f"{res.state}")
        self.status_fps.setText(f"{self.fps:5.1f} fps")
        self.status_latency.setText(f"latency {self.latency_ms:4.0f} ms")

    def _ended(self) -> None:
        self.replay.set_playing(False)
        self.statusBar().showMessage("End of the recording", 3000)

    # -- replay controls -----------------------------------------------------------------
    def toggle_play(self) -> None:
        if self.engine is None:
            return
        if self.engine.playing:
            self.engine.pause()
        else:
            if (self.source_info is not None and self.source_info.seekable and self.last_shown is not None
                    and self.last_shown.result.index >= self.source_info.frame_count - 1):
                self.engine.seek(0)
            self.engine.play()
        self.replay.set_playing(self.engine.playing)

    def step(self) -> None:
        if self.engine is not None and self.source_info is not None and self.source_info.seekable:
            self.engine.step()
            self.replay.set_playing(False)

    def seek(self, frame: int) -> None:
        if self.engine is not None:
            self.engine.seek(frame)

    def _speed_changed(self, speed: float) -> None:
        self.settings.setValue("speed", speed)
        if self.engine is not None:
            self.engine.set_speed(speed)

    def _loop_changed(self, loop: bool) -> None:
        self.settings.setValue("loop", loop)
        if self.engine is not None:
            self.engine.set_loop(loop)

    def reset_tracking(self) -> None:
        if self.engine is not None:
            self.engine.reset()
            self.statusBar().showMessage("Tracking reset", 2000)

    def toggle_fullscreen(self) -> None:
        if self.isFullScreen():
            self.showNormal()
        else:
            self.showFullScreen()

    # -- recording (live sources) --------------------------------------------------------
    def toggle_recording(self, on: bool) -> None:
        from arapp.gui import recording

        if self.engine is None or self.source_info is None or self.source_info.seekable:
            self.replay.record_button.setChecked(False)
            return
        if on:
            folder = recording.new_recording_folder()
            self.recording_folder = folder
            self.engine.record_start(folder)
            self.statusBar().showMessage(f"Recording to {folder}", 5000)
            self.replay.record_button.setText("Stop recording")
        else:
            self.replay.record_button.setText("Record")
            self.engine.record_stop()

    def _recorded(self, folder: str) -> None:
        self.statusBar().showMessage(f"Saved the recording {folder}", 8000)
        self._remember("recent_sources", folder)

    # -- anchors -------------------------------------------------------------------------
    def edit_anchors(self) -> None:
        dlg = AnchorsDialog(self.anchors_json(), self)
        if dlg.exec():
            self.settings.setValue("anchors", json.dumps(dlg.anchors_json))
            if self.source_info is not None and self.source_info.live and self.source_spec:
                self.open_source(self.source_spec)

    def save_marker_sheets(self) -> None:
        from arapp.gui import sheets

        anchors = self.source_info.anchors if self.source_info is not None else None
        folder = QFileDialog.getExistingDirectory(self, "Save marker sheets to", str(Path.cwd()))
        if not folder:
            return
        Task(sheets.save_sheets, anchors or self.anchors_json(), folder,
             done=lambda paths: self.statusBar().showMessage(f"Saved {', '.join(map(str, paths))}", 8000),
             failed=lambda e: self.show_error("Cannot save marker sheets", str(e)), owner=self).start()

    # -- models --------------------------------------------------------------------------
    def choose_model(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open a model", str(Path.cwd() / "models"), MODEL_FILTER)
        if path:
            self.open_model(path)

    def open_model(self, path: str) -> None:
        """Load (and tessellate) in a worker thread; errors (a bad model file) come back as a dialog."""
        from arapp.pipeline import load_display_model

        from arapp.gui.editing import model_mesh

        def load(p):
            model = load_display_model(p)
            return model, model_mesh(model)  # tessellate here, off the UI thread

        self.statusBar().showMessage(f"Loading {path}...")
        self._model_task = Task(load, str(path), done=lambda r, p=str(path): self._model_loaded(r[0], r[1], p),
                                failed=lambda e, p=str(path): self.show_error("Cannot open the model", str(e)),
                                name="arapp-load-model", owner=self).start()

    def _model_loaded(self, model, mesh_lines, path: str) -> None:
        from arapp.gui.editing import display_placement

        self.model = model
        self.base_model = model
        self.edits = {}
        self.model_path = path
        self.mesh_lines = mesh_lines
        self.placement = display_placement(model)
        self.model_panel.set_model(model, path, self.placement)
        self.highlight = None  # ring a control point only once the user picks one
        if self.engine is not None:
            self.engine.set_highlight(None)
        self._push_model_state()
        self._remember("recent_models", path)
        self.statusBar().showMessage(f"Model {Path(path).name}", 3000)
        self.freeze_heap()
        self.model_ready.emit(model)

    def _push_model_state(self) -> None:
        if self.engine is None:
            return
        self.model_gen += 1
        self.engine.set_model(self.model_gen, self.model_path if self.model is not None else None,
                              self.edits, self.placement, self.mode, model=self.model)

    def set_placement(self, placement: dict) -> None:
        self.placement = dict(placement)
        if self.engine is not None and self.model is not None:
            self.engine.set_placement(dict(placement))

    # -- placing the model with the pointer --------------------------------------------------
    def _paper_point(self, fx: float, fy: float, pose=None):
        """The placement-frame point (x, y mm) on the anchor's paper under the frame fraction (fx, fy),
        seen from `pose` (default: the shown frame's); None without a model, a pose, or a hit."""
        from arapp.placement import placement_point_at_pixel

        info = self.source_info
        if self.model is None or info is None or not info.anchors or self.last_shown is None:
            return None
        pose = self.last_shown.result.world_from_camera if pose is None else pose
        if pose is None:
            return None
        cam = info.camera
        pixel = (fx * cam.width - 0.5, fy * cam.height - 0.5)   # pixel centres at integers
        return placement_point_at_pixel(cam, pose, info.anchors[0], pixel)

    def _drag_started(self, fx: float, fy: float, mode: str) -> None:
        from arapp.placement import placement_from_any

        grab = self._paper_point(fx, fy)
        self._drag = None
        if grab is not None:
            pose = self.last_shown.result.world_from_camera.copy()
            self._drag = (mode, grab, placement_from_any(self.placement), pose)

    def _drag_moved(self, fx: float, fy: float) -> None:
        from arapp.placement import dragged_placement

        if self._drag is None:
            return
        mode, grab, start, pose = self._drag
        # the paper under the pointer in the view being shown (a live camera may move meanwhile)
        now = self._paper_point(fx, fy)
        if now is None:
            now = self._paper_point(fx, fy, pose)
        if now is not None:
            self._place(dragged_placement(start, grab, now, mode))

    def _drag_ended(self) -> None:
        self._drag = None

    def _wheel_scaled(self, steps: float) -> None:
        from dataclasses import replace

        from arapp.placement import placement_from_any

        if self.model is None or steps == 0:
            return
        p = placement_from_any(self.placement)
        self._place(replace(p, size_mm=float(np.clip(p.size_mm * 1.1 ** steps, 1.0, 1000.0))))

    def _place(self, placement) -> None:
        """Apply a placement chosen with the pointer: the fields show it, the view draws it."""
        d = {"size_mm": placement.size_mm, "offset": tuple(placement.offset),
             "rotation_deg": tuple(placement.rotation_deg)}
        self.model_panel.set_placement(d)
        self.set_placement(d)

    def set_mode(self, mode: str) -> None:
        self.mode = mode
        self.settings.setValue("mode", mode)
        if self.engine is not None:
            self.engine.set_mode(mode)

    def _point_selected(self, k: int, i: int, j: int) -> None:
        self.highlight = (k, i, j)
        if self.engine is not None:
            self.engine.set_highlight(self.highlight)

    def edit_control_point(self, k: int, i: int, j: int, xyz: tuple, weight: float) -> None:
        """Replace surface k's control point (i, j) and its weight; re-tessellate in a worker (newest edit wins)."""
        if self.model is None:
            return
        self.edits[(k, i, j)] = (tuple(xyz), float(weight))
        self._edit_task.send((self.base_model, dict(self.edits)))

    @staticmethod
    def _retessellate(job):
        from arapp.gui.editing import edited_model, model_mesh

        base, edits = job
        model = edited_model(base, edits)
        return base, model, model_mesh(model)

    def _edit_done(self, result) -> None:
        base, model, (mesh, lines) = result
        if base is not self.base_model:
            return  # the user switched models meanwhile
        self.model = model
        self.mesh_lines = (mesh, lines)
        self.model_panel.set_surfaces(model.surfaces)
        # the edited model's bounds may differ: place it anew (the engine re-tessellates off the UI thread)
        self._push_model_state()
        self.model_ready.emit(model)

    def _edit_failed(self, exc: BaseException) -> None:
        self.show_error("Cannot apply the edit", str(exc))
        if self.model is not None:
            self.model_panel.set_surfaces(self.model.surfaces)

    def _start_thumbnails(self) -> None:
        from arapp.gui.editing import library_thumbnails

        paths = library_files()

        def each(result):
            path, image = result
            self.model_panel.set_thumbnail(path, image)

        self._thumb_task = Task(library_thumbnails, paths, each, self, name="arapp-thumbnails").start()

    # -- printing ------------------------------------------------------------------------
    def open_print_dialog(self) -> None:
        old = self._print_dialog
        if old is not None and old.printing:
            old.show()  # a print is running: its dialog, not a new one
            old.raise_()
            return
        if self.model is None:
            self.show_error("Nothing to print", "Open a model first (Model panel or File > Open model)")
            return
        from arapp.gui.print_dialog import PrintDialog

        dlg = PrintDialog(self.model, self.placement, settings=self.settings, parent=self)
        dlg.error.connect(self.show_error)
        dlg.preview_changed.connect(self.set_toolpaths)
        self._print_dialog = dlg
        dlg.open()

    def set_toolpaths(self, spec: dict | None) -> None:
        """Show the print preview `spec` (arapp.gui.toolpaths.preview_spec: G-code, printer profile, layer,
        layer being printed) on the bed in the live view; None clears it. Built in the engine, off this thread."""
        self.toolpaths_gen += 1
        self.toolpaths_spec = None if spec is None else dict(spec)
        if self.engine is not None:
            self.engine.set_toolpaths(self.toolpaths_spec, self.toolpaths_gen)

    def _toolpaths_shown(self, info: dict) -> None:
        if self.sender() is not self.engine:
            return  # a closed source's engine
        self.toolpaths_info = info
        dlg = self._print_dialog
        if dlg is not None and info.get("layers"):
            dlg.preview_shown(info)
        if info.get("outside"):
            self.statusBar().showMessage("Print preview: the part leaves the build area (drawn red on the bed)",
                                         10000)

    # -- settings, recent files, drag and drop -----------------------------------------------
    def _recent(self, key: str) -> list[str]:
        value = self.settings.value(key, [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def _remember(self, key: str, item: str) -> None:
        items = [item] + [x for x in self._recent(key) if x != item]
        self.settings.setValue(key, items[:RECENT_MAX])
        self._update_recent_menus()

    def _update_recent_menus(self) -> None:
        for menu, key, slot in ((self.recent_sources_menu, "recent_sources", self.open_source),
                                (self.recent_models_menu, "recent_models", self.open_model)):
            menu.clear()
            for item in self._recent(key):
                a = menu.addAction(item)
                a.triggered.connect(lambda _c=False, x=item, s=slot: s(x))
            menu.setEnabled(bool(self._recent(key)))

    def dragEnterEvent(self, event):  # noqa: N802
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event):  # noqa: N802
        for url in event.mimeData().urls():
            self.open_path(url.toLocalFile())
        event.acceptProposedAction()

    def open_path(self, path: str) -> None:
        """A dropped or given path: a model file, a recording folder or a video."""
        p = Path(path)
        if p.suffix.lower() in MESH_SUFFIXES or (p.suffix.lower() == ".json" and p.name != "session.json"):
            self.open_model(str(p))
        elif p.name == "session.json":
            self.open_source(str(p.parent))
        else:
            self.open_source(str(p))

    def closeEvent(self, event):  # noqa: N802
        self.settings.setValue("geometry", self.saveGeometry())
        self.settings.sync()
        if self.engine is not None:
            if self.replay.record_button.isChecked():
                self.toggle_recording(False)
            self.engine.stop(wait=2.0)
        for e in getattr(self, "_old_engines", []):
            e.stop(wait=1.0)
        super().closeEvent(event)
