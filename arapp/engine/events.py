"""Change events for the headless app model: a plain-Python signal, no Qt.

`Event` is a list of callbacks; `emit(*args)` calls each in the emitting
thread, in the order they were connected. The Qt layer connects its widget
updates to these; a headless driver (tests, scripts) connects plain functions.
Which thread emits is the emitter's business: `arapp.app.session.Session`
emits on the thread that calls it (the GUI's UI thread, or a test's thread).
"""

from __future__ import annotations

from typing import Callable


class Event:
    """A named list of callbacks. `connect(fn)` adds one (returns fn, so it works as a decorator),
    `disconnect(fn)` removes it, `emit(*args)` calls them all with args."""

    def __init__(self, name: str = ""):
        self.name = name
        self._callbacks: list[Callable] = []

    def connect(self, fn: Callable) -> Callable:
        self._callbacks.append(fn)
        return fn

    def disconnect(self, fn: Callable) -> None:
        try:
            self._callbacks.remove(fn)
        except ValueError:
            pass  # not connected: nothing to undo

    def emit(self, *args) -> None:
        for fn in list(self._callbacks):
            fn(*args)

    def __len__(self) -> int:
        return len(self._callbacks)

    def __repr__(self) -> str:
        return f"Event({self.name!r}, {len(self._callbacks)} callbacks)"


class Events:
    """A namespace of `Event`s made from names: `Events("opened", "error").opened.connect(...)`."""

    def __init__(self, *names: str):
        for n in names:
            setattr(self, n, Event(n))
