"""USB serial link to Marlin firmware: stream G-code so that no line is lost or run twice.

How exactly-once works. Every line goes out as `N<n> <cmd>*<xor>`; the firmware
only accepts line `last + 1` and answers anything else with
`Resend: <last + 1>`, so a line number can never run twice, and a line that is
missing is asked for. The host therefore (1) sends every line number, in
order, keeping the sent lines (`history`) until they are acknowledged, (2) on
`Resend: r` sends again from `r` (the printer is the authority on what it has
run), and (3) when the printer says nothing at all (or says `wait`, idle, while
a line is unanswered) sends again from the first line it has not seen
acknowledged: a copy of a line it already ran is refused by its number.

The send window holds at most `window` unacknowledged lines and `rx_buffer`
bytes (Marlin's receive buffer is 128 bytes). Each line sent (`_Copy`) gets
exactly one `ok` from the firmware, preceded by `Resend:` when it was refused;
responses to copies sent before the latest rewind are stale and ignored.

A reader thread turns the port's bytes into classified replies (`protocol.Reply`)
on a queue; the thread that called `print_gcode` runs the protocol: it writes,
and waits on the queue (no polling loops).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from . import protocol as P
from .base import (
    CANCELLED,
    CANCELLING,
    DONE,
    HEATING,
    PAUSED,
    PRINTING,
    LinkError,
    LinkLost,
    PrinterHalted,
    PrinterReset,
    PrintLink,
    Progress,
    ProgressCallback,
    eta,
)
from .job import Command, JobState, Program, cancel_commands, new_state

log = logging.getLogger("arapp.printing.link")

_LINK_LOST = "link_lost"  # reader-thread event kind
_WAKE = "wake"  # pause/resume/cancel from another thread


@dataclass
class _Item:
    """A line to send: a program command (`command` set) or a host command."""

    text: str
    command: Command | None = None


@dataclass
class _Copy:
    """One transmission of a numbered line."""

    number: int
    size: int
    epoch: int
    sent_at: float
    rejected: bool = False


class SerialPrinter(PrintLink):
    """A Marlin printer on a serial port (pyserial URL or device path).

    window: unacknowledged lines allowed in flight (1 = wait for each `ok`).
    rx_buffer: unacknowledged bytes allowed in flight.
    timeout: seconds without any reply, with a line unanswered, before it is sent again.
    max_timeouts: consecutive unanswered resends before the link counts as lost.
    boot_wait: seconds between connection hellos (a board that resets on open
        needs its bootloader time); connect_timeout: give up after this long.
    job_path: where the job state is saved (on layer changes, on stop, on failure).
    bed_height: mm, caps the nozzle lift of a cancel.
    """

    def __init__(
        self,
        port: str,
        baud: int = 115200,
        *,
        window: int = 1,
        rx_buffer: int = 127,
        timeout: float = 10.0,
        max_timeouts: int = 5,
        boot_wait: float = 3.0,
        connect_timeout: float = 15.0,
        temp_interval: float = 2.0,
        job_path=None,
        bed_height: float | None = None,
        history: int = 1024,
    ):
        if window < 1:
            raise ValueError(f"window must be at least 1 line, got {window}")
        self.port = port
        self.baud = int(baud)
        self.window = int(window)
        self.rx_buffer = int(rx_buffer)
        self.timeout = float(timeout)
        self.max_timeouts = int(max_timeouts)
        self.boot_wait = float(boot_wait)
        self.connect_timeout = float(connect_timeout)
        self.temp_interval = float(temp_interval)
        self.job_path = job_path
        self.bed_height = bed_height
        self._history_len = int(history)

        self._serial = None
        self._reader: threading.Thread | None = None
        self._events: queue.Queue = queue.Queue()
        self._closing = threading.Event()
        self._write_lock = threading.Lock()

        self._pause_req = threading.Event()
        self._cancel_req = threading.Event()

        # line-number bookkeeping (see module doc)
        self._history: dict[int, tuple[bytes, _Item]] = {}
        self._top = -1  # highest number sent so far
        self._next = 0  # next number to send
        self._confirmed = -1  # highest number known run by the printer
        self._inflight: deque[_Copy] = deque()
        self._epoch = 0

        self.firmware = ""
        self.capabilities: dict[str, bool] = {}
        self.temperatures: dict = {}
        self.messages: list[str] = []  # echo: lines, latest last (bounded)
        self.state: JobState | None = None
        self.resends = 0
        self.timeouts = 0

    # ------------------------------------------------------------------ port
    def connect(self) -> None:
        """Open the port, wait for the firmware, reset line numbers (M110), ask M115."""
        import serial

        try:
            self._serial = serial.serial_for_url(
                self.port, baudrate=self.baud, timeout=None, write_timeout=10.0
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise OSError(
                f"cannot open printer port {self.port!r}: {exc}; check the cable, "
                "the device name (ls /dev/ttyUSB* /dev/ttyACM*) and that your user may use it "
                "(group dialout)"
            ) from exc
        self._closing.clear()
        self._reader = threading.Thread(target=self._read_loop, name="arapp-serial-reader", daemon=True)
        self._reader.start()

        self._handshake()
        self._run([_Item("M115")], progress=None, cancel=None, connecting=True)
        if self.capabilities.get("AUTOREPORT_TEMP"):
            self._run([_Item(f"M155 S{max(1, round(self.temp_interval))}")], None, None, connecting=True)

    def _handshake(self) -> None:
        """Reset line numbers with `N0 M110 N0` until the firmware answers `ok`.

        Boards that reset when the port opens print `start` after their
        bootloader; others say nothing. The hello is repeated every
        `boot_wait` seconds (and right after a `start`) until `connect_timeout`.
        """
        hello = P.frame(0, "M110 N0")
        deadline = time.monotonic() + self.connect_timeout
        sent = 0
        while True:
            self._write(hello)
            sent += 1
            retry_at = min(deadline, time.monotonic() + self.boot_wait)
            answer = None
            while answer is None:
                ev = self._get_event(retry_at)
                if ev is None:
                    break
                if isinstance(ev, BaseException):
                    raise LinkLost(f"printer port {self.port} closed while connecting: {ev}")
                if ev.kind in (P.OK, P.START, P.FATAL):
                    answer = ev
            if answer is not None and answer.kind == P.OK:
                break
            if answer is not None and answer.kind == P.FATAL:
                raise PrinterHalted(f"the printer reports a halt: {answer.text} (reset it, or send M999)")
            if time.monotonic() >= deadline:
                raise LinkLost(
                    f"no answer from a printer on {self.port} at {self.baud} baud within "
                    f"{self.connect_timeout:g} s; check the baud rate and that the printer is on"
                )
        if sent > 1:
            # Repeated hellos each get an `ok`: let the extra ones arrive and drop them.
            quiet = time.monotonic() + 0.5
            while (ev := self._get_event(quiet)) is not None:
                if isinstance(ev, BaseException):
                    raise LinkLost(f"printer port {self.port} closed while connecting: {ev}")
        self._next, self._top, self._confirmed = 1, 0, 0
        self._history.clear()
        self._inflight.clear()
        self._history[0] = (hello, _Item("M110 N0"))

    def close(self) -> None:
        """Close the port (does not stop the printer; cancel first for that)."""
        self._closing.set()
        ser = self._serial
        if ser is not None:
            cancel_read = getattr(ser, "cancel_read", None)
            if cancel_read is not None:
                cancel_read()
            if self._reader is not None:
                self._reader.join(timeout=2.0)
            ser.close()
        self._serial = None

    def _read_loop(self) -> None:
        """Reader thread: bytes -> lines -> classified replies on the event queue."""
        import serial

        ser = self._serial
        buf = b""
        try:
            while not self._closing.is_set():
                chunk = ser.read(1)
                if not chunk:
                    continue  # read cancelled (close) or port timeout
                waiting = ser.in_waiting
                if waiting:
                    chunk += ser.read(waiting)
                buf += chunk
                *lines, buf = buf.split(b"\n")
                for raw in lines:
                    text = raw.decode("ascii", errors="replace").strip("\r\x00 ")
                    if not text:
                        continue
                    log.debug("<<< %s", text)
                    self._events.put(P.parse_reply(text))
        except (serial.SerialException, OSError) as exc:
            if not self._closing.is_set():
                self._events.put(exc)

    def _write(self, data: bytes) -> None:
        import serial

        log.debug(">>> %s", data.decode("ascii", errors="replace").rstrip())
        try:
            with self._write_lock:
                self._serial.write(data)
        except (serial.SerialException, OSError) as exc:
            raise _Lost(f"writing to {self.port} failed: {exc}") from exc

    def _get_event(self, deadline: float | None):
        timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
        try:
            return self._events.get(timeout=timeout)
        except queue.Empty:
            return None

    # ------------------------------------------------------------ controls
    def pause(self) -> None:
        """Stop sending after the lines in flight; heaters stay as they are."""
        self._pause_req.set()
        self._events.put(_WAKE)

    def resume(self) -> None:
        self._pause_req.clear()
        self._events.put(_WAKE)

    def cancel(self) -> None:
        """Stop the job: heaters and fan off, nozzle up, motors off."""
        self._cancel_req.set()
        self._events.put(_WAKE)

    def send_commands(self, commands: Sequence[str]) -> None:
        """Run host commands (e.g. from a console) and wait until all are acknowledged."""
        self._run([_Item(P.clean_command(c)) for c in commands if P.clean_command(c)], None, None)

    # ---------------------------------------------------------------- job
    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        program: Program | None = None,
        state: JobState | None = None,
        preamble: Sequence[str] = (),
        gcode_path: str = "",
    ) -> JobState:
        """Stream G-code; block until done or cancelled. Returns the final job state.

        To resume, pass the saved `state` (its `next_line` is where the job
        continues) and a `preamble` (job.resume_commands) that runs first.
        """
        if self._serial is None:
            raise LinkError("the printer is not connected: call connect() first")
        program = program or Program.from_lines(lines)
        if state is None:
            state = new_state(program, gcode_path)
        state.port, state.baud = self.port, self.baud
        state.commands_total = len(program.commands)
        state.status = PRINTING
        self.state = state
        self._pause_req.clear()
        self._cancel_req.clear()
        start = program.position_of(state.next_line)
        items = [_Item(P.clean_command(c)) for c in preamble if P.clean_command(c)]
        items += [_Item(c.text, c) for c in program.commands[start:]]
        self._run(items, progress, cancel)
        return state

    # -------------------------------------------------------- the protocol
    def _run(self, items, progress, cancel, connecting: bool = False) -> None:
        """Send `items`, handle every reply, return when all ran (or cancelled)."""
        items = deque(items)
        state = self.state if not connecting else None
        t0 = time.monotonic()
        last_reply = time.monotonic()
        last_report = 0.0
        last_save = time.monotonic()
        last_temp_poll = time.monotonic()
        done_at_start = state.commands_done if state else 0
        cancelling = False
        error_seen_at = None  # a recoverable error without its resend request yet
        consecutive_timeouts = 0
        fatal: list[str] = []
        lost: str | None = None
        poll_temps = not connecting and not self.capabilities.get("AUTOREPORT_TEMP")

        last_kind = None
        last_layer = None

        def report(kind: str, force: bool = False):
            # At most 10 per second, but every change of state and of layer is reported (the AR
            # preview highlights the layer being printed from these reports).
            nonlocal last_report, last_kind, last_layer
            if progress is None or state is None:
                return
            now = time.monotonic()
            if not force and kind == last_kind and state.layer == last_layer and now - last_report < 0.1:
                return
            last_report, last_kind, last_layer = now, kind, state.layer
            elapsed = now - t0
            progress(self._progress(state, kind, elapsed, done_at_start))

        def current_kind_heating() -> bool:
            head = self._history.get(self._inflight[0].number) if self._inflight else None
            return bool(head) and head[1].text.split()[0].upper() in ("M109", "M190")

        def current_kind():
            if cancelling:
                return CANCELLING
            if self._pause_req.is_set():
                return PAUSED
            head = self._history.get(self._inflight[0].number) if self._inflight else None
            if head and head[1].text.split()[0].upper() in ("M109", "M190"):
                return HEATING
            return PRINTING

        applied = [self._confirmed]  # highest number applied to the job state

        def executed(number: int):
            frame_item = self._history.get(number)
            if frame_item is None or number <= applied[0]:
                return  # unknown, or already counted (the printer asked again for a line it had)
            applied[0] = number
            item = frame_item[1]
            if state is not None:
                if item.command is not None:
                    state.apply(item.command)
                else:
                    state.apply(Command(-1, item.text, state.layer))
            # Drop history far behind the confirmed line.
            old = number - self._history_len
            if old in self._history:
                del self._history[old]

        def confirm_through(number: int):
            while self._confirmed < number:
                self._confirmed += 1
                executed(self._confirmed)

        def rewind(to: int):
            self._inflight.clear()
            self._epoch += 1
            self._next = to

        def finished() -> bool:
            return not items and self._next > self._top and not self._inflight and self._confirmed >= self._top

        try:
            while True:
                # -- cancel requests
                if (self._cancel_req.is_set() or (cancel is not None and cancel.is_set())) and not cancelling and not connecting:
                    cancelling = True
                    items.clear()
                    self._pause_req.clear()
                    if state is not None:
                        state.status = CANCELLING
                        items.extend(_Item(c) for c in cancel_commands(state, bed_height=self.bed_height))
                    report(CANCELLING, force=True)
                    if current_kind_heating() and self.capabilities.get("EMERGENCY_PARSER"):
                        # Marlin's emergency parser acts on M108 as the bytes arrive, ending
                        # the heat wait at once; it is sent past the window for that reason.
                        item = _Item("M108")
                        frame = P.frame(self._top + 1, item.text)
                        self._history[self._top + 1] = (frame, item)
                        if self._next == self._top + 1:
                            self._top += 1
                            self._write(frame)
                            self._inflight.append(_Copy(self._next, len(frame), self._epoch, time.monotonic()))
                            self._next += 1
                        else:
                            del self._history[self._top + 1]  # resending: it goes out in order
                            items.appendleft(item)
                # -- send while the window has room
                while (
                    len(self._inflight) < self.window
                    and (not self._pause_req.is_set() or self._next <= self._top or cancelling)
                ):
                    if self._next <= self._top:
                        frame = self._history[self._next][0]
                    elif items:
                        if (
                            poll_temps
                            and time.monotonic() - last_temp_poll > self.temp_interval
                        ):
                            item = _Item("M105")
                            last_temp_poll = time.monotonic()
                        else:
                            item = items.popleft()
                        frame = P.frame(self._next, item.text)
                        self._history[self._next] = (frame, item)
                        self._top = self._next
                    else:
                        break
                    inflight_bytes = sum(c.size for c in self._inflight)
                    if self._inflight and inflight_bytes + len(frame) > self.rx_buffer:
                        break
                    self._write(frame)
                    self._inflight.append(_Copy(self._next, len(frame), self._epoch, time.monotonic()))
                    self._next += 1
                if finished():
                    break
                # -- wait for a reply (or a timeout)
                now = time.monotonic()
                if self._inflight:
                    deadline = last_reply + self.timeout
                    if error_seen_at is not None:
                        deadline = min(deadline, error_seen_at + min(1.0, self.timeout))
                elif self._pause_req.is_set() and poll_temps:
                    deadline = last_temp_poll + self.temp_interval
                else:
                    deadline = now + self.timeout
                wake = deadline
                if cancel is not None and not cancelling:
                    wake = min(deadline, now + 0.25)  # an external Event cannot wake the queue: look at it
                ev = self._get_event(wake)
                if ev is None:
                    if time.monotonic() < deadline - 1e-3:
                        pass   # only woken to look at the cancel Event (checked at the loop's top)
                    elif self._inflight:
                        consecutive_timeouts += 1
                        self.timeouts += 1
                        if consecutive_timeouts > self.max_timeouts:
                            lost = f"the printer on {self.port} stopped answering (no reply for {self.timeout:g} s, {self.max_timeouts} times)"
                            break
                        log.info("no answer for line %d: sending from %d again", self._inflight[0].number, self._confirmed + 1)
                        error_seen_at = None
                        last_reply = time.monotonic()
                        rewind(self._confirmed + 1)
                    elif self._pause_req.is_set() and poll_temps and not self._inflight:
                        last_temp_poll = 0.0  # poll temperatures while paused
                        self._send_poll()
                        last_temp_poll = time.monotonic()
                    report(current_kind())
                    continue
                if ev == _WAKE:
                    report(current_kind(), force=True)
                    continue
                if isinstance(ev, BaseException):
                    lost = f"the connection to {self.port} was lost: {ev}"
                    break
                last_reply = time.monotonic()
                consecutive_timeouts = 0
                kind = ev.kind
                if ev.temperatures:
                    for name, (actual, target) in ev.temperatures.items():
                        if target is None and name in self.temperatures:
                            target = self.temperatures[name][1]  # heat-up lines carry no target
                        self.temperatures[name] = (actual, target)
                    if state is not None:
                        state.read_temperatures(ev.temperatures)
                    report(current_kind(), force=True)
                if kind == P.OK:
                    error_seen_at = None
                    if self._inflight:
                        copy = self._inflight.popleft()
                        if not copy.rejected and copy.number > self._confirmed:
                            confirm_through(copy.number)
                    report(current_kind())
                elif kind == P.RESEND:
                    error_seen_at = None
                    self.resends += 1
                    head = self._inflight[0] if self._inflight else None
                    if head is not None:
                        stale = head.epoch < self._epoch
                        head.rejected = True  # the `ok` that follows answers this request
                        if stale:
                            continue  # answers a copy sent before the last rewind
                    r = ev.line
                    if r > self._top + 1:
                        raise LinkError(
                            f"the printer asked to resend line {r}, but the last line sent was {self._top}"
                        )
                    if r <= self._top and r not in self._history:
                        raise LinkError(f"the printer asked to resend line {r}, which is no longer in the history")
                    if r - 1 > self._confirmed:
                        confirm_through(r - 1)
                    elif r - 1 < self._confirmed:
                        log.warning("printer asks again for line %d, acknowledged before", r)
                        self._confirmed = r - 1
                    # Copies still in flight become stale; they absorb their own replies.
                    self._epoch += 1
                    self._next = r
                elif kind == P.ERROR:
                    log.info("printer: %s", ev.text)
                    if self._inflight and error_seen_at is None:
                        error_seen_at = time.monotonic()
                elif kind == P.WAIT:
                    # Idle with a line unanswered: the printer lost it.
                    if self._inflight and time.monotonic() - self._inflight[0].sent_at > 0.25:
                        self.timeouts += 1
                        error_seen_at = None
                        rewind(self._confirmed + 1)
                elif kind == P.FATAL:
                    fatal.append(ev.text)
                    self._collect_fatal(fatal)
                    break
                elif kind == P.START:
                    if not connecting:
                        lost = "the printer restarted (firmware reset) during the print"
                        break
                elif kind == P.ACTION:
                    action = ev.text.split()[0].lower() if ev.text else ""
                    if action == "pause":
                        self._pause_req.set()
                    elif action == "resume":
                        self._pause_req.clear()
                    elif action == "cancel":
                        self._cancel_req.set()
                    elif action == "disconnect":
                        lost = "the printer asked the host to disconnect"
                        break
                elif kind in (P.ECHO, P.OTHER):
                    self._note_message(ev)
                report(current_kind())
                if state is not None and time.monotonic() - last_save > 5.0 and self.job_path:
                    state.save(self.job_path)
                    last_save = time.monotonic()
        except _Lost as exc:
            lost = str(exc)

        if state is not None:
            elapsed = time.monotonic() - t0
            if fatal:
                state.status, state.message = "halted", "; ".join(fatal)
            elif lost:
                state.status = "reset" if "restarted" in lost else "link_lost"
                state.message = lost
            elif cancelling:
                state.status = CANCELLED
            elif not connecting and state.status in (PRINTING, CANCELLING):
                state.status = DONE
            if self.job_path:
                state.save(self.job_path)
            if progress is not None:
                progress(self._progress(state, state.status, elapsed, done_at_start))
        if fatal:
            raise PrinterHalted(f"the printer halted: {'; '.join(fatal)}", self.state, self.job_path)
        if lost:
            cls = PrinterReset if "restarted" in lost else LinkLost
            raise cls(lost, state, self.job_path if state is not None else None)

    def _send_poll(self) -> None:
        """Ask for temperatures as a numbered line (used while paused)."""
        item = _Item("M105")
        frame = P.frame(self._next, item.text)
        self._history[self._next] = (frame, item)
        self._top = self._next
        self._write(frame)
        self._inflight.append(_Copy(self._next, len(frame), self._epoch, time.monotonic()))
        self._next += 1

    def _collect_fatal(self, fatal: list[str]) -> None:
        """Gather the rest of a halt message (Marlin prints several lines)."""
        deadline = time.monotonic() + 0.3
        while True:
            ev = self._get_event(deadline)
            if ev is None or isinstance(ev, BaseException):
                return
            if ev.kind in (P.FATAL, P.ECHO) and ev.text and ev.text not in fatal:
                fatal.append(ev.text)

    def _note_message(self, ev: P.Reply) -> None:
        text = ev.text
        if text.startswith("FIRMWARE_NAME:"):
            self.firmware = text
        elif text.startswith("Cap:"):
            parts = text[4:].split(":")
            if len(parts) == 2:
                self.capabilities[parts[0].upper()] = parts[1].strip() == "1"
        elif ev.kind == P.ECHO:
            self.messages.append(text)
            del self.messages[:-50]

    def _progress(self, state: JobState, kind: str, elapsed: float, done_at_start: int) -> Progress:
        total = state.commands_total
        done = state.commands_done
        percent = 100.0 * done / total if total else 100.0
        return Progress(
            state=kind,
            lines_done=done,
            lines_total=total,
            layer=state.layer,
            layer_count=state.layer_count,
            percent=percent,
            elapsed_s=elapsed,
            eta_s=eta(done - done_at_start, total - done_at_start, elapsed),
            temperatures=dict(self.temperatures),
            message=state.message,
        )


class _Lost(Exception):
    """Internal: a write failed, the link is gone."""
