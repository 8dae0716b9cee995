"""The capture thread of the live engine: reads a source's frames, paced, with replay controls. No Qt.

`Player` opens the source (in its own thread: a camera can take seconds),
reads frames (paced at the recording's own timestamps times a speed factor,
or as fast as a live camera delivers) into a `LatestSlot`, and obeys
play/pause/step/seek/loop. It never waits for the stages after it.
"""

from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from arapp.engine.slots import LatestSlot
from arapp.engine.sourcespec import is_live, is_seekable

# Recordings are read continuously at their pace rather than on demand with seeks: OpenCV's seek in the
# recorder's MJPG/AVI files costs 50-150 ms here (it reopens and decodes forward), against ~13 ms for the next
# frame at 1280x720. Measured by benchmarks/bench_gui.py. Each next frame is read once the consumer is done
# with the last one (it waits for a frame), or at the latest when it must be read to be ready when due
# (`_read_by`): read at once, its decoding shared the cores with the last frame's tracking.
ON_DEMAND = False
# the margin kept for reading a frame in time: this many times the decoding's recent mean, plus READ_SLACK_S
READ_MARGIN = 1.5
READ_SLACK_S = 0.003


@dataclass
class Captured:
    """One frame as read: index and time (seconds) in the stream, BGR image, perf_counter() when read."""

    index: int
    t: float
    image: np.ndarray
    captured_at: float
    depth: np.ndarray | None = None  # float32 metres on the image's pixels (depth cameras, recordings with depth)




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
        out.on_wait = self._demand   # (on demand: reads then; else reads no earlier, `_read_by`)
        self._read_s = 0.0   # seconds reading (decoding) a frame takes, a running mean
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
        self.last_t: float | None = None   # stream time of the last frame handed over

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

    def _read_by(self) -> None:
        """Playing a recording continuously: wait until the consumer wants a frame, or until the next one must
        be read to be ready when due (its decoding's recent time with a margin before), or a command."""
        with self._cond:
            if self._ref is None:
                return   # a new clock: read now
            wall0, t0 = self._ref
            ref, speed = self._ref, self._speed
        times = getattr(self.source, "times", None)
        nxt = self.last_index + 1
        if times is not None and nxt < len(times):
            t_next = float(times[nxt])
        else:
            fps = float(getattr(self.source, "fps", 0.0) or 0.0)
            if fps <= 0 or self.last_t is None:
                return
            t_next = self.last_t + 1.0 / fps
        deadline = wall0 + (t_next - t0) / speed - READ_MARGIN * self._read_s - READ_SLACK_S
        with self._cond:
            self._cond.wait_for(lambda: self._demanded or self._halt or not self._playing or self._seek is not None
                                or self._ref is not ref, max(0.0, deadline - time.perf_counter()))

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
                it = self._seek_to(seek)
                continue
            if (self._playing and not is_step and self.seekable and self.on_demand and first is None):
                if not self._wait_demand():
                    continue
                ahead = self._skip_to_due()
                it = it if ahead is None else ahead
            elif self._playing and not is_step and not self.live and first is None:
                self._read_by()
            try:
                with self._cond:
                    self._demanded = False
                if first is not None:
                    frame, first = first, None
                else:
                    started = time.perf_counter()
                    frame = next(it)
                    self._read_s = 0.8 * self._read_s + 0.2 * (time.perf_counter() - started)
            except StopIteration:
                stop, looped = self._source_ended()
                if stop:
                    return
                it = it if looped is None else looped
                continue
            if self._playing and not self.live and not is_step and not self._pace(float(frame.t)):
                return
            self._hand_over(frame)

    def _seek_to(self, seek: int):
        """Seek the source to frame `seek` (clamped); paused, that frame is shown. Returns its iterator."""
        seek = max(0, min(seek, int(self.source.frame_count) - 1))
        self.source.seek(frame=seek)
        it = iter(self.source)
        self.last_index = seek - 1
        if not self._playing:
            with self._cond:
                self._steps = max(self._steps, 1)  # show the frame sought to
        return it

    def _skip_to_due(self):
        """On demand, behind the clock: seek ahead to the frame due now (counted in `skipped`) and return
        the new iterator; None when the next frame is the one due."""
        nxt = self.last_index + 1
        due = self._due_index(nxt)
        if due <= nxt:
            return None
        self.source.seek(frame=due)
        self.skipped += due - nxt
        return iter(self.source)

    def _source_ended(self):
        """The source gave no more frames: (stop the loop?, new iterator when it loops back to the start).

        A source error is reported (a lost camera stops the loop); a looping seekable source starts again;
        a live one that just stops raises; else playback pauses at the end and `on_end` is called."""
        error = getattr(self.source, "error", None)
        if error:
            title = "Camera lost" if self.live else "The recording is damaged"
            self._fail(title, error if isinstance(error, BaseException) else RuntimeError(str(error)))
            if self.live:
                return True, None
        if self.seekable and self._loop and not error:
            self.source.seek(frame=0)
            it = iter(self.source)
            self.last_index = -1
            with self._cond:
                self._ref = None
                fps = float(getattr(self.source, "fps", 0) or 30.0)
                self._wrap_delay = 1.0 / (fps * self._speed)
            return False, it
        if self.live:
            raise RuntimeError("the camera stopped delivering frames")
        with self._cond:
            self._playing = False
            self._steps = 0
        if self.on_end is not None:
            self.on_end()
        return False, None

    def _hand_over(self, frame) -> None:
        """Pass a frame read on: counted, recorded when recording, put on the output queue."""
        item = Captured(int(frame.index), float(frame.t), frame.image, time.perf_counter(),
                        getattr(frame, "depth", None))
        self.frames_read += 1
        self.last_index, self.last_t = item.index, item.t
        with self._cond:
            self._demanded = False   # (a wait the consumer began before this frame: it takes this one now)
        if self.recorder is not None:
            self.recorder.write(item)
        self.out.put(item)

