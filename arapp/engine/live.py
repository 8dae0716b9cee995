"""The live engine: one open source with its capture and processing threads, joined latest-frame-wins. No Qt.

    source --Player--> LatestSlot --Processor (Pipeline: track + draw)--> LatestSlot --> take()

`LiveEngine` starts and stops the threads and applies `arapp.engine.commands`.
Its `events` are emitted from the worker threads: `opened(SourceInfo)`,
`ready()` (a new frame waits in `take()`), `error(title, message)`,
`ended()` (a recording reached its end without loop), `recorded(folder)`,
`toolpaths(info)` (a print preview is drawn). The GUI's thread engine turns
them into Qt signals; its child process sends them over a pipe; a headless
driver (arapp.engine.headless) queues them for its own thread.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from arapp.engine import recording
from arapp.engine.capture import ArVideoWriter
from arapp.engine.discovery import DiscoveryStage
from arapp.engine.editing import edited_model, model_mesh
from arapp.engine.events import Events
from arapp.engine.player import ON_DEMAND, Player
from arapp.engine.processor import ProcessingStage, Processor, Shown
from arapp.engine.slots import LatestSlot
from arapp.engine.sourcespec import DEFAULT_ANCHORS, display_name, is_live, is_seekable, open_spec
from arapp.engine.toolpaths import ToolpathStage
from arapp.engine.pipeline import Pipeline, load_display_model
from tracking.recording.schema import parse_anchors


@dataclass
class SourceInfo:
    """What the app needs to know about an opened source: its name, whether it seeks (a recording) and
    its frame count and rate, the camera (tracking.camera.Camera), the anchors tracked (AnchorSpec list),
    whether it is live (a camera)."""

    name: str
    seekable: bool
    frame_count: int
    fps: float
    camera: Any
    anchors: list
    live: bool
    extra: dict = field(default_factory=dict)


def source_info(source, name: str, default_anchors: list | None = None) -> SourceInfo:
    """Describe an opened source. Raises (with the source's own message) when it has no calibration."""
    seekable = is_seekable(source)
    frame_count = int(getattr(source, "frame_count", 0) or 0)
    session = getattr(source, "session", None)
    anchors = list(getattr(session, "anchors", None) or default_anchors or [])
    fps = float(getattr(source, "fps", 0.0) or 0.0)
    camera = source.camera  # tracking.sources raises SourceError naming the missing calibration
    return SourceInfo(name=name, seekable=seekable, frame_count=frame_count if seekable else 0, fps=fps,
                      camera=camera, anchors=anchors, live=is_live(source))


def default_pipeline(source, info: SourceInfo) -> Pipeline:
    """The live view's pipeline: tracking and drawing, no status line (the app shows the state itself);
    the model arrives later as a command. The tracker leaves its keypoint upkeep for after each frame is
    shown (`TrackerConfig.defer_upkeep`; the processing thread runs it: `Processor._idle`)."""
    return Pipeline(info.camera, info.anchors, status_line=False, tracker_params={"defer_upkeep": True})


def _are_default(anchors: list) -> bool:
    """Whether `anchors` are the app's default board (the why line then says none were chosen)."""
    return [a.to_dict() for a in anchors] == [a.to_dict() for a in parse_anchors(DEFAULT_ANCHORS)]


class TappedSlot(LatestSlot):
    """A LatestSlot that also hands each item put into it to `tap` (the AR video writer), in the putting
    thread, before the UI may drop it: the video keeps frames the screen skipped."""

    tap: Callable[[Any], None] | None = None

    def put(self, item) -> bool:
        tap = self.tap
        if tap is not None:
            tap(item)
        return super().put(item)


class EngineFacade:
    """The engine interface `Session` uses (`send`, `start`, `stop`, `take`, `running`, `playing`), over a
    LiveEngine in `self.live` (the headless and the GUI's thread engine share it)."""

    live: "LiveEngine"

    def send(self, command) -> None:
        """Apply an arapp.engine.commands command (the threads pick it up between frames)."""
        self.live.apply(command)

    def start(self) -> None:
        self.live.start()

    def stop(self, wait: float = 0.0) -> None:
        self.live.stop(wait)

    def take(self):
        return self.live.take()

    @property
    def running(self) -> bool:
        return self.live.running

    @property
    def playing(self) -> bool:
        return self.live.playing


class LiveEngine:
    """One open source, its Player and Processor threads, and the commands that steer them.

    spec: the source spec (arapp.engine.sourcespec), or `opener()` returning an
    open source; anchors: AnchorSpecs tracked when the source names none;
    `pipeline_factory(source, info)` makes the pipeline in the processing
    thread; `wrap(bgra)` runs there on each picture (the GUI's QImage); `display_buffer(shape)` gives
    the array each picture is written into (None: a new one; arapp.engine.processor.Processor).
    A recording starts with its first frame only, and plays once that frame is
    on its way to the screen: otherwise it would run ahead while the pipeline
    starts up (GL, tracker), and those frames would be dropped unseen.
    """

    def __init__(self, spec: str | None = None, *, opener: Callable[[], Any] | None = None, name: str = "",
                 anchors: list | None = None, speed: float = 1.0, loop: bool = False, playing: bool = True,
                 display_size: tuple[int, int] | None = None, on_demand: bool = ON_DEMAND,
                 pipeline_factory: Callable[[Any, SourceInfo], Any] = default_pipeline,
                 wrap: Callable[[np.ndarray], Any] | None = None,
                 display_buffer: Callable[[tuple], Any] | None = None):
        if opener is None and spec is None:
            raise ValueError("LiveEngine needs a source spec or an opener")
        self.spec = spec
        self.name = name or (display_name(spec) if spec else "source")
        self.default_anchors = list(anchors or [])
        self.pipeline_factory = pipeline_factory
        self.wrap = wrap
        self.display_buffer = display_buffer
        self.events = Events("opened", "ready", "error", "ended", "recorded", "toolpaths")
        self.captured, self.shown = LatestSlot(), TappedSlot()
        self.ar_video: ArVideoWriter | None = None
        self._ar_closing: threading.Thread | None = None  # finishing the AR video file
        self.stage = ProcessingStage(display_size)
        self.info: SourceInfo | None = None
        self.autoplay = playing
        self.first_ready = False
        # stop() and the source's opening meet here: a source that opens after stop() (a camera answering
        # after the session gave up on it) starts no processing thread that nothing would stop
        self._life = threading.Lock()
        self._stopped = False
        # the processing side's view of the model, copied into each frame's `extra`
        # `discovery`: what anchor discovery found while the anchors gave no pose (discovery.offer_dict)
        self.state = {"mesh_faces": 0, "model_gen": 0, "mode": "shaded", "resets": 0, "toolpaths": None,
                      "discovery": None}
        self.discovery: DiscoveryStage | None = None
        self._models: dict = {}  # path -> the model as loaded (SetModel without a model object)
        self._toolpaths: ToolpathStage | None = None
        self._toolpaths_lock = threading.Lock()
        self.player = Player(opener or (lambda: open_spec(spec)), self.captured, speed=speed, loop=loop,
                             playing=False, on_demand=on_demand, on_open=self._opened,
                             on_error=self.events.error.emit, on_end=self._ended)
        self.player._steps = 1  # the first frame, before play

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        self.player.start()

    def _opened(self, source) -> None:
        """Capture thread, once the source is open: describe it and start the processing thread."""
        with self._life:
            if self._stopped:
                return  # the player sees its stop next and closes the source
            info = source_info(source, self.name, self.default_anchors)
            if info.camera is None:
                raise RuntimeError(f"{self.name}: the source has no camera calibration; tracking needs one")
            if not info.anchors:
                raise RuntimeError(f"{self.name}: no anchors are configured; set them in the tracking panel")
            self.info = info
            processor = Processor(lambda: self.pipeline_factory(source, info), self.captured, self.shown,
                                  on_ready=self._ready, on_error=self.events.error.emit,
                                  skipped=lambda: self.player.skipped, wrap=self.wrap,
                                  display_buffer=self.display_buffer)
            self.discovery = DiscoveryStage(info.anchors, self._discovered,
                                            default_anchors=_are_default(info.anchors),
                                            offer=not getattr(getattr(source, "session", None), "anchors", None))
            processor.watch = self.discovery.observe
            self.stage.start(processor)
        if info.live and self.autoplay:
            self.player.play()  # a camera does not wait
        self.events.opened.emit(info)

    def _ended(self) -> None:
        """Capture thread: the recording reached its end (no loop). A clip too short for anchor discovery to
        have looked at it, and never tracked, gets its last frame looked at now."""
        if self.discovery is not None:
            self.discovery.at_end()
        self.events.ended.emit()

    def _ready(self) -> None:
        if not self.first_ready:
            self.first_ready = True
            if self.autoplay:
                self.player.play()
        self.events.ready.emit()

    def stop(self, wait: float = 0.0) -> None:
        """Ask both threads to finish (they close the source and the pipeline themselves); optionally join.
        An AR video being written is finished first (an MP4 cut off before its index cannot be played)."""
        with self._life:
            self._stopped = True
        if self.ar_video is not None:
            self.ar_record_stop()
        closing = self._ar_closing
        if closing is not None:
            closing.join(10.0)
        self.player.stop()
        self.end_discovery()
        with self._toolpaths_lock:
            if self._toolpaths is not None:
                self._toolpaths.stop()
        processor = self.stage.current()
        if processor is not None:
            processor.stop()
        self.shown.wake()
        if wait > 0:
            deadline = time.perf_counter() + wait
            if self.player.is_alive() or self.player.ident is not None:
                self.player.join(max(0.0, deadline - time.perf_counter()))
            if processor is not None:
                processor.join(max(0.0, deadline - time.perf_counter()))

    @property
    def running(self) -> bool:
        return self.player.is_alive() or self.stage.is_alive()

    @property
    def playing(self) -> bool:
        """Playing, or about to play once the first frame is processed."""
        return self.player.playing or (self.autoplay and not self.first_ready)

    # -- frames --------------------------------------------------------------------------
    def take(self, timeout: float | None = 0.0) -> Shown | None:
        """The newest processed frame (None when nothing new within `timeout` s), its `result.extra` holding
        the processing side's model state."""
        shown = self.shown.take(timeout=timeout)
        if shown is not None:
            shown.dropped_paint = self.shown.dropped
            if isinstance(getattr(shown.result, "extra", None), dict):
                shown.result.extra.update(self.state)
        return shown

    # -- commands ------------------------------------------------------------------------
    def apply(self, command) -> None:
        """Apply an `arapp.engine.commands` command (any thread)."""
        command.apply(self)

    def submit(self, fn: Callable[[Any], None]) -> None:
        """Run fn(pipeline) in the processing thread between frames (queued until the pipeline exists)."""
        self.stage.submit(fn)

    def _discovered(self, offer: dict) -> None:
        """Discovery's thread: a new finding, carried to the app model with the next frame shown; while
        playback stands still (the end of a recording) the last frame is shown again to carry it."""
        self.state["discovery"] = offer
        processor = self.stage.current()
        if processor is not None and not self.player.playing:
            processor.show_again()

    def end_discovery(self) -> None:
        """Stop anchor discovery (its offer was answered, or the engine stops)."""
        if self.discovery is not None:
            self.discovery.finish()

    def load(self, path: str, edits: dict):
        """The model file at `path` (loaded once) with control-point `edits` applied, tessellated here (in
        the caller's thread, not between frames)."""
        base = self._models.get(path)
        if base is None:
            base = self._models[path] = load_display_model(path)
        model = edited_model(base, edits) if edits else base
        model_mesh(model)
        return model

    def toolpath_stage(self) -> ToolpathStage:
        """The print preview's builder thread, started on the first request."""
        with self._toolpaths_lock:
            if self._toolpaths is None:
                self._toolpaths = ToolpathStage(self.submit, self._toolpaths_shown, self.events.error.emit)
            return self._toolpaths

    def _toolpaths_shown(self, info: dict) -> None:
        """Pipeline thread: the print preview `info` is drawn from the next frame on."""
        self.state["toolpaths"] = info
        self.events.toolpaths.emit(info)

    def record_start(self, folder) -> None:
        try:
            self.player.recorder = recording.start(folder, self.info, self.player.source)
        except (ValueError, OSError, RuntimeError, AttributeError) as exc:
            self.events.error.emit("Cannot record", str(exc))

    def record_stop(self) -> None:
        """Finish the files in a thread of their own (a long video takes a moment); `recorded` follows."""
        rec, self.player.recorder = self.player.recorder, None
        if rec is None:
            return

        def finish():
            try:
                rec.close()
            except Exception as exc:  # noqa: BLE001 - told to the user; the view goes on
                self.events.error.emit("Recording failed", str(exc))
                return
            self.events.recorded.emit(str(rec.folder))

        threading.Thread(target=finish, name="arapp-record-close", daemon=True).start()

    def ar_record_start(self, path: str) -> None:
        """Record the composited view (camera + model as drawn) to the video file `path` (.mp4 or .avi)."""
        if self.ar_video is not None:
            return
        try:
            fps = self.info.fps if self.info is not None and self.info.fps > 0 else 30.0
            self.ar_video = ArVideoWriter(path, fps)
        except (ValueError, OSError) as exc:
            self.events.error.emit("Cannot record the AR video", str(exc))
            return
        self.shown.tap = self.ar_video.write

    def ar_record_stop(self) -> None:
        """Finish the AR video in a thread of its own; `recorded(path)` follows."""
        writer, self.ar_video = self.ar_video, None
        self.shown.tap = None
        if writer is None:
            return

        def finish():
            try:
                path = writer.close()
            except Exception as exc:  # noqa: BLE001 - told to the user; the view goes on
                self.events.error.emit("AR video failed", str(exc))
                return
            self.events.recorded.emit(str(path))

        self._ar_closing = threading.Thread(target=finish, name="arapp-ar-video-close", daemon=True)
        self._ar_closing.start()
