"""The live view's worker threads: capture -> (tracking + rendering) -> paint, latest frame wins.

Two Python threads per open source, joined by `LatestSlot`s:

- `Player` opens the source, reads frames (paced at the recording's own
  timestamps times a speed factor, or as fast as a live camera delivers) and
  obeys play/pause/step/seek/loop. It never waits for the stages after it.
- `Processor` owns the `arapp.pipeline.Pipeline` (its tracker state and its GL
  context, which belong to the thread that made them), applies configuration
  commands between frames, processes the newest frame only, and wraps the
  composited BGR image in a QImage without copying it.

`Engine` is the QObject the UI talks to: it starts and stops the threads and
turns their events into Qt signals, which Qt delivers on the UI thread. The UI
thread only takes the newest `Shown` frame and paints it.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable

import cv2
import numpy as np
from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QImage

from arapp.gui.slots import LatestSlot


@dataclass
class Captured:
    """One frame as read: index and time (seconds) in the stream, BGR image, perf_counter() when read."""

    index: int
    t: float
    image: np.ndarray
    captured_at: float


@dataclass
class Shown:
    """A processed frame ready to paint: the pipeline's FrameResult, its QImage, the frame as captured
    (`frame`, BGR, before compositing) and the timing marks (perf_counter seconds)."""

    result: Any
    qimage: QImage
    frame: np.ndarray
    captured_at: float
    processed_at: float
    dropped_capture: int = 0
    dropped_paint: int = 0


@dataclass
class SourceInfo:
    """What the UI needs to know about an opened source."""

    name: str
    seekable: bool
    frame_count: int
    fps: float
    camera: Any
    anchors: list
    live: bool
    extra: dict = field(default_factory=dict)


def bgr_qimage(image: np.ndarray) -> QImage:
    """A (H, W, 3) uint8 BGR array as a QImage in the screen's native 32-bit format (B, G, R, 255 bytes:
    QImage.Format_RGB32 on little-endian machines), so painting it is a plain copy. The conversion is
    the caller's thread's work (a worker's); the QImage keeps its buffer alive."""
    if image.ndim == 2:
        bgra = cv2.cvtColor(image, cv2.COLOR_GRAY2BGRA)
    else:
        bgra = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    h, w = bgra.shape[:2]
    fmt = QImage.Format.Format_RGB32 if sys.byteorder == "little" else QImage.Format.Format_ARGB32
    if sys.byteorder != "little":
        bgra = np.ascontiguousarray(bgra[:, :, ::-1])  # big-endian: A, R, G, B bytes
    q = QImage(bgra.data, w, h, bgra.strides[0], fmt)
    q._keep = bgra  # the QImage points into the numpy buffer
    return q


LIVE_KINDS = ("v4l2", "depthai")
# Recordings are read continuously at their pace (decoding in parallel with processing) rather than on
# demand with seeks: OpenCV's seek in the recorder's MJPG/AVI files costs 50-150 ms here (it reopens and
# decodes forward), against ~13 ms for the next frame at 1280x720. Measured by benchmarks/bench_gui.py.
ON_DEMAND = False


def is_live(source) -> bool:
    """Cameras deliver at their own pace and cannot seek; files and recordings are paced by the player."""
    return getattr(source, "kind", "") in LIVE_KINDS


def is_seekable(source) -> bool:
    return not is_live(source) and hasattr(source, "seek") and int(getattr(source, "frame_count", 0) or 0) > 0


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


class Player(threading.Thread):
    """Capture thread: reads frames from a source into `out`, paced, with replay controls.

    `opener()` runs in this thread (opening a camera can take seconds) and
    returns the source. Callbacks run in this thread: on_open(source),
    on_error(title, message), on_end(), on_frame(Captured) (for a recorder).
    """

    def __init__(self, opener: Callable[[], Any], out: LatestSlot, *, speed: float = 1.0, loop: bool = False,
                 playing: bool = True, on_demand: bool = False, on_open=None, on_error=None, on_end=None,
                 name: str = "arapp-capture"):
        super().__init__(name=name, daemon=True)
        # on_demand: a recording is read when the consumer is ready for a frame, jumping straight to the
        # frame due at that moment, so frames that would be dropped are never decoded. Cameras are read
        # continuously (their drivers queue frames) and the slot drops the stale ones.
        self.on_demand = on_demand
        self._demanded = False
        self.skipped = 0  # frames jumped over (never decoded) because the consumer was busy
        if on_demand:
            out.on_wait = self._demand
        self.opener = opener
        self.out = out
        self.source = None
        self.on_open = on_open
        self.on_error = on_error
        self.on_end = on_end
        self.recorder = None  # object with .write(Captured), set while recording a live source
        self._cond = threading.Condition()
        self._playing = playing
        self._speed = float(speed)
        self._loop = bool(loop)
        self._steps = 0
        self._seek: int | None = None
        self._halt = False
        self._ref: tuple[float, float] | None = None  # (wall clock, stream time) the pacing counts from
        self._wrap_delay = 0.0
        self.seekable = False
        self.live = False
        self.frames_read = 0
        self.last_index = -1

    # -- commands (any thread) -------------------------------------------------------
    def _command(self, **changes) -> None:
        with self._cond:
            for k, v in changes.items():
                setattr(self, k, v)
            self._ref = None
            self._cond.notify_all()

    def play(self) -> None:
        self._command(_playing=True)

    def pause(self) -> None:
        self._command(_playing=False)

    @property
    def playing(self) -> bool:
        return self._playing

    def step(self, n: int = 1) -> None:
        """While paused, read the next n frames."""
        with self._cond:
            self._playing = False
            self._steps += n
            self._cond.notify_all()

    def seek(self, frame: int) -> None:
        self._command(_seek=int(frame))

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"replay speed must be positive, got {speed}")
        self._command(_speed=float(speed))

    def set_loop(self, loop: bool) -> None:
        self._command(_loop=bool(loop))

    def stop(self) -> None:
        self._command(_halt=True)

    def _demand(self) -> None:
        """The consumer waits for a frame (called from its thread)."""
        with self._cond:
            self._demanded = True
            self._cond.notify_all()

    def _wait_demand(self) -> bool:
        """Playing a recording on demand: block until the consumer wants a frame; False if a command came first."""
        with self._cond:
            ref = self._ref
            self._cond.wait_for(lambda: self._demanded or self._halt or not self._playing or self._seek is not None
                                or self._ref is not ref)
            return self._demanded and not self._halt and self._playing and self._seek is None

    def _due_index(self, next_index: int) -> int:
        """The newest frame whose time has come on the replay clock (at least next_index)."""
        with self._cond:
            if self._ref is None:
                return next_index
            wall0, t0 = self._ref
            t_due = t0 + (time.perf_counter() - wall0) * self._speed
        times = getattr(self.source, "times", None)
        n = int(self.source.frame_count)
        if times is not None and len(times) == n:
            due = int(np.searchsorted(np.asarray(times), t_due + 1e-9, side="right")) - 1
        else:
            due = int(np.floor(t_due * float(getattr(self.source, "fps", 30.0) or 30.0) + 1e-9))
        return max(next_index, min(due, n - 1))

    # -- thread body -------------------------------------------------------------------
    def run(self) -> None:
        try:
            self.source = self.opener()
            self.seekable = is_seekable(self.source)
            self.live = is_live(self.source)
            it = iter(self.source)
            first = None
            if self.live:
                # a camera may refine its calibration from the first frame it delivers
                first = next(it, None)
                if first is None:
                    raise RuntimeError(getattr(self.source, "error", None) or "the camera delivered no frame")
            if self.on_open is not None:
                self.on_open(self.source)
        except Exception as exc:  # noqa: BLE001 - every failure to open becomes a dialog, never a crash
            self._fail("Cannot open source", exc)
            self._close_source()
            return
        try:
            self._loop_frames(it, first)
        except Exception as exc:  # noqa: BLE001
            self._fail("Camera lost" if not self.seekable else "Cannot read the recording", exc)
        finally:
            self._close_source()

    def _fail(self, title: str, exc: BaseException) -> None:
        if self.on_error is not None:
            self.on_error(title, str(exc) or type(exc).__name__)
        else:
            traceback.print_exception(exc)

    def _close_source(self) -> None:
        if self.recorder is not None:
            try:
                self.recorder.close()
            except Exception as exc:  # noqa: BLE001
                self._fail("Recording failed", exc)
            self.recorder = None
        if self.source is not None:
            try:
                self.source.close()
            except Exception:  # noqa: BLE001 - closing a dead camera may fail; nothing left to do
                pass

    def _wait_for_work(self) -> tuple[bool, int | None, bool]:
        """Block until playing, a step, a seek or stop; return (stop, seek, is_step)."""
        with self._cond:
            self._cond.wait_for(lambda: self._halt or self._playing or self._steps > 0 or self._seek is not None)
            if self._halt:
                return True, None, False
            seek, self._seek = self._seek, None
            is_step = False
            if not self._playing and seek is None:
                self._steps -= 1
                is_step = True
            return False, seek, is_step

    def _pace(self, t: float) -> bool:
        """Sleep until stream time t is due at the current speed (interruptible); False when told to stop."""
        with self._cond:
            now = time.perf_counter()
            if self._ref is None:
                # a new clock: after a loop wraps, the first frame still waits one frame interval
                self._ref = (now + self._wrap_delay, t)
                self._wrap_delay = 0.0
            wall0, t0 = self._ref
            due = wall0 + (t - t0) / self._speed
            if due < now - 0.25:
                # Far behind (slow disk, a stall): restart the clock rather than burst through frames.
                self._ref = (now, t)
                return not self._halt
            while not self._halt and self._ref is not None:
                left = due - time.perf_counter()
                if left <= 0:
                    break
                self._cond.wait(left)
            return not self._halt

    def _loop_frames(self, it, first=None) -> None:
        while True:
            stop, seek, is_step = self._wait_for_work()
            if stop:
                return
            if seek is not None and self.seekable:
                seek = max(0, min(seek, int(self.source.frame_count) - 1))
                self.source.seek(frame=seek)
                it = iter(self.source)
                self.last_index = seek - 1
                if not self._playing:
                    with self._cond:
                        self._steps = max(self._steps, 1)  # show the frame sought to
                continue
            if (self._playing and not is_step and self.seekable and self.on_demand and first is None):
                if not self._wait_demand():
                    continue
                nxt = self.last_index + 1
                due = self._due_index(nxt)
                if due > nxt:
                    self.source.seek(frame=due)
                    it = iter(self.source)
                    self.skipped += due - nxt
            try:
                with self._cond:
                    self._demanded = False
                if first is not None:
                    frame, first = first, None
                else:
                    frame = next(it)
            except StopIteration:
                error = getattr(self.source, "error", None)
                if error:
                    title = "Camera lost" if self.live else "The recording is damaged"
                    self._fail(title, error if isinstance(error, BaseException) else RuntimeError(str(error)))
                    if self.live:
                        return
                if self.seekable and self._loop and not error:
                    self.source.seek(frame=0)
                    it = iter(self.source)
                    self.last_index = -1
                    with self._cond:
                        self._ref = None
                        fps = float(getattr(self.source, "fps", 0) or 30.0)
                        self._wrap_delay = 1.0 / (fps * self._speed)
                    continue
                if self.live:
                    raise RuntimeError("the camera stopped delivering frames")
                with self._cond:
                    self._playing = False
                    self._steps = 0
                if self.on_end is not None:
                    self.on_end()
                continue
            if self._playing and not self.live and not is_step and not self._pace(float(frame.t)):
                return
            item = Captured(int(frame.index), float(frame.t), frame.image, time.perf_counter())
            self.frames_read += 1
            self.last_index = item.index
            if self.recorder is not None:
                self.recorder.write(item)
            self.out.put(item)


