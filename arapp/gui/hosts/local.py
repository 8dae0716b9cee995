"""The live view's engine in the GUI's own process: `arapp.engine.live.LiveEngine` seen through Qt signals.

The capture and processing threads and the commands they obey live in
arapp.app (no Qt); here their events become Qt signals, which Qt delivers on
the UI thread, and each processed picture is wrapped as a QImage (without a
copy) in the processing thread, so the UI thread only paints. The default
engine runs the same LiveEngine in a child process instead (remote.py);
`ARAPP_GUI_ENGINE=threads` selects this one.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, Callable

import numpy as np
from PySide6.QtCore import QObject
from PySide6.QtGui import QImage

from arapp.engine.live import EngineFacade, LiveEngine, SourceInfo, default_pipeline
from arapp.engine.processor import Shown, to_bgra
from arapp.gui.hosts.remote import EngineSignals, RemoteEngine

__all__ = ["Engine", "make_engine", "connect_handlers", "bgr_qimage", "qimage_from_bgra", "SourceInfo", "Shown"]


def qimage_from_bgra(bgra: np.ndarray) -> QImage:
    """A QImage over an (H, W, 4) uint8 array in the screen's native 32-bit order (arapp.engine.processor.to_bgra),
    without copying it; the QImage keeps the array alive (`_keep`)."""
    h, w = bgra.shape[:2]
    fmt = QImage.Format.Format_RGB32 if sys.byteorder == "little" else QImage.Format.Format_ARGB32
    q = QImage(bgra.data, w, h, bgra.strides[0], fmt)
    q._keep = bgra  # the QImage points into the numpy buffer
    return q


def bgr_qimage(image: np.ndarray) -> QImage:
    """A (H, W, 3) BGR (or grey) uint8 array as a QImage in the screen's native 32-bit format, so painting
    it is a plain copy. The conversion is the caller's thread's work (a worker's)."""
    return qimage_from_bgra(to_bgra(image))


class Engine(EngineSignals, EngineFacade):
    """One open source with its two worker threads in this process, seen from the UI thread through the
    EngineSignals. Commands: `send(arapp.engine.commands...)`."""

    def __init__(self, spec: str | None = None, *, opener: Callable[[], Any] | None = None, name: str = "",
                 anchors: list | None = None, speed: float = 1.0, loop: bool = False, playing: bool = True,
                 pipeline_factory=default_pipeline, parent: QObject | None = None):
        super().__init__(parent)
        self.live = LiveEngine(spec, opener=opener, name=name, anchors=anchors, speed=speed, loop=loop,
                               playing=playing, pipeline_factory=pipeline_factory, wrap=qimage_from_bgra)
        self._notify_pending = threading.Event()
        ev = self.live.events
        ev.opened.connect(self.opened.emit)
        ev.ready.connect(self._on_ready)
        ev.error.connect(self.error.emit)
        ev.ended.connect(self.ended.emit)
        ev.recorded.connect(self.recorded.emit)
        ev.toolpaths.connect(self.toolpaths_shown.emit)

    def _on_ready(self) -> None:
        # one queued signal at a time: the UI takes the newest frame, however many were made meanwhile
        if not self._notify_pending.is_set():
            self._notify_pending.set()
            self.frame_ready.emit()

    @property
    def info(self) -> SourceInfo | None:
        return self.live.info

    def take(self) -> Shown | None:
        """The newest processed frame (None when nothing new); call from the UI thread on frame_ready."""
        self._notify_pending.clear()
        shown = self.live.take()
        if shown is not None:
            shown.stages["taken"] = time.perf_counter()
        return shown


def make_engine(kind: str, spec: str, *, name: str, anchors: list, speed: float, loop: bool, handlers,
                full_frames: bool = False, parent: QObject | None = None):
    """An engine for `Session` (its `make_engine`): kind "threads" (this process) or "process" (a child
    process, remote.RemoteEngine), its signals wired to the session's `handlers` (arapp.app.session
    .EngineHandlers), which Qt then calls on the UI thread."""
    if kind == "threads":
        engine = Engine(spec, name=name, anchors=anchors, speed=speed, loop=loop, parent=parent)
    else:
        engine = RemoteEngine(spec, name=name, anchors_json=[a.to_dict() for a in anchors], speed=speed,
                              loop=loop, full_frames=full_frames, parent=parent)
    return connect_handlers(engine, handlers)


def connect_handlers(engine, handlers):
    """Wire a GUI engine's signals (EngineSignals) to a session's `handlers`; returns the engine."""
    engine.opened.connect(handlers.opened)
    engine.frame_ready.connect(handlers.ready)
    engine.error.connect(handlers.error)
    engine.ended.connect(handlers.ended)
    engine.recorded.connect(handlers.recorded)
    engine.toolpaths_shown.connect(handlers.toolpaths)
    return engine
