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
- Liveness (issue #27): any line from the printer means it is alive. It
  "stopped answering" only after `max_timeouts` windows (`timeout` seconds
  each) in which nothing at all arrived while a line waited for its answer;
  while a blocking command (M109, M190, G28, G29, G4, M0/M1, M600, M400) is
  the oldest line unanswered on a printer that has sent no `busy:` yet, that
  limit is `blocking_timeout` (a silent firmware homes or probes for minutes).
- Progress: a line newly acknowledged (`ok`), or a keep-alive that says the
  firmware is working (`busy: processing`, `echo:busy: paused for user`, a
  heat wait's temperature line), restarts the window (a honoured `Resend:`
  restarts it from the copy asked for; a loop of requests is not progress). A window without one is
  answered by a poke, never by sending a line again: a numbered `M105` on the
  next free line number (`N<top+1> M105`), sent past the window while
  Marlin's receive buffer has room. A busy firmware runs it after the line it
  is busy with (harmless, nothing runs twice); a firmware that lost a line
  refuses it by number and asks `Resend:` for the lost one; a firmware whose
  `ok` was lost answers it `ok T:...`, which accounts for every line before
  it (Marlin runs lines in order and takes N only after N-1). A line goes
  out again only when the firmware asks for it. With no progress for as long
  as the liveness limit although the printer talks (temperature reports
  only), the stream stops too: it never waits for ever.
- A resend request for a line the firmware confirmed, or for line 0 after the
  start-up exchange, cannot come from a healthy exchange (a reset without its
  banner, or noise): the stream stops (`StopReason.BAD_RESEND`), it never
  replays. A request is honoured once: the same request again, without an
  `Error:` line of its own, before the line was answered is a doubled reply,
  and its `ok` is absorbed.
- An `Error:` without a `Resend:` after it (OctoPrint's VirtualPrinter's
  missing line number) is the whole answer to the oldest copy: known when the
  next copy's own `Error:` comes first, else after a short wait. A `Resend:`
  read after that wait (a loaded host reads late) gives the copy back: each
  `ok` must stay with the copy it answers, or a later one is confirmed early.
- Never more than `window` lines (and `rx_buffer` bytes) in flight, pokes
  apart (they stop at `rx_buffer` bytes once one is in flight).

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
    WAITING = "waiting"  # the deadline has not come yet
    POKE = "poke"  # a window without progress: a numbered M105 goes out (frames_to_send)
    PAUSE = "pause"
    RESUME = "resume"
    CANCEL = "cancel"


class StopReason(enum.Enum):
    HALTED = "halted"  # the firmware said Error:/!! (not a line error)
    RESET = "reset"  # the firmware printed its start banner
    BAD_RESEND = "bad_resend"  # a resend request no healthy exchange produces
    NO_ANSWER = "no_answer"  # nothing from the printer (or no progress) for the liveness limit
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
    bytes allowed in flight; timeout: the progress window, seconds without an
    answer or keep-alive before a poke (M105); max_timeouts: windows without a
    byte from the printer (or without progress) before it counts as gone;
    blocking_timeout: that limit in seconds while a blocking command is the
    oldest line unanswered on a printer that sends no keep-alives;
    poll_interval: seconds between host M105 polls (0: no polls);
    history_len: lines kept for resends.
    """

    window: int = 1
    rx_buffer: int = 127
    timeout: float = 10.0
    blocking_timeout: float = 600.0
    max_timeouts: int = 12
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

    last_byte: float = 0.0  # liveness: the last line of any kind from the printer
    last_progress: float = 0.0  # progress: the last answer or working keep-alive
    last_tick: float = 0.0  # the last window that ran out (a poke, or one skipped for room)
    last_poll: float = 0.0
    error_seen_at: float | None = None
    consecutive_timeouts: int = 0  # windows without progress since the last progress
    poke_due: bool = False
    pokes: int = 0  # M105 pokes sent
    plain_ok_seen: bool = False  # the firmware answers other lines with a bare `ok` (see on_ok)
    absorb_oks: int = 0
    honoured: tuple | None = None  # (line, confirmed then) of the last resend request honoured
    # The copy the short error wait took as answered by its `Error:` alone (on_timeout); its
    # `Resend:` may still come, read late on a loaded host (on_resend puts it back).
    error_only: Copy | None = None
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
        self.honoured, self.absorb_oks, self.error_only = None, 0, None
        self.last_byte = self.last_progress = self.last_tick = now
        self.poke_due = False

    def start(self, items, state: JobState | None, now: float) -> None:
        """Queue `items` for a run; `state` (None while connecting) follows the program lines."""
        self.items = deque(items)
        self.state = state
        self.cancelling = False
        self.consecutive_timeouts = 0
        self.error_seen_at = None
        self.poke_due = False
        self.last_byte = self.last_progress = self.last_tick = self.last_poll = now

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

        A due temperature poll (M105) goes out between program lines; a due
        poke (on_timeout, on_wait) goes out first, past the window.
        """
        out = []
        if self.poke_due:
            self.poke_due = False
            frame = self._poke(now)
            if frame is not None:
                out.append(frame)
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
            if self.inflight and self._bytes_in_flight() + len(frame) > self.rx_buffer:
                break  # Marlin's receive buffer would overflow; it goes out after the next answer
            self._sent(self.next_number, frame, now)
            self.next_number += 1
            out.append(frame)
        return out

    def _poke(self, now: float) -> bytes | None:
        """A numbered M105 on the next free number (top + 1), or None when a poke already waits in
        the printer's buffer and another would not fit in `rx_buffer` (it would only overflow)."""
        number = self.top + 1
        frame = P.frame(number, "M105")
        waiting = any(self._is_m105(c) and not c.rejected for c in self.inflight)
        if waiting and self._bytes_in_flight() + len(frame) > self.rx_buffer:
            return None
        self.history[number] = (frame, Item("M105"))
        self.top = number
        self._sent(number, frame, now)
        if self.next_number == number:
            self.next_number += 1
        # else: a resend is going on; this line goes out again in its turn, after the resent ones.
        self.pokes += 1
        return frame

    def _is_m105(self, copy: Copy) -> bool:
        entry = self.history.get(copy.number)
        return entry is not None and entry[1].command is None and entry[1].text == "M105"

    def _bytes_in_flight(self) -> int:
        return sum(c.size for c in self.inflight)

    def poll_frame(self, now: float) -> bytes | None:
        """A numbered M105 while paused (nothing else in flight), when a poll is due."""
        if not self.paused or self.inflight or self.poll_interval <= 0 or now - self.last_poll < self.poll_interval:
            return None
        self.last_poll = now
        frame = P.frame(self.next_number, "M105")
        self.history[self.next_number] = (frame, Item("M105"))
        self.top = self.next_number
        self._sent(self.next_number, frame, now)
        self.next_number += 1
        return frame

    def _sent(self, number: int, frame: bytes, now: float) -> None:
        if not self.inflight:
            # The timers run from the first line in flight: an idle printer may say nothing.
            self.last_progress = max(self.last_progress, now)
            self.last_byte = max(self.last_byte, now)
        self.inflight.append(Copy(number, len(frame), self.epoch, now))
        self.max_inflight = max(self.max_inflight, len(self.inflight))

    def finished(self) -> bool:
        return (not self.items and self.next_number > self.top and not self.inflight
                and self.confirmed >= self.top)

    # ------------------------------------------------------------- replies
    def on_line(self, now: float) -> None:
        """Any line from the printer (liveness): call it before the reply's own method."""
        self.last_byte = now

    def on_ok(self, now: float, temperatures: bool = False) -> Step:
        """`ok`: the oldest copy in flight was answered (run, or refused when a resend request came first).

        `temperatures`: the ok carries a temperature report (`ok T:...`), which Marlin sends only as
        the answer to M105. On a firmware that answers other lines with a bare `ok`, such an ok
        answers the oldest M105 in flight: the copies before it lost their answers, and every line up
        to that M105's number was taken (Marlin takes N only after N-1).
        """
        self.error_seen_at = None
        self.error_only = None
        self.last_byte = now
        if temperatures and self.plain_ok_seen:
            for i, copy in enumerate(self.inflight):
                if self._is_m105(copy) and not copy.rejected:
                    for _ in range(i + 1):
                        self.inflight.popleft()
                    if copy.number <= self.confirmed:
                        return Step.IGNORED
                    self._confirm_through(copy.number)
                    self._answered(now)
                    return Step.CONFIRMED
        elif not temperatures:
            self.plain_ok_seen = True
        if self.absorb_oks:
            self.absorb_oks -= 1
            return Step.IGNORED
        if not self.inflight:
            return Step.IGNORED  # an ok nothing asked for (e.g. a late answer after a rewind)
        copy = self.inflight.popleft()
        if copy.rejected or copy.number <= self.confirmed:
            return Step.IGNORED
        self._confirm_through(copy.number)
        self._answered(now)  # progress: a line newly acknowledged
        return Step.CONFIRMED

    def on_resend(self, line: int, now: float) -> Step | Stop:
        """`Resend: line`: the printer's last accepted line is `line - 1`."""
        after_error = self.error_seen_at is not None  # a request with its own `Error:` line is a new one
        self.error_seen_at = None
        if self.error_only is not None and not after_error:
            # The request that followed the `Error:` the error wait took as the whole answer, read late:
            # the copy was answered by both, so it is in flight again (else every later `ok` would be
            # counted for the line after the one it answers).
            self.inflight.appendleft(self.error_only)
            after_error = True
        self.error_only = None
        self.last_byte = now  # alive; progress only once the line asked for is acknowledged
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
        if head is not None and head.number >= line and any(c.number == line for c in list(self.inflight)[1:]):
            # The copy refused is one the firmware got after it had missed `line` (a poke sent
            # during a resend, say), and a copy of `line` is already on its way behind it: the
            # firmware takes that one in its turn. Rewinding again would only stack more copies in
            # its buffer, each answered later by the same request.
            head.rejected = True
            return Step.IGNORED
        if head is not None:
            head.rejected = True  # the ok that follows answers this request
        if line - 1 > self.confirmed:
            self._confirm_through(line - 1)
        self.honoured = (line, self.confirmed)
        self.epoch += 1
        self.next_number = line
        self.last_tick = now  # the window runs from the copy asked for
        return Step.REWOUND

    def on_error(self, now: float) -> Step:
        """A recoverable `Error:` (checksum, line number): a resend request should follow at once."""
        if self.error_seen_at is not None and self.inflight:
            # Two `Error:` lines without a `Resend:` between them: the first was the whole answer to the
            # oldest copy (the VirtualPrinter's missing line number); this one answers the next copy.
            self.inflight.popleft()
        self.error_only = None  # the request after this error has its own `Error:` line
        self.error_seen_at = now if self.inflight else None
        return Step.NOTHING

    def on_wait(self, now: float) -> Step:
        """`wait`: the printer is idle with its queue empty. If everything in flight went out a while
        ago and is unanswered, a line or its answer was lost: poke (the firmware's answer to the poke
        says which; nothing is sent again unless it asks)."""
        if self.inflight and not self.head_is_blocking() and now - self.inflight[-1].sent_at > 0.25:
            self.timeouts += 1
            self.last_tick = now
            self.poke_due = True
            return Step.POKE
        return Step.NOTHING

    def on_keepalive(self, reply: P.Reply, now: float) -> Step:
        """`busy:` (any head) or a heat wait's temperature line (M109/M190 head, still heating): the
        firmware is working on the oldest line; progress, so no poke (see module doc). Other
        temperature lines only show the printer is alive (on_line)."""
        head = self.head()
        if head is None:
            return Step.NOTHING
        code = code_of(head.text)
        if reply.kind == P.BUSY:
            self.keepalive_seen = True
            self._working(now)
        elif code in HEAT_WAITS and self._heat_wait_going_on(head.text, code, reply):
            self._working(now)
        return Step.NOTHING

    def _working(self, now: float) -> None:
        self.last_progress = now
        self.consecutive_timeouts = 0

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
        """When `on_timeout` is due: the end of the progress window (None: nothing in flight)."""
        if not self.inflight:
            return None
        deadline = max(self.last_progress, self.last_tick) + self.timeout
        if self.error_seen_at is not None:
            # An `Error:` waits for its `Resend:` (Marlin sends both at once): this long, not less
            # (on_timeout then takes the error as the whole answer) nor more (poke soon).
            deadline = self.error_seen_at + min(1.0, self.timeout)
        return deadline

    def give_up_after(self) -> float:
        """Seconds of silence (or of no progress) before the printer counts as gone (liveness)."""
        limit = self.max_timeouts * self.timeout
        if self.head_is_blocking() and not self.keepalive_seen:
            limit = max(limit, self.blocking_timeout)  # a silent firmware homes or probes for minutes
        return limit

    def on_timeout(self, now: float) -> Step | Stop:
        """A progress window ran out: poke (frames_to_send sends it), or stop when the printer has
        been silent, or has made no progress, for the liveness limit."""
        deadline = self.deadline()
        if deadline is None or now < deadline:
            return Step.WAITING
        limit = self.give_up_after()
        silent, stalled = now - self.last_byte, now - self.last_progress
        if silent >= limit:
            return Stop(StopReason.NO_ANSWER,
                        f"the printer stopped answering (nothing at all received for {silent:.1f} s; "
                        f"the limit is {limit:g} s)")
        if stalled >= limit:
            return Stop(StopReason.NO_ANSWER,
                        f"the printer still talks but has acknowledged no line for {stalled:.1f} s "
                        f"(the limit is {limit:g} s)")
        self.consecutive_timeouts += 1
        self.timeouts += 1
        if self.error_seen_at is not None and now >= self.error_seen_at + min(1.0, self.timeout):
            # An `Error:` with no `Resend:` or `ok` after it (the VirtualPrinter's missing line
            # number): that was the whole answer to the oldest copy; none follows. Not confirmed.
            if self.inflight:
                self.error_only = self.inflight.popleft()
        self.error_seen_at = None
        self.last_tick = now
        self.poke_due = True
        return Step.POKE

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
        self._sent(self.next_number, frame, now)
        self.next_number += 1
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
        self.last_progress = self.last_byte = now
        self.consecutive_timeouts = 0

    def _confirm_through(self, number: int) -> None:
        while self.confirmed < number:
            self.confirmed += 1
            entry = self.history.get(self.confirmed)
            if entry is not None and entry[1].command is not None and self.state is not None:
                self.state.apply(entry[1].command)  # only program lines move the job
            old = self.confirmed - self.history_len
            self.history.pop(old, None)
