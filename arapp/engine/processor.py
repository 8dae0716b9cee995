"""The processing thread of the live engine: newest captured frame -> pipeline -> picture to paint. No Qt.

`Processor` owns the `arapp.engine.pipeline.Pipeline` (its tracker state and its GL
context belong to the thread that made them), applies configuration commands
between frames, processes the newest frame only and makes the picture to paint:
the frame scaled to the view's size in the screen's 32-bit layout (B, G, R, 255
bytes), so the UI thread only copies it. A side thread scales the frame as
captured while this one tracks and draws it; the marker marks and then the
model's rendered crop are laid on it (`_picture`). Once the picture is out, the
pipeline's deferred work runs (`Pipeline.idle`) before the next frame is taken.
`ProcessingStage` holds the processor of an engine, which exists only once the
source is open.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import cv2
import numpy as np

from arapp.engine.overlay_marks import draw_marks, marker_marks, under_opacity
from arapp.engine.player import Captured
from arapp.engine.slots import LatestSlot
from arapp.render import composite
from tracking.poses import invert


@dataclass
class Shown:
    """A processed frame ready to paint: the pipeline's FrameResult, the display picture (`display`: BGRA
    uint8, scaled to the view; `qimage`: the GUI's QImage over it, None headless), the frame as captured
    (`frame`, BGR, before compositing) and the timing marks (perf_counter seconds)."""

    result: Any
    display: np.ndarray
    frame: np.ndarray
    captured_at: float
    processed_at: float
    dropped_capture: int = 0
    dropped_paint: int = 0
    qimage: Any = None
    marks: bool = False  # drawn with the marker marks on (View > Show detected markers; outlines where there is a pose)
    # timing marks between captured_at and processed_at and after (perf_counter seconds, one clock for the
    # UI and the pipeline process on Linux): "start" (processing began), "composited" (tracked and drawn);
    # the GUI engines add "sent" and "received" (the child process's hand-over) and "taken" (by the UI)
    stages: dict = field(default_factory=dict)


def to_bgra(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """A (H, W, 3) BGR or (H, W) grey uint8 array as (H, W, 4) in the screen's native 32-bit order
    (B, G, R, 255 bytes on little-endian machines; A, R, G, B on big-endian), so painting is a copy.
    `out`: an (H, W, 4) uint8 array to write it into (a shared-memory slot), returned."""
    code = cv2.COLOR_GRAY2BGRA if image.ndim == 2 else cv2.COLOR_BGR2BGRA
    if sys.byteorder != "little":
        bgra = np.ascontiguousarray(cv2.cvtColor(image, code)[:, :, ::-1])
        if out is None:
            return bgra
        np.copyto(out, bgra)
        return out
    if out is None:
        return cv2.cvtColor(image, code)
    cv2.cvtColor(image, code, dst=out)
    return out


def fit_to(image: np.ndarray, size: tuple[int, int] | None) -> np.ndarray:
    """`image` scaled to fit `size` (width, height, device pixels) with its aspect kept; None: as it is.

    Bilinear down to half size: a window a little smaller than the frame costs about 1 ms a 720p frame
    that way, where INTER_AREA's non-integer path takes 3 ms on an idle 2-core machine and several times
    that under load; below half size bilinear would skip pixels, so INTER_AREA averages them."""
    if size is None:
        return image
    h, w = image.shape[:2]
    s = min(size[0] / w, size[1] / h)
    tw, th = max(1, int(round(w * s))), max(1, int(round(h * s)))
    if (tw, th) == (w, h):
        return image
    return cv2.resize(image, (tw, th), interpolation=cv2.INTER_AREA if s < 0.5 else cv2.INTER_LINEAR)


def redraw(pipeline, item: Captured, last):
    """Composite the pipeline's current model over `item` at the pose `last` (a FrameResult) found for it.

    The draw half of `Pipeline.process` without tracking: settings changed
    while paused show at once, and the tracker never sees a frame twice.
    """
    out = pipeline.draw_overlay(item.image, last.world_from_camera, item.depth) if pipeline.draw else item.image
    return replace(last, image=out)


def mark_control_point(image: np.ndarray, pipeline, world_from_camera, k: int, i: int, j: int) -> np.ndarray:
    """A copy of `image` with control point (i, j) of surface k of the shown model ringed, where the pipeline
    places the model (display only: the composite in FrameResult stays as the pipeline made it)."""
    model = getattr(pipeline, "model", None)
    if model is None or world_from_camera is None or not getattr(model, "surfaces", None):
        return image
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
    """Processing thread: newest captured frame -> pipeline.process -> `Shown` into `out`.

    `make_pipeline()` runs in this thread so the renderer's GL context belongs
    to it. Configuration arrives as callables via `submit(fn)`, each called as
    fn(pipeline) between frames; after one, the last frame is processed again
    so a change shows while replay is paused. `wrap(bgra)`, when given, runs here too and its
    result becomes `Shown.qimage` (the GUI wraps the picture as a QImage without copying it).
    `display_buffer((h, w, 4))`, when given, returns the array to write the display picture into (a
    shared-memory slot of the child process's frame ring, so the picture is written once), or None for
    a new one.
    """

    def __init__(self, make_pipeline: Callable[[], Any], inbox: LatestSlot, out: LatestSlot, *,
                 on_ready=None, on_error=None, skipped: Callable[[], int] | None = None,
                 wrap: Callable[[np.ndarray], Any] | None = None,
                 display_buffer: Callable[[tuple], np.ndarray | None] | None = None, name: str = "arapp-process"):
        super().__init__(name=name, daemon=True)
        self.skipped = skipped or (lambda: 0)
        self.wrap = wrap
        self.display_buffer = display_buffer
        self.highlight: tuple[int, int, int] | None = None  # (surface, i, j) control point marked on screen
        self.marks = False  # outline the detected markers, under the model (arapp.engine.overlay_marks)
        # watch(image, world_from_camera) after each newly tracked frame (anchor discovery: arapp.engine.discovery)
        self.watch: Callable[[np.ndarray, Any], None] | None = None
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

    def show_again(self) -> None:
        """Process the last frame again (drawn, not tracked): a paused view shows what changed beside the
        pipeline (the highlight, the marks, the engine's state carried with each frame)."""
        self.submit(lambda pipeline: None)

    def _display(self, image: np.ndarray) -> np.ndarray:
        scaled = fit_to(image, self.display_size)
        out = None if self.display_buffer is None else self.display_buffer(scaled.shape[:2] + (4,))
        return to_bgra(scaled, out)

    def stop(self) -> None:
        self._halt.set()
        self.inbox.wake()

    def _draw_marks(self, display: np.ndarray, result, frame: np.ndarray | None) -> bool:
        """The detected markers outlined in the display picture (arapp.engine.overlay_marks), under the model
        where it differs from `frame` (None: the model is laid over them afterwards). False when they could not
        be drawn: reported, and off from then on."""
        seen = result.markers if getattr(result, "state", None) == "marker" else 0
        pipe = self.pipeline
        try:
            marks = marker_marks(pipe.camera, pipe.anchors, result.world_from_camera, seen)
            draw_marks(display, marks, None if frame is None else result.image, frame,
                       under_opacity(getattr(pipe, "mode", "shaded")))
        except (ValueError, IndexError, AttributeError) as exc:  # the view goes on without them
            self._report("Cannot draw the detected markers", exc)
            self.marks = False
            return False
        return True

    def _idle(self) -> None:
        """The pipeline's work for after a frame is shown (`Pipeline.idle`: the tracker's deferred keypoint
        work), done here before the next frame is taken, off that frame's latency."""
        idle = getattr(self.pipeline, "idle", None)   # (pipelines stood in by tests have none)
        if idle is None:
            return
        try:
            idle()
        except Exception as exc:  # noqa: BLE001 - as a frame's tracking error: reported, the view goes on
            self._report("Tracking or rendering failed", exc)

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
        # scales each new frame for the view while this thread tracks and draws it (OpenCV releases the
        # interpreter): the picture's largest cost off the frame's latency
        self._side = ThreadPoolExecutor(max_workers=1, thread_name_prefix="arapp-scale")
        try:
            while not self._halt.is_set():
                item = self.inbox.take(timeout=0.5)
                changed = self._apply_commands()
                if self._halt.is_set():
                    break
                shown = self._show(item, changed)
                if shown is None:
                    continue
                self.out.put(shown)
                if self.on_ready is not None:
                    self.on_ready()
                self._idle()
        finally:
            self._side.shutdown(wait=True)
            try:
                self.pipeline.close()
            except Exception:  # noqa: BLE001 - shutting down; a GL teardown error changes nothing
                pass

    def _show(self, item: Captured | None, changed: bool) -> Shown | None:
        """The newest frame tracked and drawn into a `Shown` (paused, None: the last frame drawn again when a
        setting `changed`); None when there is nothing to show or the frame failed (reported)."""
        started = time.perf_counter()
        ahead = None
        try:
            if item is None:
                if not changed or self._last is None:
                    return None
                # Paused: draw the last frame again with the new settings, without tracking it twice.
                item, last_result = self._last
                result = redraw(self.pipeline, item, last_result)
            else:
                ahead = self._scale_ahead(item.image)
                # depth only when the frame has it: pipelines stood in by tests take no depth
                extra = {} if item.depth is None else {"depth": item.depth}
                result = self.pipeline.process(item.image, item.t, item.index, **extra)
                if self.watch is not None:
                    self.watch(item.image, result.world_from_camera)
        except Exception as exc:  # noqa: BLE001 - one bad frame must not end the view
            self._report("Tracking or rendering failed", exc)
            return None
        self._last = (item, result)
        self.processed += 1
        composited = time.perf_counter()
        display, marks = self._picture(result, item, ahead)
        return Shown(result, display, item.image, item.captured_at, time.perf_counter(),
                     dropped_capture=self.inbox.dropped + self.skipped(),
                     qimage=None if self.wrap is None else self.wrap(display), marks=marks,
                     stages={"start": started, "composited": composited})

    def _scale_ahead(self, frame: np.ndarray):
        """A future of `frame` as captured made into the display picture (`_display`) on the side thread, when
        the pipeline's overlay can be laid on it afterwards (`_picture`); else None."""
        pipe, size = self.pipeline, self.display_size
        if (sys.byteorder != "little" or self.highlight is not None or getattr(pipe, "overlay", None) is None
                or not getattr(pipe, "draw", False) or getattr(pipe, "status_line", True)):
            return None
        if size is not None and min(size[0] / frame.shape[1], size[1] / frame.shape[0]) < 0.5:
            return None   # (below half size the picture averages areas: composite.over_scaled does not)
        return self._side.submit(self._display, frame)

    def _picture(self, result, item: Captured, ahead) -> tuple[np.ndarray, bool]:
        """(The display picture of `result`, whether the marker marks were on for it). From the frame scaled
        `ahead`: the marks drawn on it, then the pipeline's overlay laid over them (`composite.over_scaled`).
        Else the composite scaled, the marks drawn under the model where it differs from the frame."""
        marks = self.marks  # read once: the UI may switch it meanwhile, and Shown says which was drawn
        draw = marks and result.world_from_camera is not None
        if ahead is not None:
            display = ahead.result()
            if self.highlight is None:   # (set meanwhile: the composite's picture rings the point)
                frame = item.image
                if draw:
                    marks = self._draw_marks(display, result, None)
                scale = (display.shape[1] / frame.shape[1], display.shape[0] / frame.shape[0])
                for crop, x0, y0 in self.pipeline.overlay:
                    composite.over_scaled(display, crop, x0, y0, scale)
                return display, marks
        shown_image = result.image
        if self.highlight is not None:
            try:
                shown_image = mark_control_point(shown_image, self.pipeline, result.world_from_camera, *self.highlight)
            except (IndexError, ValueError, AttributeError):
                pass  # a stale selection (model changed meanwhile): draw nothing
        display = self._display(shown_image)
        if draw:
            marks = self._draw_marks(display, result, item.image)
        return display, marks


class ProcessingStage:
    """Where an engine keeps its Processor, which exists only once the source is open. Commands
    submitted before then wait and are handed over in order; the view's settings (display size,
    ringed control point, marker marks) are kept and given to the processor when it starts. Used by both engines
    (threads here, the child process in remote.py); any thread."""

    def __init__(self, display_size: tuple[int, int] | None = None):
        self._lock = threading.Lock()
        self._pending: list = []
        self.processor: Processor | None = None
        self.display_size = display_size
        self.highlight: tuple[int, int, int] | None = None
        self.marks = False

    def start(self, processor: Processor) -> None:
        """Hand over the queued commands and settings, then start the processing thread."""
        processor.display_size = self.display_size
        processor.highlight = self.highlight
        processor.marks = self.marks
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
            processor.show_again()

    def set_marks(self, on: bool) -> None:
        self.marks = bool(on)
        with self._lock:
            processor = self.processor
        if processor is not None:
            processor.marks = self.marks
            processor.show_again()

    def current(self) -> Processor | None:
        with self._lock:
            return self.processor

    def is_alive(self) -> bool:
        processor = self.current()
        return processor is not None and processor.is_alive()


