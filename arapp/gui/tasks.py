"""Background jobs for the UI: run a function in a worker thread, get its result back on the UI thread."""

from __future__ import annotations

import threading
from typing import Any, Callable

import shiboken6
from PySide6.QtCore import QObject, Signal


class _Bridge(QObject):
    """Lives on the UI thread; its signal carries (callback, value, owner) across threads (Qt queues it).
    A callback whose owner widget has been deleted meanwhile is dropped."""

    deliver = Signal(object, object, object)

    def __init__(self):
        super().__init__()
        self.deliver.connect(self._call)

    def _call(self, callback, value, owner) -> None:
        if owner is not None and not shiboken6.isValid(owner):
            return
        callback(value)


_bridge: _Bridge | None = None


def _get_bridge() -> _Bridge:
    global _bridge
    if _bridge is None:
        _bridge = _Bridge()
    return _bridge


def on_ui(callback: Callable[[Any], None], value=None, owner: QObject | None = None) -> None:
    """Call callback(value) on the UI thread (from any thread), unless `owner` is deleted by then.
    Make the bridge on the UI thread first (`init_ui_bridge()`), which `MainWindow` does."""
    _get_bridge().deliver.emit(callback, value, owner)


def init_ui_bridge() -> None:
    _get_bridge()


class Task:
    """fn(*args) in a daemon thread; done(result) or failed(exception) on the UI thread.

    `cancel` is a threading.Event that fn may watch (pass it in args); `running` says whether fn is still going.
    """

    def __init__(self, fn: Callable, *args, done: Callable[[Any], None] | None = None,
                 failed: Callable[[BaseException], None] | None = None, name: str = "arapp-task",
                 owner: QObject | None = None):
        self.fn, self.args = fn, args
        self.done, self.failed = done, failed
        self.owner = owner
        self.cancel = threading.Event()
        self.result = None
        self.error: BaseException | None = None
        _get_bridge()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> "Task":
        self._thread.start()
        return self

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float | None = None) -> None:
        self._thread.join(timeout)

    def _run(self) -> None:
        try:
            self.result = self.fn(*self.args)
        except Exception as exc:  # noqa: BLE001 - handed to the UI as a dialog
            self.error = exc
            if self.failed is not None:
                on_ui(self.failed, exc, self.owner)
            return
        if self.done is not None:
            on_ui(self.done, self.result, self.owner)


class LatestTask:
    """Runs fn(value) in one worker thread for the newest value only: values sent while a run is busy
    replace each other, so rapid edits (a spin box held down) never queue up."""

    def __init__(self, fn: Callable[[Any], Any], done: Callable[[Any], None],
                 failed: Callable[[BaseException], None] | None = None, name: str = "arapp-latest",
                 owner: QObject | None = None):
        self.fn, self.done, self.failed = fn, done, failed
        self.owner = owner
        self._cond = threading.Condition()
        self._value = None
        self._has = False
        self._busy = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        _get_bridge()
        self._thread.start()

    def send(self, value) -> None:
        with self._cond:
            self._value, self._has = value, True
            self._cond.notify_all()

    @property
    def idle(self) -> bool:
        with self._cond:
            return not self._has and not self._busy

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._has)
                value, self._value, self._has = self._value, None, False
                self._busy = True
            try:
                result = self.fn(value)
            except Exception as exc:  # noqa: BLE001
                if self.failed is not None:
                    on_ui(self.failed, exc, self.owner)
            else:
                on_ui(self.done, result, self.owner)
            finally:
                with self._cond:
                    self._busy = False


class QtRunner:
    """The GUI's runner for the app model (arapp.app.runner): jobs in worker threads, results on the UI
    thread (dropped once `owner` is deleted)."""

    def __init__(self, owner: QObject | None = None):
        self.owner = owner

    def run(self, fn: Callable, *args, done=None, failed=None, name: str = "arapp-task") -> Task:
        return Task(fn, *args, done=done, failed=failed, name=name, owner=self.owner).start()

    def latest(self, fn: Callable[[Any], Any], done, failed=None, name: str = "arapp-latest") -> LatestTask:
        return LatestTask(fn, done, failed, name=name, owner=self.owner)

    def post(self, fn: Callable[[Any], None], value=None) -> None:
        on_ui(fn, value, self.owner)
