"""USB serial link to Marlin firmware: stream G-code so that no line is lost or run twice.

The protocol's rules live in `stream.LineStream` (a state object without
I/O); this module is the I/O around it. A reader thread turns the port's
bytes into classified replies (`protocol.Reply`) on a queue; the thread that
called `print_gcode` writes what the stream says and hands it each reply, or
the passing of its deadline (no polling loops).

Every way out of a run (done, cancelled, firmware halt or reset, no answer,
port gone, a failure in the host) goes through `_end`: heaters, fan and
motors off while the port is still up, the job state saved, one exception
with one line of text.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Sequence

import serial

from . import protocol as P
from .base import (
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
from .job import NOT_RESUMABLE, JobState, Program, new_state
from .stream import Item, LineStream, Step, Stop, StopReason

log = logging.getLogger("arapp.printing.link")

_WAKE = "wake"  # pause/resume/cancel from another thread
# Sent when a print stops any way but done or cancelled: no move, so a resumed job's Z is still right.
SAFE_STOP = ("M104 S0", "M140 S0", "M107", "M84")


class SerialPrinter(PrintLink):
    """A Marlin printer on a serial port (pyserial URL or device path).

    window: unacknowledged lines allowed in flight (1 = wait for each `ok`).
    rx_buffer: unacknowledged bytes allowed in flight.
    timeout: the progress window: seconds without an answer or keep-alive, with a line
        unanswered, before a poke (a numbered M105; nothing is sent again unless the
        printer asks). See stream.py and docs/printer-faults.md.
    max_timeouts: windows without a byte from the printer (or without progress) before
        the link counts as lost (12 x 10 s by default: a 75 s busy move passes).
    blocking_timeout: that limit in seconds while a blocking command (G29, M0, M109...)
        runs on a printer that sends no keep-alives.
    boot_wait: seconds between connection hellos (a board that resets on open
        needs its bootloader time); connect_timeout: give up after this long.
    job_path: where the job state is saved (at the start, every 5 s, at the end).
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
        blocking_timeout: float = 600.0,
        max_timeouts: int = 12,
        boot_wait: float = 3.0,
        connect_timeout: float = 15.0,
        temp_interval: float = 2.0,
        job_path=None,
        bed_height: float | None = None,
        history: int = 1024,
    ):
        if window < 1:
            raise ValueError(f"window must be at least 1 line, got {window}")
        if not timeout > 0:
            raise ValueError(f"timeout must be positive seconds, got {timeout}")
        self.port = port
        self.baud = int(baud)
        self.window = int(window)
        self.timeout = float(timeout)
        self.boot_wait = float(boot_wait)
        self.connect_timeout = float(connect_timeout)
        self.temp_interval = float(temp_interval)
        self.job_path = job_path
        self.bed_height = bed_height
        self._stream = LineStream(window=int(window), rx_buffer=int(rx_buffer), timeout=float(timeout),
                                  blocking_timeout=float(blocking_timeout), max_timeouts=int(max_timeouts),
                                  history_len=int(history))

        self._serial = None
        self._reader: threading.Thread | None = None
        self._events: queue.Queue = queue.Queue()
        self._closing = threading.Event()
        self._write_lock = threading.Lock()

        self._pause_req = threading.Event()
        self._cancel_req = threading.Event()
        self._last_save = 0.0

        self.firmware = ""
        self.capabilities: dict[str, bool] = {}
        self.temperatures: dict = {}
        self.messages: list[str] = []  # echo: lines, latest last (bounded)
        self.state: JobState | None = None
        self.save_error: str | None = None

    @property
    def resends(self) -> int:
        """Resend requests the printer made so far."""
        return self._stream.resends

    @property
    def timeouts(self) -> int:
        """Progress windows that ran out (each answered by a poke, or by none when one already waits)."""
        return self._stream.timeouts

    @property
    def pokes(self) -> int:
        """M105 pokes sent for windows without progress."""
        return self._stream.pokes

    @property
    def max_inflight(self) -> int:
        """The most lines that were in flight at once."""
        return self._stream.max_inflight

    # ------------------------------------------------------------------ port
    def connect(self) -> None:
        """Open the port, wait for the firmware, reset line numbers (M110), ask M115."""
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
        self._run([Item("M115")], progress=None, cancel=None, connecting=True)
        if self.capabilities.get("AUTOREPORT_TEMP"):
            self._run([Item(f"M155 S{max(1, round(self.temp_interval))}")], None, None, connecting=True)

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
                if ev is not _WAKE and ev.kind in (P.OK, P.START, P.FATAL):
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
        self._stream.reset_numbering(time.monotonic())

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
        """Stop the job: heaters and fan off, nozzle up, motors off. Returns at once; the
        printing thread sends the cancel sequence (a `cancel` Event given to print_gcode
        does the same)."""
        self._cancel_req.set()
        self._events.put(_WAKE)

    def send_commands(self, commands: Sequence[str]) -> None:
        """Run host commands (e.g. from a console) and wait until all are acknowledged."""
        self._run([Item(P.clean_command(c)) for c in commands if P.clean_command(c)], None, None)

    # ---------------------------------------------------------------- job
    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        gcode_path: str = "",
        program: Program | None = None,
        state: JobState | None = None,
        preamble: Sequence[str] = (),
    ) -> JobState:
        """Stream G-code; block until done or cancelled. Returns the final job state.

        To resume, pass the saved `state` (its `next_line` is where the job
        continues) and a `preamble` (job.resume_commands) that runs first.
        Refuses to start (LinkError, nothing sent) when the job file cannot be
        written or the state is not resumable.
        """
        if self._serial is None:
            raise LinkError("the printer is not connected: call connect() first")
        program = program or Program.from_lines(lines)
        if state is None:
            state = new_state(program, gcode_path)
        elif state.status in NOT_RESUMABLE:
            raise LinkError(f"this job is {state.status}; it cannot be resumed: start the print again")
        state.port, state.baud = self.port, self.baud
        state.commands_total = len(program.commands)
        state.status = PRINTING
        state.message = ""
        self.state = state
        self.save_error = None
        if self.job_path:
            try:
                state.save(self.job_path)
            except OSError as exc:
                raise LinkError(
                    f"cannot write the job file {self.job_path}: {exc.strerror or exc}; "
                    "nothing was sent: choose a writable place with --job"
                ) from exc
            self._last_save = time.monotonic()
        self._pause_req.clear()
        self._cancel_req.clear()
        start = program.position_of(state.next_line)
        items = [Item(P.clean_command(c)) for c in preamble if P.clean_command(c)]
        items += [Item(c.text, c) for c in program.commands[start:]]
        self._run(items, progress, cancel)
        return state

    # -------------------------------------------------------- the I/O loop
    def _run(self, items, progress, cancel, connecting: bool = False) -> None:
        """Send `items` through the stream, feed it every reply; end as `_end` says."""
        stream = self._stream
        state = None if connecting else self.state
        stream.start(items, state, time.monotonic())
        autoreport = self.capabilities.get("AUTOREPORT_TEMP")
        stream.poll_interval = 0.0 if connecting or autoreport else self.temp_interval
        report = _Reporter(self, progress, state)
        try:
            stop = self._exchange(stream, cancel, report, connecting)
        except _Lost as exc:
            stop = Stop(StopReason.LINK_LOST, str(exc))
        except Exception as exc:  # noqa: BLE001 - any failure of the host ends the print the safe way
            log.exception("print stopped by an error in the host")
            stop = Stop(StopReason.FAILED, f"the print stopped on an error in arapp: {type(exc).__name__}: {exc}")
        self._end(stream, stop, report, connecting)

    def _exchange(self, stream: LineStream, cancel, report: "_Reporter", connecting: bool) -> Stop | None:
        """Write, wait for a reply or a deadline, hand it to the stream; until finished or stopped."""
        while True:
            now = time.monotonic()
            if not connecting and not stream.cancelling and (
                self._cancel_req.is_set() or (cancel is not None and cancel.is_set())
            ):
                for frame in stream.cancel(self.bed_height, self.capabilities.get("EMERGENCY_PARSER", False), now):
                    self._write(frame)
                report(stream.progress_kind(), force=True)
            if not stream.cancelling:
                stream.paused = self._pause_req.is_set()
            for frame in stream.frames_to_send(now):
                self._write(frame)
            if stream.finished():
                return None
            deadline = stream.deadline()
            if deadline is None and stream.paused and stream.poll_interval > 0:
                deadline = stream.last_poll + stream.poll_interval
            wake = deadline
            if cancel is not None and not stream.cancelling:
                # An external Event cannot wake the queue: look at it 4 times a second.
                wake = now + 0.25 if wake is None else min(wake, now + 0.25)
            ev = self._get_event(wake)
            now = time.monotonic()
            if ev is None:
                if stream.paused and not stream.inflight:
                    frame = stream.poll_frame(now)
                    if frame is not None:
                        self._write(frame)
                elif deadline is not None and now >= deadline:
                    step = stream.on_timeout(now)
                    if isinstance(step, Stop):
                        return Stop(step.reason, f"{step.message} on {self.port}")
                    if step is Step.POKE:
                        log.info("no progress for %g s: poking with M105", stream.timeout)
                report(stream.progress_kind())
                continue
            if ev is _WAKE:
                report(stream.progress_kind(), force=True)
                continue
            if isinstance(ev, BaseException):
                return Stop(StopReason.LINK_LOST, f"the connection to {self.port} was lost: {ev}")
            stop = self._on_reply(stream, ev, now, report, connecting)
            if stop is not None:
                return stop
            report(stream.progress_kind())
            self._save_now_and_then(stream.state)

    def _on_reply(self, stream: LineStream, ev: P.Reply, now: float, report, connecting: bool) -> Stop | None:
        """Hand one reply to the stream; a Stop when it ends the exchange."""
        if ev.temperatures:
            for name, (actual, target) in ev.temperatures.items():
                if target is None and name in self.temperatures:
                    target = self.temperatures[name][1]  # heat-up lines carry no target
                self.temperatures[name] = (actual, target)
            if stream.state is not None:
                stream.state.read_temperatures(ev.temperatures)
            report(stream.progress_kind(), force=True)
        kind = ev.kind
        stream.on_line(now)  # liveness: any line at all
        if kind == P.OK:
            stream.on_ok(now, temperatures=bool(ev.temperatures))
        elif kind == P.RESEND:
            step = stream.on_resend(ev.line, now)
            if isinstance(step, Stop):
                return step
        elif kind == P.ERROR:
            log.info("printer: %s", ev.text)
            stream.on_error(now)
        elif kind == P.WAIT:
            stream.on_wait(now)
        elif kind in (P.BUSY, P.TEMPERATURE):
            stream.on_keepalive(ev, now)
        elif kind == P.FATAL:
            messages = [ev.text]
            self._collect_fatal(messages)
            return Stop(StopReason.HALTED, "; ".join(messages))
        elif kind == P.START:
            if not connecting:
                return stream.on_start()
        elif kind == P.ACTION:
            step = stream.on_action(ev.text)
            if isinstance(step, Stop):
                return step
            if step is Step.PAUSE:
                self._pause_req.set()
            elif step is Step.RESUME:
                self._pause_req.clear()
            elif step is Step.CANCEL:
                self._cancel_req.set()
        else:
            self._note_message(ev)
        return None

    def _save_now_and_then(self, state: JobState | None) -> None:
        """Save the job every 5 s. A failed save does not stop the print (the file only matters
        if the link drops); it is reported (progress message, final state) and tried again."""
        if state is None or not self.job_path or time.monotonic() - self._last_save < 5.0:
            return
        self._last_save = time.monotonic()
        try:
            state.save(self.job_path)
            self.save_error = None
        except OSError as exc:
            if self.save_error is None:
                log.warning("cannot save the job file %s: %s", self.job_path, exc)
            self.save_error = f"cannot save the job file {self.job_path}: {exc.strerror or exc}"
            state.message = self.save_error

    def _end(self, stream: LineStream, stop: Stop | None, report: "_Reporter", connecting: bool) -> None:
        """Every way out of a run ends here: printer made safe, job saved, one exception (or none)."""
        finish = stream.finish(stop)
        state = stream.state
        if stop is not None and not connecting and stop.reason is not StopReason.LINK_LOST:
            self._safe_stop()
        saved = None
        if state is not None and self.job_path:
            try:
                state.save(self.job_path)
                saved = self.job_path
                self.save_error = None
            except OSError as exc:
                self.save_error = f"cannot save the job file {self.job_path}: {exc.strerror or exc}"
                if stop is None:
                    state.message = self.save_error
        if state is not None:
            try:
                report(finish.status, force=True)
            except Exception:  # noqa: BLE001 - the caller's callback failed; the stop below says what ended the print
                log.exception("the progress callback failed")
        if stop is None:
            return
        message = stop.message
        if state is not None and self.job_path and saved is None:
            message += f" ({self.save_error})"
        if stop.reason is StopReason.HALTED:
            raise PrinterHalted(f"the printer halted: {message}", state, saved)
        if stop.reason in (StopReason.RESET, StopReason.BAD_RESEND):
            raise PrinterReset(message, state, saved)
        if stop.reason is StopReason.FAILED:
            raise LinkError(message, state, saved)
        raise LinkLost(message, state, saved)

    def _safe_stop(self) -> None:
        """Heaters, fan and motors off, as unnumbered lines (the line numbering may be what failed).

        No move: the nozzle stays where it is, so a resumed job's saved Z is still right.
        """
        try:
            for command in SAFE_STOP:
                self._write(f"{command}\n".encode("ascii"))
        except _Lost:
            return
        # Let the answers arrive (at most a second) so that they do not meet a later run.
        deadline = time.monotonic() + 1.0
        oks = 0
        while oks < len(SAFE_STOP):
            ev = self._get_event(deadline)
            if ev is None or isinstance(ev, BaseException):
                return
            if ev is not _WAKE and ev.kind == P.OK:
                oks += 1

    def _collect_fatal(self, fatal: list[str]) -> None:
        """Gather the rest of a halt message (Marlin prints several lines)."""
        deadline = time.monotonic() + 0.3
        while True:
            ev = self._get_event(deadline)
            if ev is None or isinstance(ev, BaseException):
                return
            if ev is not _WAKE and ev.kind in (P.FATAL, P.ECHO) and ev.text and ev.text not in fatal:
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


