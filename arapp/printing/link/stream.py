"""The host side of Marlin's numbered-line protocol as a state object, without I/O.

`LineStream` holds what the host knows: the lines sent and not yet
acknowledged, the highest line the firmware confirmed, the queue of lines to
send, and the timers. The serial link's I/O loop (serial_link.py) feeds it
the printer's replies (`on_ok`, `on_resend`, `on_timeout`, `on_action`, ...)
and writes what `frames_to_send` returns; every method takes the time `now`
(seconds, monotonic clock) so each rule is testable alone.

The rules (docs/domain.md §4, issue #14):

- Progress is what the firmware acknowledges: a program line counts once, when
  its `ok` (or a resend request for a later line) arrives. Lines the host adds
  itself (temperature polls, a resume preamble, the cancel sequence) never
  move the job's position.
- Only a reply that answers a line (`ok`, `Resend:`) resets the no-answer
  timer. Keep-alives (`busy:`, temperature lines of a heat wait) extend it
  only while a blocking command (M109, M190, G28, G29, G4, M0/M1, M600, M400)
  is the oldest line unanswered; such a command gets no timeout while the
  printer shows it is alive, and `blocking_timeout` of silence otherwise.
- A resend request for a line the firmware confirmed, or for line 0 after the
  start-up exchange, cannot come from a healthy exchange (a reset without its
  banner, or noise): the stream stops (`StopReason.BAD_RESEND`), it never
  replays. A request is honoured once: the same request again, without an
  `Error:` line of its own, before the line was answered is a doubled reply,
  and its `ok` is absorbed.
- Never more than `window` lines (and `rx_buffer` bytes) in flight.

Outcomes are typed: each `on_*` method returns a `Step` (what happened) or a
`Stop` (why the stream must end); `finish` turns the end into a `Finish`
(job status, message, the error class to raise).
"""

from __future__ import annotations

import enum
import re
from collections import deque
from dataclasses import dataclass, field

from . import protocol as P
from .job import Command, JobState, cancel_commands

# Commands that may run for minutes without an answer (docs/domain.md §4).
BLOCKING = frozenset({"M109", "M190", "G28", "G29", "G4", "M0", "M1", "M600", "M400"})
HEAT_WAITS = {"M109": ("T", "T0"), "M190": ("B",)}
# A heater reading this close to the wait's target (degrees C) no longer shows
# the wait is still going on (Marlin's TEMP_HYSTERESIS is 3 C).
HEAT_WINDOW_C = 3.0
_S_WORD = re.compile(r"\bS\s*(-?\d*\.?\d+)", re.IGNORECASE)
_RESIDENCY = re.compile(r"\bW\s*:\s*(\?|\d+)")  # Marlin's heat-wait countdown field


class Step(enum.Enum):
    """What a reply did to the stream."""

    NOTHING = "nothing"  # no change of what was acknowledged
    CONFIRMED = "confirmed"  # one or more lines acknowledged
    REWOUND = "rewound"  # lines from `next_number` go out again
    IGNORED = "ignored"  # a stale or doubled reply, absorbed
    WAITING = "waiting"  # a timer ran out but the printer is alive or the head is blocking
    PAUSE = "pause"
    RESUME = "resume"
    CANCEL = "cancel"


class StopReason(enum.Enum):
    HALTED = "halted"  # the firmware said Error:/!! (not a line error)
    RESET = "reset"  # the firmware printed its start banner
    BAD_RESEND = "bad_resend"  # a resend request no healthy exchange produces
    NO_ANSWER = "no_answer"  # timeouts in a row
    LINK_LOST = "link_lost"  # the port went away
    DISCONNECT = "disconnect"  # the printer asked the host to disconnect (//action:disconnect)
    FAILED = "failed"  # the host itself failed (an exception)


@dataclass(frozen=True)
class Stop:
    reason: StopReason
    message: str


# Job status written for each way a stream ends.
STATUS = {
    StopReason.HALTED: "halted",
    StopReason.RESET: "reset",
    StopReason.BAD_RESEND: "reset",
    StopReason.NO_ANSWER: "link_lost",
    StopReason.LINK_LOST: "link_lost",
    StopReason.DISCONNECT: "link_lost",
    StopReason.FAILED: "failed",
}


@dataclass(frozen=True)
class Finish:
    """How a stream ended: the job's status, a message, and the stop (None: done or cancelled)."""

    status: str
    message: str
    stop: Stop | None = None


@dataclass
class Item:
    """A line to send: a program command (`command` set) or a host command (`command` None)."""

    text: str
    command: Command | None = None


