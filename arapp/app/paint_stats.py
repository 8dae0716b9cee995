"""What the user sees of the live view's speed: frames painted, painted frames per second, capture-to-paint
latency (milliseconds). Fed by the view's paint events; no Qt."""

from __future__ import annotations

from collections import deque


class PaintStats:
    """Counts painted frames. `painted(shown, when)` after each new frame reaches the screen (`when`:
    perf_counter seconds); `restart()` when a new source opens."""

    def __init__(self):
        self.frames_painted = 0
        self.latencies_ms: list[float] = []
        self.latency_ms = 0.0
        self.fps = 0.0
        self._times: deque[float] = deque(maxlen=120)
        self._source_frames = 0
        self._last: tuple[int, float] | None = None  # (index, captured_at) of the frame last painted

    def restart(self) -> None:
        self._source_frames = 0
        self._last = None
        self.latency_ms = 0.0

    def painted(self, shown, when: float) -> None:
        self.frames_painted += 1
        self._source_frames += 1
        key = (shown.result.index, shown.captured_at)
        redraw = self._last == key
        self._last = key
        # the first frame of a source waits for GL start-up, and a paused frame drawn again with new
        # settings was captured long ago: neither is a latency
        if self._source_frames > 1 and not redraw:
            latency = (when - shown.captured_at) * 1e3
            self.latencies_ms.append(latency)
            self.latency_ms = latency if self.latency_ms == 0 else 0.8 * self.latency_ms + 0.2 * latency
        self._times.append(when)
        if len(self._times) >= 2:
            span = self._times[-1] - self._times[0]
            recent = [t for t in self._times if t >= when - 1.0]
            if len(recent) >= 2 and recent[-1] > recent[0]:
                self.fps = (len(recent) - 1) / (recent[-1] - recent[0])
            elif span > 0:
                self.fps = (len(self._times) - 1) / span
