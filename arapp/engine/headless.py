"""Running a `Session` without a GUI: the live engine in this process, its events delivered by `pump()`.

The GUI's event loop delivers an engine's events on the UI thread; here a
queue does: the worker threads put (handler, args) into it and the driver's
thread calls `pump()` (or `wait_until`) to run them, so the session is only
ever touched from one thread, as in the GUI. The session's time limits (a
source with no first picture) act when the driver calls `session.tick()`.

    events = EventQueue()
    session = Session(headless_engine_factory(events))
    session.open_source("recordings/board_orbit")
    events.wait_until(lambda: session.last_shown is not None, timeout=30)
"""

from __future__ import annotations

import queue
import time
from typing import Callable

from arapp.engine.live import EngineFacade, LiveEngine


class EventQueue:
    """Callbacks posted from any thread, run by `pump` in the driver's thread."""

    def __init__(self):
        self._queue: queue.SimpleQueue = queue.SimpleQueue()

    def post(self, fn: Callable, *args) -> None:
        self._queue.put((fn, args))

    def pump(self, timeout: float = 0.0) -> int:
        """Run the callbacks waiting (waiting up to `timeout` s for the first); return how many ran."""
        ran = 0
        block = timeout > 0
        while True:
            try:
                fn, args = self._queue.get(block=block, timeout=timeout if block else None)
            except queue.Empty:
                return ran
            fn(*args)
            ran += 1
            block = False

    def wait_until(self, condition: Callable[[], bool], timeout: float = 30.0) -> bool:
        """Pump until `condition()` holds (True) or `timeout` s pass (False)."""
        deadline = time.monotonic() + timeout
        while not condition():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.pump(min(left, 0.1))
        return True


class HeadlessEngine(EngineFacade):
    """A `LiveEngine` seen through an `EventQueue`: the engine interface `Session` uses."""

    def __init__(self, live: LiveEngine, events: EventQueue, handlers):
        self.live = live
        for name in ("opened", "ready", "error", "ended", "recorded", "toolpaths"):
            handler = getattr(handlers, name)
            getattr(live.events, name).connect(lambda *a, h=handler: events.post(h, *a))


def headless_engine_factory(events: EventQueue, **engine_options) -> Callable:
    """The `make_engine` of a headless `Session` (engine_options go to LiveEngine, e.g. pipeline_factory)."""

    def make(spec: str, *, name: str, anchors: list, speed: float, loop: bool, handlers) -> HeadlessEngine:
        live = LiveEngine(spec, name=name, anchors=anchors, speed=speed, loop=loop, **engine_options)
        return HeadlessEngine(live, events, handlers)

    return make