@dataclass
class Copy:
    """One transmission of a numbered line."""

    number: int
    size: int
    epoch: int
    sent_at: float
    rejected: bool = False


def code_of(text: str) -> str:
    """`G1`, `M109`, ... (upper case) of a command; '' for an empty one."""
    word = text.split(None, 1)[0].upper() if text.strip() else ""
    # `G01` and `G1` are the same command.
    if len(word) > 1 and word[1:].isdigit():
        word = word[0] + str(int(word[1:]))
    return word


@dataclass
class LineStream:
    """The numbered-line exchange with one printer (see module doc).

    window: unacknowledged lines allowed in flight; rx_buffer: unacknowledged
    bytes allowed in flight; timeout: seconds without an answer before the
    unanswered lines go out again; blocking_timeout: the same, while a
    blocking command with no keep-alive is the oldest line unanswered;
    max_timeouts: timeouts in a row before the printer counts as gone;
    poll_interval: seconds between host M105 polls (0: no polls);
    history_len: lines kept for resends.
    """

    window: int = 1
    rx_buffer: int = 127
    timeout: float = 10.0
    blocking_timeout: float = 600.0
    max_timeouts: int = 5
    poll_interval: float = 0.0
    history_len: int = 1024

    history: dict = field(default_factory=dict)  # number -> (frame bytes, Item)
    top: int = -1  # highest number sent so far
    next_number: int = 0  # next number to send
    confirmed: int = -1  # highest number the printer confirmed
    inflight: deque = field(default_factory=deque)
    epoch: int = 0
    items: deque = field(default_factory=deque)
    state: JobState | None = None
    paused: bool = False
    cancelling: bool = False
    keepalive_seen: bool = False  # the printer sends busy: while it blocks (HOST_KEEPALIVE)

    last_answer: float = 0.0
    last_alive: float = 0.0
    last_poll: float = 0.0
    error_seen_at: float | None = None
    consecutive_timeouts: int = 0
    absorb_oks: int = 0
    honoured: tuple | None = None  # (line, confirmed then) of the last resend request honoured
    resends: int = 0
    timeouts: int = 0
    max_inflight: int = 0

    # ------------------------------------------------------------------ setup
    def reset_numbering(self, now: float) -> None:
        """After `N0 M110 N0` was answered: line 0 is confirmed, the next is 1 (line 0 is never sent
        again: a request for it stops the stream)."""
        self.history.clear()
        self.inflight.clear()
        self.next_number, self.top, self.confirmed = 1, 0, 0
        self.honoured, self.absorb_oks = None, 0
        self.last_answer = self.last_alive = now

    def start(self, items, state: JobState | None, now: float) -> None:
        """Queue `items` for a run; `state` (None while connecting) follows the program lines."""
        self.items = deque(items)
        self.state = state
        self.cancelling = False
        self.consecutive_timeouts = 0
        self.error_seen_at = None
        self.last_answer = self.last_alive = self.last_poll = now

    # ------------------------------------------------------------- sending
    def head(self) -> Item | None:
        """The oldest line sent and not answered (None when nothing is in flight)."""
        if not self.inflight:
            return None
        entry = self.history.get(self.inflight[0].number)
        return entry[1] if entry else None

    def head_is_blocking(self) -> bool:
        head = self.head()
        return head is not None and code_of(head.text) in BLOCKING

    def frames_to_send(self, now: float) -> list[bytes]:
        """Frames to write now: lines to resend first, then new ones, while the window has room.

        A due temperature poll (M105) goes out between program lines.
        """
        out = []
        while len(self.inflight) < self.window and (not self.paused or self.next_number <= self.top):
            if self.next_number <= self.top:
                frame = self.history[self.next_number][0]
            elif self.items:
                if self.poll_interval > 0 and not self.cancelling and now - self.last_poll > self.poll_interval:
                    item = Item("M105")
                    self.last_poll = now
                else:
                    item = self.items.popleft()
                frame = P.frame(self.next_number, item.text)
                self.history[self.next_number] = (frame, item)
                self.top = self.next_number
            else:
                break
            if self.inflight and sum(c.size for c in self.inflight) + len(frame) > self.rx_buffer:
                break  # Marlin's receive buffer would overflow; it goes out after the next answer
            self._sent(frame, now)
            out.append(frame)
        return out

    def poll_frame(self, now: float) -> bytes | None:
        """A numbered M105 while paused (nothing else in flight), when a poll is due."""
        if not self.paused or self.inflight or self.poll_interval <= 0 or now - self.last_poll < self.poll_interval:
            return None
        self.last_poll = now
        frame = P.frame(self.next_number, "M105")
        self.history[self.next_number] = (frame, Item("M105"))
        self.top = self.next_number
        self._sent(frame, now)
        return frame

    def _sent(self, frame: bytes, now: float) -> None:
        if not self.inflight:
            self.last_answer = max(self.last_answer, now)  # the timer runs from the first line in flight
        self.inflight.append(Copy(self.next_number, len(frame), self.epoch, now))
        self.next_number += 1
        self.max_inflight = max(self.max_inflight, len(self.inflight))

    def finished(self) -> bool:
        return (not self.items and self.next_number > self.top and not self.inflight
                and self.confirmed >= self.top)

    # ------------------------------------------------------------- replies
    def on_ok(self, now: float) -> Step:
        """`ok`: the oldest copy in flight was answered (run, or refused when a resend request came first)."""
        self.error_seen_at = None
        self._answered(now)
        if self.absorb_oks:
            self.absorb_oks -= 1
            return Step.IGNORED
        if not self.inflight:
            return Step.IGNORED  # an ok nothing asked for (e.g. a late answer after a rewind)
        copy = self.inflight.popleft()
        if copy.rejected or copy.number <= self.confirmed:
            return Step.IGNORED
        self._confirm_through(copy.number)
        return Step.CONFIRMED

    def on_resend(self, line: int, now: float) -> Step | Stop:
        """`Resend: line`: the printer's last accepted line is `line - 1`."""
        after_error = self.error_seen_at is not None  # a request with its own `Error:` line is a new one
        self.error_seen_at = None
        self._answered(now)
        self.resends += 1
        if line > self.top + 1:
            return Stop(StopReason.BAD_RESEND,
                        f"the printer asked to resend line {line}, but the last line sent was {self.top}")
        if line - 1 < self.confirmed:
            return Stop(StopReason.BAD_RESEND,
                        f"the printer asked for line {line} again, but it had confirmed every line up to "
                        f"{self.confirmed}: it was reset or the reply was garbled; nothing was sent twice")
        if not after_error and self.honoured == (line, self.confirmed):
            # The same request again, without an `Error:` line of its own (Marlin says why before each
            # real request), and nothing confirmed since: a doubled reply. Its `ok` answers nothing.
            self.absorb_oks += 1
            return Step.IGNORED
        head = self.inflight[0] if self.inflight else None
        if head is not None and head.epoch < self.epoch:
            if head.rejected:
                self.absorb_oks += 1  # a second request for the same stale copy: a doubled reply
            head.rejected = True  # answers a copy sent before the last rewind; its ok follows
            return Step.IGNORED
        if head is not None:
            head.rejected = True  # the ok that follows answers this request
        if line - 1 > self.confirmed:
            self._confirm_through(line - 1)
        self.honoured = (line, self.confirmed)
        self.epoch += 1
        self.next_number = line
        return Step.REWOUND

    def on_error(self, now: float) -> Step:
        """A recoverable `Error:` (checksum, line number): a resend request should follow at once."""
        if self.inflight and self.error_seen_at is None:
            self.error_seen_at = now
        return Step.NOTHING

    def on_wait(self, now: float) -> Step:
        """`wait`: the printer is idle; a line unanswered for a while was lost on the way."""
        if self.inflight and not self.head_is_blocking() and now - self.inflight[0].sent_at > 0.25:
            self.timeouts += 1
            self._rewind(self.confirmed + 1)
            return Step.REWOUND
        return Step.NOTHING

    def on_keepalive(self, reply: P.Reply, now: float) -> Step:
        """`busy:` or a temperature report: extends the timer only for a blocking head (see module doc)."""
        head = self.head()
        if head is None:
            return Step.NOTHING
        code = code_of(head.text)
        if reply.kind == P.BUSY:
            if code in BLOCKING:
                self.keepalive_seen = True
                self.last_alive = now
                self.consecutive_timeouts = 0
            return Step.NOTHING
        if code in HEAT_WAITS and self._heat_wait_going_on(head.text, code, reply):
            self.last_alive = now
            self.consecutive_timeouts = 0
        return Step.NOTHING

    def _heat_wait_going_on(self, text: str, code: str, reply: P.Reply) -> bool:
        if _RESIDENCY.search(reply.text):
            return True  # Marlin's heat-wait report (W: countdown)
        m = _S_WORD.search(text)
        if not m:
            return False
        target = float(m.group(1))
        for name in HEAT_WAITS[code]:
            if name in reply.temperatures:
                return abs(reply.temperatures[name][0] - target) > HEAT_WINDOW_C
        return False

    def deadline(self) -> float | None:
        """When `on_timeout` is due (None: nothing in flight, no timer)."""
        if not self.inflight:
            return None
        if self.head_is_blocking():
            if self.keepalive_seen or self.last_alive > self.last_answer:
                # The printer shows it is alive while it blocks (a keep-alive every ~2 s): no timeout
                # while they come.
                deadline = max(self.last_answer, self.last_alive) + self.timeout
            else:
                deadline = self.last_answer + self.blocking_timeout  # a silent firmware: minutes
        else:
            deadline = self.last_answer + self.timeout
        if self.error_seen_at is not None:
            deadline = min(deadline, self.error_seen_at + min(1.0, self.timeout))
        return deadline

    def on_timeout(self, now: float) -> Step | Stop:
        """No answer by the deadline: send again from the first line not confirmed, or give up."""
        deadline = self.deadline()
        if deadline is None or now < deadline:
            return Step.WAITING
        self.consecutive_timeouts += 1
        self.timeouts += 1
        if self.consecutive_timeouts > self.max_timeouts:
            return Stop(StopReason.NO_ANSWER,
                        f"the printer stopped answering (no reply for {self.timeout:g} s, "
                        f"{self.max_timeouts} times)")
        self.error_seen_at = None
        self.last_answer = now
        self._rewind(self.confirmed + 1)
        return Step.REWOUND

    def on_action(self, action: str) -> Step | Stop:
        """`//action:<name>` from the printer (pause, resume, cancel, disconnect)."""
        name = action.split()[0].lower() if action.strip() else ""
        if name == "pause":
            self.paused = True
            return Step.PAUSE
        if name == "resume":
            self.paused = False
            return Step.RESUME
        if name == "cancel":
            return Step.CANCEL
        if name == "disconnect":
            return Stop(StopReason.DISCONNECT, "the printer asked the host to disconnect")
        return Step.NOTHING

    def on_start(self) -> Stop:
        return Stop(StopReason.RESET, "the printer restarted (firmware reset) during the print")

    # ------------------------------------------------------------- control
    def cancel(self, bed_height: float | None, emergency_parser: bool, now: float) -> list[bytes]:
        """Replace what is left with the cancel sequence; returns frames to write at once.

        A heat wait at the head is ended with M108, sent past the window: Marlin's
        emergency parser acts on it as the bytes arrive.
        """
        if self.cancelling:
            return []
        self.cancelling = True
        self.paused = False
        self.items.clear()
        if self.state is not None:
            self.items.extend(Item(c) for c in cancel_commands(self.state, bed_height=bed_height))
        head = self.head()
        if head is None or code_of(head.text) not in HEAT_WAITS or not emergency_parser:
            return []
        if self.next_number != self.top + 1:
            self.items.appendleft(Item("M108"))  # resending: it goes out in order
            return []
        frame = P.frame(self.next_number, "M108")
        self.history[self.next_number] = (frame, Item("M108"))
        self.top = self.next_number
        self._sent(frame, now)
        return [frame]

    # ------------------------------------------------------------- the end
    def finish(self, stop: Stop | None) -> Finish:
        """The job status for how the stream ended, written into the job state."""
        if stop is not None:
            finish = Finish(STATUS[stop.reason], stop.message, stop)
        elif self.cancelling:
            finish = Finish("cancelled", "cancelled")
        else:
            finish = Finish("done", "")
        if self.state is not None:
            self.state.status = finish.status
            self.state.message = finish.message if stop is not None else ""
        return finish

    def progress_kind(self) -> str:
        """`printing`, `heating`, `paused` or `cancelling`, for progress reports."""
        if self.cancelling:
            return "cancelling"
        if self.paused:
            return "paused"
        head = self.head()
        if head is not None and code_of(head.text) in HEAT_WAITS:
            return "heating"
        return "printing"

    # ------------------------------------------------------------- helpers
    def _answered(self, now: float) -> None:
        self.last_answer = now
        self.consecutive_timeouts = 0

    def _rewind(self, to: int) -> None:
        self.inflight.clear()
        self.epoch += 1
        self.next_number = to
        self.error_seen_at = None

    def _confirm_through(self, number: int) -> None:
        while self.confirmed < number:
            self.confirmed += 1
            entry = self.history.get(self.confirmed)
            if entry is not None and entry[1].command is not None and self.state is not None:
                self.state.apply(entry[1].command)  # only program lines move the job
            old = self.confirmed - self.history_len
            self.history.pop(old, None)
