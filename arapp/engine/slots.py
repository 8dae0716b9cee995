"""Latest-value hand-over between threads: a producer never waits, a slow consumer only sees the newest item.

Pure Python (no Qt), so the worker threads and the tests can use it alike.
"""

from __future__ import annotations

import threading


class LatestSlot:
    """A one-item mailbox: `put` replaces what is there (counting the item it drops), `take` empties it.

    This is the "latest frame wins" rule: when a stage is slower than the one
    feeding it, frames are dropped at its door instead of queueing up as latency.
    """

    def __init__(self):
        self._cond = threading.Condition()
        self._item = None
        self._has = False
        self.dropped = 0
        self.put_count = 0
        self._woken = False
        self.on_wait = None  # called (outside the lock) when a consumer starts waiting on an empty slot

    def put(self, item) -> bool:
        """Store `item`; return True when it replaced an item nobody took (a dropped frame)."""
        with self._cond:
            replaced = self._has
            if replaced:
                self.dropped += 1
            self._item = item
            self._has = True
            self.put_count += 1
            self._cond.notify_all()
            return replaced

    def replace(self, item):
        """`put(item)`, returning the item it replaced (a dropped one), or None."""
        with self._cond:
            old = self._item if self._has else None
            self.put(item)
            return old

    def take(self, timeout: float | None = 0.0):
        """Remove and return the newest item, waiting up to `timeout` seconds (None: forever); None if empty."""
        if self.on_wait is not None and timeout != 0.0:
            with self._cond:
                empty = not self._has
            if empty:
                self.on_wait()  # a producer that reads on demand reads now
        with self._cond:
            if not self._has and timeout != 0.0:
                self._cond.wait_for(lambda: self._has or self._woken, timeout)
            self._woken = False
            if not self._has:
                return None
            item, self._item, self._has = self._item, None, False
            return item

    def peek(self):
        """The item waiting, without taking it (None when empty)."""
        with self._cond:
            return self._item if self._has else None

    def wake(self) -> None:
        """Wake a consumer blocked in `take` (it then returns None when still empty)."""
        with self._cond:
            self._woken = True
            self._cond.notify_all()

    def clear(self) -> None:
        with self._cond:
            self._item, self._has = None, False
