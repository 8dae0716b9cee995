"""The headless app model: one session's source, model, edits, placement, display mode, print preview,
print job and tracking state, with change events. No Qt.

The Qt layer (arapp.gui) binds widgets to a `Session`: it calls its methods
when the user acts and updates widgets from its `events`. A headless driver
(arapp.engine.headless, tests) does the same without widgets. The session talks
to the live engine only through `arapp.engine.commands`; an engine factory makes
the engine (the GUI's thread or process engine, or a headless one) and wires
its events to `EngineHandlers`, which must be called on the session's thread.

Units: placement in millimetres and degrees (arapp.geometry.placement), poses 4x4
world_from_camera in metres (docs/domain.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from arapp.engine import commands as cmd
from arapp.app import source_anchors
from arapp.engine.editing import display_placement, edited_model, model_mesh
from arapp.engine.events import Events
from arapp.app.first_picture import FirstPictureWatch, no_picture_message
from arapp.app.history import History
from arapp.app.captures import Captures
from arapp.app.print_session import PrintSession
from arapp.app.runner import ImmediateRunner
from arapp.engine.sourcespec import DEFAULT_ANCHORS, display_name
from arapp.exchange.meshes import is_mesh_path
from arapp.engine.pipeline import MODES, OCCLUSION_MODES, load_display_model
from arapp.geometry.placement import Placement, dragged_placement, placement_point_at_pixel
from arapp.app.scene_keeper import SceneKeeper
from arapp.app.settings import MemorySettings, as_bool
from tracking.anchors.defaults import DEFAULT_DICTIONARY
from tracking.anchors.discover import Suggestion
from tracking.recording.schema import parse_anchors

RECENT_MAX = 8
# while the print preview stands on the bed, the model on its marker is drawn see-through: one solid part
# in view, not two (the user may have the bed and the marker in the same picture)
GHOST_MODE = "translucent"
OCCLUSION_CHOICES = ("auto", *OCCLUSION_MODES)  # auto: depth when the frames carry depth, else off
GHOST_NOTE = "Print preview on the bed: the model on the marker is drawn see-through meanwhile"


def read_model(path: str):
    """(model, (mesh, lines)): the model file loaded for display and tessellated (worker thread)."""
    model = load_display_model(path)
    return model, model_mesh(model)


def retessellate(job):
    """(base, edited model, (mesh, lines)) for job = (base model, edits) (worker thread)."""
    base, edits = job
    model = edited_model(base, edits)
    return base, model, model_mesh(model)


@dataclass
class EngineHandlers:
    """What an engine factory wires the new engine's events to (called on the session's thread)."""

    opened: Callable[[Any], None]
    ready: Callable[[], None]
    error: Callable[[str, str], None]
    ended: Callable[[], None]
    recorded: Callable[[str], None]
    toolpaths: Callable[[dict], None]


class Session:
    """The app's state and actions, without widgets.

    make_engine(spec, name=, anchors=, speed=, loop=, handlers=) returns an
    engine (`send(command)`, `start()`, `stop(wait)`, `take()`, `running`,
    `playing`); settings: QSettings or `MemorySettings`; runner: how jobs run
    (arapp.app.runner). Events (all on the session's thread):
    source_opening(name), source_opened(SourceInfo), frame(Shown), ended(),
    source_failed(name, line): the source was given up before its first picture (line: what to show
    on the view, "" when the error message says it), error(title, message), status(text, ms), recorded(folder),
    model_loaded(model, path, placement), model_edited(model),
    placement_changed(Placement), mode_changed(mode), playing_changed(bool),
    toolpaths_shown(info), recent_changed(), print_session(PrintSession),
    anchor_offer(dict): anchor discovery found something (arapp.engine.discovery.offer_dict; `use_offer` or
    `dismiss_offer` answer it).
    """

    def __init__(self, make_engine: Callable[..., Any], settings=None, runner=None):
        self.make_engine = make_engine
        self.settings = settings if settings is not None else MemorySettings()
        self.run = runner or ImmediateRunner()
        self.events = Events("source_opening", "source_opened", "frame", "ended", "error", "status", "recorded",
                             "model_loaded", "model_edited", "placement_changed", "mode_changed",
                             "playing_changed", "toolpaths_shown", "recent_changed", "print_session",
                             "source_failed", "ar_recording_changed", "anchor_offer")
        self.engine = None
        self.old_engines: list = []
        self.source_spec: str | None = None
        self.source_info = None
        self.last_shown = None  # the newest processed frame (arapp.engine.processor.Shown): tracking state
        self.errors: list[tuple[str, str]] = []
        self.base_model = None  # the model as loaded; `model` is it with `edits` applied
        self.model = None
        self.model_path: str | None = None
        self.mesh_lines = None  # (mesh, lines) of `model`
        self.edits: dict = {}  # (surface, i, j) -> ((x, y, z), weight)
        self.placement: Placement | None = None
        self.mode = str(self.settings.value("mode", "shaded"))
        self.occlusion = str(self.settings.value("occlusion", "auto"))  # OCCLUSION_CHOICES
        if self.occlusion not in OCCLUSION_CHOICES:
            self.occlusion = "auto"
        self.speed = float(self.settings.value("speed", 1.0))
        self.loop = as_bool(self.settings.value("loop", False))
        self.display_size: tuple[int, int] | None = None
        self.model_gen = 0
        self.highlight: tuple[int, int, int] | None = None  # the control point being edited, ringed
        self.show_marks = False  # the detected markers outlined on the frames (`set_show_marks`)
        self.toolpaths_spec: dict | None = None  # the print preview asked for (arapp.engine.toolpaths.preview_spec)
        self.toolpaths_gen = 0
        self.toolpaths_info: dict | None = None  # what the engine drew
        self._unghost_gen: int | None = None  # the preview clear after which the model is drawn solid again
        self.captures = Captures(self)  # recording, screenshot, AR video, export (arapp.app.captures)
        self.print_session: PrintSession | None = None
        self._drag = None  # (mode, grabbed paper point mm, placement at the grab, pose at the grab)
        self._edit = self.run.latest(retessellate, self._edit_done, self._edit_failed, name="arapp-edit")
        self.history = History(self)  # undo / redo of control-point edits and placement
        self.first_picture = FirstPictureWatch()  # a source silent for its timeout_s is given up (`tick`)
        self.anchor_offer: dict | None = None  # what anchor discovery found in the open source, unanswered
        self.scenes = SceneKeeper(self)  # the saved scene tracked against (arapp.app.scene_keeper)

    # -- errors and messages -------------------------------------------------------------
    def report(self, title: str, message: str) -> None:
        """A failure the user must see (the GUI shows a dialog)."""
        self.errors.append((title, message))
        self.events.error.emit(title, message)

    def status(self, text: str, ms: int = 3000) -> None:
        self.events.status.emit(text, ms)

    # -- settings: anchors, recent files ---------------------------------------------------
    def anchors_json(self) -> list:
        text = self.settings.value("anchors")
        if text:
            try:
                return json.loads(text)
            except ValueError:
                pass  # a damaged setting: the defaults
        return DEFAULT_ANCHORS

    def set_anchors_json(self, anchors: list) -> None:
        """Store the anchors to track (session.json blocks) and reopen a live source with them."""
        self.settings.setValue("anchors", json.dumps(anchors))
        if self.source_info is not None and self.source_info.live and self.source_spec:
            self.open_source(self.source_spec)

    def recent(self, key: str) -> list[str]:
        value = self.settings.value(key, [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def remember(self, key: str, item: str) -> None:
        items = [item] + [x for x in self.recent(key) if x != item]
        self.settings.setValue(key, items[:RECENT_MAX])
        self.events.recent_changed.emit()

    # -- sources ---------------------------------------------------------------------------
    def send(self, command) -> None:
        """Send a command to the open source's engine (nothing without one)."""
        if self.engine is not None:
            self.engine.send(command)

    def open_source(self, spec: str) -> None:
        """Open a recording folder, a video (`file:PATH[?calibration=YAML]`), `v4l2:N` or `depthai[:id]`."""
        self.close_source()
        self.anchor_offer = None
        try:
            # anchors accepted for this very source (an anchor offer) before the anchors setting
            anchors = parse_anchors(source_anchors.remembered(spec) or self.anchors_json())
        except ValueError as exc:
            self.report("Anchors are not valid", str(exc))
            anchors = parse_anchors(DEFAULT_ANCHORS)
        self.source_spec = spec
        name = display_name(spec)
        engine = None

        def mine(fn):
            # events of an engine closed meanwhile are dropped (errors still reach the user)
            return lambda *a: fn(*a) if self.engine is engine else None

        handlers = EngineHandlers(opened=mine(self._opened), ready=mine(self._frame_ready),
                                  error=lambda t, m: self._engine_error(engine, t, m),
                                  ended=mine(self._ended), recorded=self.captures.recorded,
                                  toolpaths=mine(self._toolpaths_shown))
        engine = self.make_engine(spec, name=name, anchors=anchors, speed=self.speed, loop=self.loop,
                                  handlers=handlers)
        self.engine = engine
        if self.display_size is not None:
            engine.send(cmd.SetDisplaySize(self.display_size))
        self.events.source_opening.emit(name)
        engine.start()
        self.first_picture.start()
        self._push_model()
        if self.occlusion != "auto":
            engine.send(cmd.SetOcclusion(self.occlusion))
        if self.highlight is not None:
            engine.send(cmd.Highlight(self.highlight))
        if self.show_marks:
            engine.send(cmd.ShowMarks(True))
        if self.toolpaths_spec is not None:
            engine.send(cmd.ShowToolpaths(self.toolpaths_spec, self.toolpaths_gen))
        self.scenes.engine_started()
        self.events.playing_changed.emit(True)

    @staticmethod
    def classify_path(path: str) -> tuple[str, str]:
        """("model", path) for a model file, else ("source", what to open): a dropped or given path, a model
        file (a mesh or NURBS JSON), a recording folder (or its session.json) or a video."""
        p = Path(path)
        if is_mesh_path(p) or (p.suffix.lower() == ".json" and p.name != "session.json"):
            return "model", str(p)
        return "source", str(p.parent if p.name == "session.json" else p)

    def pause(self) -> None:
        self.send(cmd.Pause())
        self.events.playing_changed.emit(False)

    def close_source(self) -> None:
        self.first_picture.stop()
        if self.engine is not None:
            self.stop_ar_recording()
            self.engine.stop()
            self.old_engines = [e for e in self.old_engines if e.running] + [self.engine]
            self.engine = None
            self.source_info = None
            self.last_shown = None   # its frames are no longer what is tracked

    def shutdown(self, wait: float = 2.0) -> None:
        """Stop recording and every engine (closing the app)."""
        if self.engine is not None:
            if self.recording_folder is not None:
                self.stop_recording()
            self.stop_ar_recording()
            self.engine.stop(wait=wait)
        for e in self.old_engines:
            e.stop(wait=wait / 2)

    def set_show_marks(self, on: bool) -> None:
        """Outline the markers the tracker detects, with the anchors' axes, on the frames shown (drawn by the
        engine under the model: arapp.engine.overlay_marks), or not."""
        self.show_marks = bool(on)
        self.send(cmd.ShowMarks(self.show_marks))

    def set_display_size(self, width: int, height: int) -> None:
        self.display_size = (int(width), int(height))
        self.send(cmd.SetDisplaySize(self.display_size))

    def _opened(self, info) -> None:
        self.source_info = info
        if self.source_spec:
            self.remember("recent_sources", self.source_spec)  # only sources that opened go into Recent
        self.events.source_opened.emit(info)
        self.events.playing_changed.emit(self.playing)

    def _engine_error(self, engine, title: str, message: str) -> None:
        """An engine's error reaches the user; when the open source fails before it opened, the session
        goes back to having no source (`_give_up_source`)."""
        self.report(title, message)
        if engine is not None and engine is self.engine and self.source_info is None:
            self._give_up_source("")

    def _give_up_source(self, line: str) -> None:
        """Back to having no source: the engine stopped, nothing remembered of it; source_failed(name, line)
        tells the GUI to reset its widgets."""
        name = display_name(self.source_spec) if self.source_spec else ""
        self.close_source()
        self.source_spec = None
        self.events.playing_changed.emit(False)
        self.events.source_failed.emit(name, line)

    def tick(self) -> None:
        """The session's time-based checks; call a few times a second on the session's thread (the GUI's
        status timer does). A source with no picture after `first_picture.timeout_s` is given up: the user
        is told what failed and what to do, and its engine is stopped."""
        if self.engine is None or not self.first_picture.expired():
            return
        spec = self.source_spec or ""
        title, line = no_picture_message(display_name(spec), spec, self.first_picture.timeout_s)
        self.report(title, line)
        self._give_up_source(line)

    def _frame_ready(self) -> None:
        shown = self.engine.take() if self.engine is not None else None
        if shown is not None:
            self.first_picture.stop()
            self.last_shown = shown
            self._check_offer(shown)
            self.events.frame.emit(shown)

    # -- anchor discovery's offer ------------------------------------------------------------------
    def _check_offer(self, shown) -> None:
        extra = getattr(shown.result, "extra", None)
        found = extra.get("discovery") if isinstance(extra, dict) else None
        if found and found != self.anchor_offer and self.engine is not None:
            self.anchor_offer = dict(found)
            self.events.anchor_offer.emit(self.anchor_offer)

    def use_offer(self, size_mm: float | None = None) -> list | None:
        """Track what anchor discovery found, its marker (or QR code) `size_mm` millimetres as measured on
        the print (None: the size assumed): remembered for this source (arapp.app.source_anchors) and the
        source reopened with it. Returns the anchor blocks used (metres); None without an offer."""
        offer = self.anchor_offer
        if not offer or not offer.get("block") or not self.source_spec:
            return None
        block = dict(offer["block"])
        if size_mm is not None:
            if not size_mm > 0:
                self.report("Marker size must be positive", f"got {size_mm} mm; measure a printed marker's side")
                return None
            block = Suggestion(str(block.get("kind")), str(offer["summary"]), block,
                               offer["size_field"]).with_size(float(size_mm) / 1000.0)
        anchors = [block]
        try:
            parse_anchors(anchors)
        except ValueError as exc:
            self.report("Cannot use the anchors found", str(exc))
            return None
        self.send(cmd.EndDiscovery())
        source_anchors.remember(self.source_spec, anchors)
        self.status(f"Tracking {offer['summary']} ({size_mm if size_mm is not None else offer['size_mm']:g} mm), "
                    f"remembered for this source", 8000)
        self.open_source(self.source_spec)
        return anchors

    def dismiss_offer(self) -> None:
        """Not now: discovery stops looking in this source until it is opened again."""
        self.send(cmd.EndDiscovery())

    def _ended(self) -> None:
        self.events.playing_changed.emit(False)
        self.events.ended.emit()
        self.status("End of the recording", 3000)

    # -- replay ----------------------------------------------------------------------------
    @property
    def playing(self) -> bool:
        return self.engine is not None and self.engine.playing

    def toggle_play(self) -> None:
        if self.engine is None:
            return
        if self.engine.playing:
            self.send(cmd.Pause())
        else:
            info, shown = self.source_info, self.last_shown
            if (info is not None and info.seekable and shown is not None
                    and shown.result.index >= info.frame_count - 1):
                self.send(cmd.Seek(0))  # at the end: from the start again
            self.send(cmd.Play())
        self.events.playing_changed.emit(self.engine.playing)

    def step(self) -> None:
        if self.engine is not None and self.source_info is not None and self.source_info.seekable:
            self.send(cmd.Step(1))
            self.events.playing_changed.emit(False)

    def seek(self, frame: int) -> None:
        self.send(cmd.Seek(int(frame)))

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)
        self.settings.setValue("speed", self.speed)
        self.send(cmd.SetSpeed(self.speed))

    def set_loop(self, loop: bool) -> None:
        self.loop = bool(loop)
        self.settings.setValue("loop", self.loop)
        self.send(cmd.SetLoop(self.loop))

    def reset_tracking(self) -> None:
        if self.engine is not None:
            self.send(cmd.Reset())
            self.status("Tracking reset", 2000)

    # -- captures: recording, screenshot, AR video, export (arapp.app.captures) ----------------
    @property
    def recording_folder(self) -> Path | None:
        return self.captures.recording_folder

    @property
    def ar_video_path(self) -> Path | None:
        return self.captures.ar_video_path

    @property
    def can_record(self) -> bool:
        return self.captures.can_record

    @property
    def can_record_ar(self) -> bool:
        return self.captures.can_record_ar

    def start_recording(self, folder=None):
        return self.captures.start_recording(folder)

    def stop_recording(self) -> None:
        self.captures.stop_recording()

    def save_screenshot(self, path=None) -> Path | None:
        return self.captures.save_screenshot(path)

    def start_ar_recording(self, path=None) -> Path | None:
        return self.captures.start_ar_recording(path)

    def stop_ar_recording(self) -> None:
        self.captures.stop_ar_recording()

    def export_model(self, path) -> Path | None:
        return self.captures.export_model(path)

    # -- models ----------------------------------------------------------------------------
    def open_model(self, path: str) -> None:
        """Load and tessellate the model file (through the runner); a bad file is reported."""
        path = str(path)
        self.status(f"Loading {path}...", 0)
        self.run.run(read_model, path, done=lambda r: self.set_model(r[0], r[1], path),
                     failed=lambda e: self.report("Cannot open the model", str(e)), name="arapp-load-model")

    def set_model(self, model, mesh_lines, path: str) -> None:
        """Show a loaded model at its own placement, with no edits."""
        self.model = self.base_model = model
        self.edits = {}
        self.model_path = path
        self.mesh_lines = mesh_lines
        self.placement = display_placement(model)
        self.highlight = None  # ring a control point only once the user picks one
        self.send(cmd.Highlight(None))
        self._push_model()
        self.remember("recent_models", path)
        self.status(f"Model {Path(path).name}", 3000)
        self.events.model_loaded.emit(model, path, self.placement)

    def _push_model(self) -> None:
        if self.engine is None:
            return
        self.model_gen += 1
        self.send(cmd.SetModel(self.model_gen, self.model_path if self.model is not None else None,
                               dict(self.edits), self.placement, self.display_mode, model=self.model))

    @property
    def display_mode(self) -> str:
        """The mode the model is drawn in: the chosen one, or the ghost while a print preview is shown."""
        return GHOST_MODE if self.toolpaths_spec is not None else self.mode

    def set_mode(self, mode: str) -> None:
        if mode not in MODES:
            raise ValueError(f"display mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.mode = mode
        self.settings.setValue("mode", mode)
        self.send(cmd.SetMode(self.display_mode))
        self.events.mode_changed.emit(mode)

    def set_occlusion(self, choice: str) -> None:
        """How real things hide the model: "auto" (depth when the source gives depth, else off), "off",
        "depth" or "plane" (docs/occlusion.md); kept in the settings."""
        if choice not in OCCLUSION_CHOICES:
            raise ValueError(f"occlusion must be one of {', '.join(OCCLUSION_CHOICES)}, got {choice!r}")
        self.occlusion = choice
        self.settings.setValue("occlusion", choice)
        self.send(cmd.SetOcclusion(None if choice == "auto" else choice))

    def select_point(self, k: int, i: int, j: int) -> None:
        self.highlight = (int(k), int(i), int(j))
        self.send(cmd.Highlight(self.highlight))

    def edit_control_point(self, k: int, i: int, j: int, xyz, weight: float) -> None:
        """Replace surface k's control point (i, j) and its weight; re-tessellate (newest edit wins)."""
        if self.model is None:
            return
        self.edits[(int(k), int(i), int(j))] = (tuple(float(x) for x in xyz), float(weight))
        self._edit.send((self.base_model, dict(self.edits)))

    def _edit_done(self, result) -> None:
        base, model, mesh_lines = result
        if base is not self.base_model:
            return  # the user switched models meanwhile
        self.model = model
        self.mesh_lines = mesh_lines
        self._push_model()  # the edited model's bounds may differ: placed anew
        self.events.model_edited.emit(model)

    def _edit_failed(self, exc: BaseException) -> None:
        self.report("Cannot apply the edit", str(exc))
        if self.model is not None:
            self.events.model_edited.emit(self.model)  # the fields go back to the values in force

    # -- placement -------------------------------------------------------------------------
    def set_placement(self, placement: Placement) -> None:
        """Place the model: size (mm), offset (mm) and rotation (degrees) on the world anchor."""
        if not isinstance(placement, Placement):
            raise TypeError(f"a placement must be an arapp.geometry.placement.Placement, got {type(placement).__name__}")
        self.placement = placement
        if self.model is not None:
            self.send(cmd.SetPlacement(placement))
        self.events.placement_changed.emit(placement)

    def paper_point(self, fx: float, fy: float, pose=None):
        """The placement-frame point (x, y mm) on the anchor's paper under the frame fraction (fx, fy),
        seen from `pose` (default: the shown frame's); None without a model, a pose, or a hit."""
        info = self.source_info
        if self.model is None or info is None or not info.anchors or self.last_shown is None:
            return None
        pose = self.last_shown.result.world_from_camera if pose is None else pose
        if pose is None:
            return None
        cam = info.camera
        pixel = (fx * cam.width - 0.5, fy * cam.height - 0.5)  # pixel centres at integers
        return placement_point_at_pixel(cam, pose, info.anchors[0], pixel)

    def drag_start(self, fx: float, fy: float, mode: str) -> None:
        """The pointer grabbed the frame at (fx, fy) (fractions of its size); mode "move" or "turn"."""
        grab = self.paper_point(fx, fy)
        self._drag = None
        if grab is not None and self.placement is not None:
            self._drag = (mode, grab, self.placement, self.last_shown.result.world_from_camera.copy())

    def drag_move(self, fx: float, fy: float) -> None:
        if self._drag is None:
            return
        mode, grab, start, pose = self._drag
        # the paper under the pointer in the view being shown (a live camera may move meanwhile)
        now = self.paper_point(fx, fy)
        if now is None:
            now = self.paper_point(fx, fy, pose)
        if now is not None:
            self.set_placement(dragged_placement(start, grab, now, mode))

    def drag_end(self) -> None:
        self._drag = None

    def scale_by(self, steps: float) -> None:
        """The wheel: each notch scales the model by 10 % (1 mm .. 1 m)."""
        if self.model is None or self.placement is None or steps == 0:
            return
        p = self.placement
        self.set_placement(replace(p, size_mm=float(np.clip(p.size_mm * 1.1 ** steps, 1.0, 1000.0))))

    # -- print preview and printing ----------------------------------------------------------
    def set_toolpaths(self, spec: dict | None) -> None:
        """Show the print preview `spec` (arapp.engine.toolpaths.preview_spec) on the bed; None clears it."""
        self.toolpaths_gen += 1
        ghost_before = self.toolpaths_spec is not None
        self.toolpaths_spec = None if spec is None else dict(spec)
        self.send(cmd.ShowToolpaths(self.toolpaths_spec, self.toolpaths_gen))
        if self.toolpaths_spec is not None and not ghost_before:
            self._unghost_gen = None
            self.send(cmd.SetMode(self.display_mode))
            self.status(GHOST_NOTE, 10000)
        elif self.toolpaths_spec is None and ghost_before:
            # solid again once the bed is cleared (the engine's toolpaths event), not a frame before
            self._unghost_gen = self.toolpaths_gen

    def _toolpaths_shown(self, info: dict) -> None:
        self.toolpaths_info = info
        if (self._unghost_gen is not None and self.toolpaths_spec is None
                and int(info.get("gen", -1)) >= self._unghost_gen):
            self._unghost_gen = None
            self.send(cmd.SetMode(self.display_mode))
        if self.print_session is not None and info.get("layers"):
            self.print_session.preview_shown(info)
        self.events.toolpaths_shown.emit(info)
        if info.get("outside"):
            self.status("Print preview: the part leaves the build area (drawn red on the bed)", 10000)

    def new_print_session(self, work_dir=None) -> PrintSession | None:
        """A print of the model as shown (edits and placement); the running one while a print runs;
        None (reported) without a model."""
        old = self.print_session
        if old is not None and old.printing:
            return old
        if self.model is None:
            self.report("Nothing to print", "Open a model first (Model panel or File > Open model)")
            return None
        ps = PrintSession(self.model, self.placement, runner=self.run, work_dir=work_dir)
        ps.events.preview_changed.connect(self.set_toolpaths)
        ps.events.error.connect(self.report)
        self.print_session = ps
        self.events.print_session.emit(ps)
        return ps
