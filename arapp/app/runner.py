"""How the app model runs slow work (loading, tessellating, slicing) and hands results back. No Qt.

The app model never starts threads for its own jobs: it asks a runner.
`ImmediateRunner` (headless use and tests) runs each job at once in the
caller's thread; the GUI's runner (arapp.gui.tasks.QtRunner) runs it in a
worker thread and delivers `done`/`failed` on the UI thread.

A runner has:
- `run(fn, *args, done=None, failed=None, name="")`: fn(*args), then done(result) or failed(exception);
  returns a handle with `cancel` (a threading.Event fn may watch, when passed in) and `running`;
- `latest(fn, done, failed=None, name="")`: an object whose `send(value)` runs fn(value) for the newest
  value only (values sent meanwhile replace each other);
- `post(fn, value)`: call fn(value) on the model's thread (from any thread).
"""

from __future__ import annotations

import threading
from typing import Any, Callable


class _Done:
    """The handle of a job that already ran."""

    def __init__(self):
        self.cancel = threading.Event()
        self.running = False
        self.result = None
        self.error: BaseException | None = None


class _Latest:
    def __init__(self, runner: "ImmediateRunner", fn, done, failed):
        self.runner, self.fn, self.done, self.failed = runner, fn, done, failed

    def send(self, value) -> None:
        self.runner.run(self.fn, value, done=self.done, failed=self.failed)

    @property
    def idle(self) -> bool:
        return True


class ImmediateRunner:
    """Runs each job at once, in the calling thread; `post` calls at once too."""

    def run(self, fn: Callable, *args, done: Callable[[Any], None] | None = None,
            failed: Callable[[BaseException], None] | None = None, name: str = "") -> _Done:
        handle = _Done()
        try:
            handle.result = fn(*args)
        except Exception as exc:  # noqa: BLE001 - handed to `failed`, as a worker thread would
            handle.error = exc
            if failed is None:
                raise
            failed(exc)
            return handle
        if done is not None:
            done(handle.result)
        return handle

    def latest(self, fn: Callable[[Any], Any], done: Callable[[Any], None],
               failed: Callable[[BaseException], None] | None = None, name: str = "") -> _Latest:
        return _Latest(self, fn, done, failed)

    def post(self, fn: Callable[[Any], None], value=None) -> None:
        fn(value)
