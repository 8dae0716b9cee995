"""A timer probe for UI-thread stalls: a short periodic QTimer whose late firings measure blocking."""

from __future__ import annotations

import time

from PySide6.QtCore import QObject, Qt, QTimer


class BlockProbe(QObject):
    """Fires every `interval_ms` on the UI thread; a firing `interval_ms + X` after the previous one means the
    thread was busy for about X ms. `max_block_ms` is the worst X seen since `start()`."""

    def __init__(self, interval_ms: int = 5, parent=None):
        super().__init__(parent)
        self.interval_ms = interval_ms
        self._timer = QTimer(self)
        self._timer.setTimerType(Qt.TimerType.PreciseTimer)
        self._timer.setInterval(interval_ms)
        self._timer.timeout.connect(self._tick)
        self._last = None
        self.max_block_ms = 0.0
        self.blocks_ms: list[float] = []

    def start(self) -> None:
        self._last = None
        self.max_block_ms = 0.0
        self.blocks_ms = []
        self._timer.start()

    def stop(self) -> None:
        self._timer.stop()

    def _tick(self) -> None:
        now = time.perf_counter()
        if self._last is not None:
            block = (now - self._last) * 1e3 - self.interval_ms
            self.blocks_ms.append(block)
            self.max_block_ms = max(self.max_block_ms, block)
        self._last = now