class _Reporter:
    """Progress reports: at most 10 per second, but every change of state and of layer (the AR
    preview highlights the layer being printed from these reports)."""

    def __init__(self, link: SerialPrinter, progress: ProgressCallback | None, state: JobState | None):
        self.link, self.progress, self.state = link, progress, state
        self.t0 = time.monotonic()
        self.done_at_start = state.commands_done if state else 0
        self.last = (None, None, 0.0)  # kind, layer, time

    def __call__(self, kind: str, force: bool = False) -> None:
        state = self.state
        if self.progress is None or state is None:
            return
        now = time.monotonic()
        last_kind, last_layer, last_at = self.last
        if not force and kind == last_kind and state.layer == last_layer and now - last_at < 0.1:
            return
        self.last = (kind, state.layer, now)
        elapsed = now - self.t0
        total, done = state.commands_total, state.commands_done
        self.progress(Progress(
            state=kind,
            lines_done=done,
            lines_total=total,
            layer=state.layer,
            layer_count=state.layer_count,
            percent=100.0 * done / total if total else 100.0,
            elapsed_s=elapsed,
            eta_s=eta(done - self.done_at_start, total - self.done_at_start, elapsed),
            temperatures=dict(self.link.temperatures),
            message=state.message,
        ))


class _Lost(Exception):
    """Internal: a write failed, the link is gone."""