def redraw(pipeline, item: Captured, last):
    """Composite the pipeline's current model over `item` at the pose `last` (a FrameResult) found for it.

    The draw half of `Pipeline.process` without tracking: settings changed
    while paused show at once, and the tracker never sees a frame twice.
    """
    from dataclasses import replace

    out = pipeline.draw_overlay(item.image, last.world_from_camera) if pipeline.draw else item.image
    return replace(last, image=out)


def mark_control_point(image: np.ndarray, pipeline, world_from_camera, k: int, i: int, j: int) -> np.ndarray:
    """A copy of `image` with control point (i, j) of surface k of the shown model ringed, where the pipeline
    places the model (display only: the composite in FrameResult stays as the pipeline made it)."""
    model = getattr(pipeline, "model", None)
    if model is None or world_from_camera is None or not getattr(model, "surfaces", None):
        return image
    from tracking.poses import invert

    p_model = np.append(np.asarray(model.surfaces[k].control_points[i, j], float), 1.0)
    p_cam = (invert(world_from_camera) @ pipeline.world_from_model @ p_model)[:3]
    if p_cam[2] <= 1e-3:
        return image
    uv = pipeline.camera.project(p_cam[None, :]).reshape(-1)
    if not np.all(np.isfinite(uv)):
        return image
    out = image.copy()
    c = (int(round(uv[0] * 4)), int(round(uv[1] * 4)))
    r = max(6, image.shape[0] // 80)
    cv2.circle(out, c, r * 4, (0, 0, 0), 4, cv2.LINE_AA, shift=2)
    cv2.circle(out, c, r * 4, (0, 240, 255), 2, cv2.LINE_AA, shift=2)
    cv2.circle(out, c, 8, (0, 240, 255), -1, cv2.LINE_AA, shift=2)
    return out


class Processor(threading.Thread):
    """Processing thread: newest captured frame -> pipeline.process -> QImage into `out`.

    `make_pipeline()` runs in this thread so the renderer's GL context belongs
    to it. Configuration arrives as callables via `submit(fn)`, each called as
    fn(pipeline) between frames; after one, the last frame is processed again
    so a change shows while replay is paused.
    """

    def __init__(self, make_pipeline: Callable[[], Any], inbox: LatestSlot, out: LatestSlot, *,
                 on_ready=None, on_error=None, skipped: Callable[[], int] | None = None,
                 name: str = "arapp-process"):
        super().__init__(name=name, daemon=True)
        self.skipped = skipped or (lambda: 0)
        self.highlight: tuple[int, int, int] | None = None  # (surface, i, j) control point marked on screen
        # (width, height) the view shows the frame at; the image is scaled here, off the UI thread,
        # so painting is a 1:1 copy. None: full size.
        self.display_size: tuple[int, int] | None = None
        self.make_pipeline = make_pipeline
        self.inbox = inbox
        self.out = out
        self.on_ready = on_ready
        self.on_error = on_error
        self.pipeline = None
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self._halt = threading.Event()
        self._last: tuple[Captured, Any] | None = None
        self.processed = 0

    def submit(self, fn: Callable[[Any], None]) -> None:
        self._commands.put(fn)
        self.inbox.wake()

    def _qimage(self, image: np.ndarray) -> QImage:
        size = self.display_size
        h, w = image.shape[:2]
        if size is not None:
            s = min(size[0] / w, size[1] / h)
            tw, th = max(1, int(round(w * s))), max(1, int(round(h * s)))
            if (tw, th) != (w, h) and s < 1.0:
                image = cv2.resize(image, (tw, th), interpolation=cv2.INTER_AREA)
            elif (tw, th) != (w, h):
                image = cv2.resize(image, (tw, th), interpolation=cv2.INTER_LINEAR)
        return bgr_qimage(image)

    def stop(self) -> None:
        self._halt.set()
        self.inbox.wake()

    def _apply_commands(self) -> bool:
        changed = False
        while True:
            try:
                fn = self._commands.get_nowait()
            except queue.Empty:
                return changed
            try:
                fn(self.pipeline)
                changed = True
            except Exception as exc:  # noqa: BLE001 - a bad setting is reported, the view keeps running
                self._report("Cannot apply the change", exc)

    def _report(self, title: str, exc: BaseException) -> None:
        if self.on_error is not None:
            self.on_error(title, str(exc) or type(exc).__name__)
        else:
            traceback.print_exception(exc)

    def run(self) -> None:
        try:
            self.pipeline = self.make_pipeline()
        except Exception as exc:  # noqa: BLE001
            self._report("Cannot start tracking and rendering", exc)
            return
        try:
            while not self._halt.is_set():
                item = self.inbox.take(timeout=0.5)
                changed = self._apply_commands()
                if self._halt.is_set():
                    break
                try:
                    if item is None:
                        if not changed or self._last is None:
                            continue
                        # Paused: draw the last frame again with the new settings, without tracking it twice.
                        item, last_result = self._last
                        result = redraw(self.pipeline, item, last_result)
                    else:
                        result = self.pipeline.process(item.image, item.t, item.index)
                except Exception as exc:  # noqa: BLE001 - one bad frame must not end the view
                    self._report("Tracking or rendering failed", exc)
                    continue
                self._last = (item, result)
                self.processed += 1
                shown_image = result.image
                if self.highlight is not None:
                    try:
                        shown_image = mark_control_point(shown_image, self.pipeline, result.world_from_camera,
                                                         *self.highlight)
                    except (IndexError, ValueError, AttributeError):
                        pass  # a stale selection (model changed meanwhile): draw nothing
                shown = Shown(result, self._qimage(shown_image), item.image, item.captured_at,
                              time.perf_counter(), dropped_capture=self.inbox.dropped + self.skipped())
                self.out.put(shown)
                if self.on_ready is not None:
                    self.on_ready()
        finally:
            try:
                self.pipeline.close()
            except Exception:  # noqa: BLE001 - shutting down; a GL teardown error changes nothing
                pass


class ProcessingStage:
    """Where an engine keeps its Processor, which exists only once the source is open. Commands
    submitted before then wait and are handed over in order; the view's settings (display size,
    ringed control point) are kept and given to the processor when it starts. Used by both engines
    (threads here, the child process in remote.py); any thread."""

    def __init__(self, display_size: tuple[int, int] | None = None):
        self._lock = threading.Lock()
        self._pending: list = []
        self.processor: Processor | None = None
        self.display_size = display_size
        self.highlight: tuple[int, int, int] | None = None

    def start(self, processor: Processor) -> None:
        """Hand over the queued commands and settings, then start the processing thread."""
        processor.display_size = self.display_size
        processor.highlight = self.highlight
        with self._lock:
            self.processor = processor
            for fn in self._pending:
                processor.submit(fn)
            self._pending.clear()
        processor.start()

    def submit(self, fn: Callable[[Any], None]) -> None:
        """Run fn(pipeline) in the processing thread between frames (queued until it exists)."""
        with self._lock:
            if self.processor is None:
                self._pending.append(fn)
                return
            processor = self.processor
        processor.submit(fn)

    def set_display_size(self, size: tuple[int, int] | None) -> None:
        self.display_size = size
        with self._lock:
            if self.processor is not None:
                self.processor.display_size = size

    def set_highlight(self, point: tuple[int, int, int] | None) -> None:
        self.highlight = point
        with self._lock:
            processor = self.processor
        if processor is not None:
            processor.highlight = point
            processor.submit(lambda p: None)  # redraw a paused frame

    def current(self) -> Processor | None:
        with self._lock:
            return self.processor

    def is_alive(self) -> bool:
        processor = self.current()
        return processor is not None and processor.is_alive()


class Engine(QObject):
    """One open source with its two worker threads, seen from the UI thread through signals.

    Signals (delivered on the UI thread): opened(SourceInfo), frame_ready(),
    error(title, message), ended() when a recording reaches its end without loop.
    """

    opened = Signal(object)
    frame_ready = Signal()
    error = Signal(str, str)
    ended = Signal()
    recorded = Signal(str)
    toolpaths_shown = Signal(object)

    def __init__(self, opener: Callable[[], Any], pipeline_factory: Callable[[Any, SourceInfo], Any], *,
                 name: str = "", default_anchors: list | None = None, speed: float = 1.0, loop: bool = False,
                 playing: bool = True, on_demand: bool = ON_DEMAND, parent: QObject | None = None):
        super().__init__(parent)
        self.name = name
        self.default_anchors = default_anchors
        self.pipeline_factory = pipeline_factory
        self.captured = LatestSlot()
        self.shown = LatestSlot()
        self.info: SourceInfo | None = None
        self._notify_pending = threading.Event()
        self.stage = ProcessingStage()
        # A recording starts with its first frame only, and plays once that frame is on its way to the
        # screen: otherwise it would run ahead while the pipeline starts up (GL, tracker), and those
        # frames would be dropped unseen.
        self._autoplay = playing
        self._first_ready = False
        self.model_state = {"mesh_faces": 0, "model_gen": 0, "mode": "shaded", "resets": 0, "toolpaths": None}
        self.player = Player(opener, self.captured, speed=speed, loop=loop, playing=False, on_demand=on_demand,
                             on_open=self._on_open, on_error=self.error.emit, on_end=self.ended.emit)
        self.player._steps = 1
        self._toolpaths = None  # arapp.gui.toolpaths.ToolpathStage, made on the first preview request

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        self.player.start()

    def _on_open(self, source) -> None:
        """Runs in the capture thread once the source is open: start the processing thread."""
        info = source_info(source, self.name, self.default_anchors)
        self.info = info
        if info.camera is None:
            raise RuntimeError(f"{self.name}: the source has no camera calibration; tracking needs one")
        if not info.anchors:
            raise RuntimeError(f"{self.name}: no anchors are configured; set them in the tracking panel")
        processor = Processor(lambda: self.pipeline_factory(source, info), self.captured, self.shown,
                              on_ready=self._on_ready, on_error=self.error.emit,
                              skipped=lambda: self.player.skipped)
        self.stage.start(processor)
        if info.live and self._autoplay:
            self.player.play()  # a camera does not wait
        self.opened.emit(info)

    def _on_ready(self) -> None:
        if not self._first_ready:
            self._first_ready = True
            if self._autoplay:
                self.player.play()
        if not self._notify_pending.is_set():
            self._notify_pending.set()
            self.frame_ready.emit()

    def stop(self, wait: float = 0.0) -> None:
        """Ask both threads to finish (they close the source and the pipeline themselves); optionally join."""
        self.player.stop()
        if self._toolpaths is not None:
            self._toolpaths.stop()
        processor = self.stage.current()
        if processor is not None:
            processor.stop()
        if wait > 0:
            deadline = time.perf_counter() + wait
            self.player.join(max(0.0, deadline - time.perf_counter()))
            if processor is not None:
                processor.join(max(0.0, deadline - time.perf_counter()))

    @property
    def running(self) -> bool:
        return self.player.is_alive() or self.stage.is_alive()

    # -- UI side -----------------------------------------------------------------------
    def take(self) -> Shown | None:
        """The newest processed frame (None when nothing new); call from the UI thread on frame_ready."""
        self._notify_pending.clear()
        shown = self.shown.take()
        if shown is not None:
            shown.dropped_paint = self.shown.dropped
            if isinstance(getattr(shown.result, "extra", None), dict):
                shown.result.extra.update(self.model_state)
        return shown

    def set_display_size(self, width: int, height: int) -> None:
        """The size the view paints frames at (device pixels); frames are scaled to fit it in the worker."""
        self.stage.set_display_size((int(width), int(height)))

    def submit(self, fn: Callable[[Any], None]) -> None:
        """Run fn(pipeline) in the processing thread between frames (queued until the pipeline exists)."""
        self.stage.submit(fn)

    # the same commands as remote.RemoteEngine ------------------------------------------------
    def set_model(self, gen: int, path: str | None, edits: dict, placement: dict | None, mode: str,
                  model=None) -> None:
        """Show `model` (already loaded and edited by the caller) as placed; `gen` numbers the request."""

        def apply(p):
            p.set_mode(mode)
            p.set_model(model, placement)
            self.model_state.update(mode=mode, model_gen=gen,
                                    mesh_faces=0 if p.mesh is None else int(len(p.mesh.faces)))

        self.submit(apply)

    def set_placement(self, placement: dict) -> None:
        self.submit(lambda p, pl=dict(placement): p.set_placement(pl))

    def set_highlight(self, point: tuple[int, int, int] | None) -> None:
        """Ring control point (surface, i, j) of the shown model on screen; None: no ring."""
        self.stage.set_highlight(point)

    def set_mode(self, mode: str) -> None:
        def apply(p):
            p.set_mode(mode)
            self.model_state["mode"] = mode

        self.submit(apply)

    def set_toolpaths(self, spec: dict | None, gen: int = 0) -> None:
        """Show the print preview `spec` (arapp.gui.toolpaths.preview_spec) on the bed; None clears it.
        Built in a worker thread; `toolpaths_shown(info)` follows once drawn."""
        if self._toolpaths is None:
            from arapp.gui.toolpaths import ToolpathStage

            def shown(info):
                self.model_state["toolpaths"] = info
                self.toolpaths_shown.emit(info)

            self._toolpaths = ToolpathStage(self.submit, shown, self.error.emit)
        self._toolpaths.request(spec, gen=gen)

    def reset(self) -> None:
        def apply(p):
            p.reset()
            self.model_state["resets"] += 1

        self.submit(apply)

    def record_start(self, folder) -> None:
        from arapp.gui import recording

        try:
            self.player.recorder = recording.start(folder, self.info, self.player.source)
        except (ValueError, OSError, RuntimeError) as exc:
            self.error.emit("Cannot record", str(exc))

    def record_stop(self) -> None:
        rec, self.player.recorder = self.player.recorder, None
        if rec is None:
            return

        def finish():
            try:
                rec.close()
            except Exception as exc:  # noqa: BLE001
                self.error.emit("Recording failed", str(exc))
                return
            self.recorded.emit(str(rec.folder))

        threading.Thread(target=finish, name="arapp-record-close", daemon=True).start()

    # replay controls, forwarded to the capture thread
    def play(self) -> None:
        self._autoplay = True
        self.player.play()

    def pause(self) -> None:
        self._autoplay = False
        self.player.pause()

    def step(self, n: int = 1) -> None:
        self._autoplay = False
        self.player.step(n)

    def seek(self, frame: int) -> None:
        self.player.seek(frame)

    def set_speed(self, speed: float) -> None:
        self.player.set_speed(speed)

    def set_loop(self, loop: bool) -> None:
        self.player.set_loop(loop)

    @property
    def playing(self) -> bool:
        """Playing, or about to play once the first frame is processed."""
        return self.player.playing or (self._autoplay and not self._first_ready)
