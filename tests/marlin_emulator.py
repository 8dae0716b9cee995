"""A small Marlin emulator on a pseudo-terminal, with the faults printer-host users report.

`MarlinPty` answers like Marlin 2.x (docs/domain.md §4): numbered, checksummed
lines; `Resend: <last + 1>` + `ok` for a bad or out-of-sequence line; one `ok`
per line; M115 capabilities; M105 temperatures; optional auto-report
(`M155`), host keep-alive (`busy:` while a blocking command runs), heat waits
that print temperature lines. A host opens `emu.port` with real pyserial.

It is the reference for "executed exactly once": `executed` lists every
command the emulated firmware ran, in order (numbered lines without N and
checksum, and unnumbered lines). `max_outstanding` is the most lines the
host had sent that the firmware had not answered yet (never more than the
host's window in a healthy exchange). `hotend_target`, `bed_target` and
`motors_on` are the emulated printer's state at the end.

Faults are keyed by a command and its occurrence: `{"G1 X10": "lose_ok"}` (the
first time that command arrives) or `{("M105", 3): "drop"}` (the third):

- `lose_ok`: run the line, never answer it.
- `drop`: run the line, answer it; the link goes away (port closed) when the
  next line arrives, which does not run (so the host knows exactly what ran).
- `drop_before_ok`: run the line, then the link goes away without the answer.
- `silent_reset`: the board resets (heaters off, line counter 0) without its
  `start` banner before running the line; later lines get `Resend: 1`.
- `resend0`: the line arrives damaged and the resend request is garbled into `Resend: 0`.
- `resend99999`: the line arrives damaged and the firmware asks for line 99999.
- `double_resend`: the line arrives damaged; the error is answered by two
  complete `Resend`/`ok` pairs.
- `halt`: thermal runaway: `Error:` lines, heaters off, nothing runs afterwards.
- `block:<seconds>`: the command takes that long (silent unless keepalive=True).
"""

from __future__ import annotations

import os
import re
import select
import threading
import time
import tty

from pty_hangup import hang_up

_NUMBERED = re.compile(r"^N(-?\d+)\s*(.*?)\*(\d+)\s*$")
_S = re.compile(r"\bS\s*(-?\d*\.?\d+)")


def checksum(body: str) -> int:
    value = 0
    for b in body.encode("ascii"):
        value ^= b
    return value


class MarlinPty:
    """Marlin firmware behind a pty; see the module doc."""

    def __init__(self, *, faults: dict | None = None, autoreport: bool = False, keepalive: bool = False,
                 report_interval: float = 0.1, heat_s: float = 0.05, ambient: float = 25.0, move_s: float = 0.0):
        self.faults = dict(faults or {})
        self.autoreport = autoreport
        self.keepalive = keepalive
        self.report_interval = report_interval
        self.heat_s = heat_s
        self.move_s = move_s  # seconds each G0/G1 takes
        self._drop_next = False
        self.temp = {"T": ambient, "B": ambient}
        self.hotend_target = 0.0
        self.bed_target = 0.0
        self.motors_on = False
        self.executed: list[str] = []
        self.received: list[str] = []
        self.max_outstanding = 0
        self.resets = 0
        self.halted = False
        self.dropped = threading.Event()
        self._seen: dict[str, int] = {}
        self._last = 0
        self._received_numbered = 0
        self._answered = 0
        self._autoreport_on = False
        self._lines: list[str] = []
        self._handling = False
        self._cond = threading.Condition()
        self._closed = threading.Event()
        self._write_lock = threading.Lock()

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop_r, self._stop_w = os.pipe()
        self._threads = [threading.Thread(target=t, daemon=True) for t in (self._reader, self._worker, self._reporter)]
        for t in self._threads:
            t.start()

    # -- wire ------------------------------------------------------------------------------
    def _say(self, *lines: str) -> None:
        with self._write_lock:
            if self.dropped.is_set() or self._closed.is_set():
                return
            try:
                os.write(self._master, "".join(f"{line}\n" for line in lines).encode("ascii"))
            except OSError:
                pass

    def _drop(self) -> None:
        with self._write_lock:
            if not self.dropped.is_set():
                self.dropped.set()
                hang_up(self._master)  # the number itself is closed by close(), once the threads are done

    def _reader(self) -> None:
        pending = b""
        while not self._closed.is_set() and not self.dropped.is_set():
            try:
                ready, _, _ = select.select([self._master, self._stop_r], [], [], 0.5)
            except (OSError, ValueError):
                return  # the link was dropped (master closed)
            if self._stop_r in ready:
                return
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            pending += chunk
            while b"\n" in pending:
                raw, pending = pending.split(b"\n", 1)
                text = raw.decode("ascii", errors="replace").strip()
                if not text:
                    continue
                with self._cond:
                    self.received.append(text)
                    if text.startswith("N"):
                        self._received_numbered += 1
                        self.max_outstanding = max(self.max_outstanding, self._received_numbered - self._answered)
                    self._lines.append(text)
                    self._cond.notify_all()

    def _worker(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._lines or self._closed.is_set())
                if self._closed.is_set():
                    return
                text = self._lines.pop(0)
                self._handling = True
            if self.dropped.is_set():
                return
            try:
                self._handle(text)
            finally:
                with self._cond:
                    self._handling = False
                    self._cond.notify_all()

    def _reporter(self) -> None:
        while not self._closed.wait(self.report_interval):
            if self._autoreport_on and not self.halted:
                self._say(self._temps())

    # -- firmware --------------------------------------------------------------------------
    def _temps(self, wait_field: bool = False) -> str:
        line = (f"T:{self.temp['T']:.1f} /{self.hotend_target:.1f} B:{self.temp['B']:.1f} /{self.bed_target:.1f} "
                "@:0 B@:0")
        return line + (" W:?" if wait_field else "")

    def _fault(self, command: str) -> str | None:
        n = self._seen[command] = self._seen.get(command, 0) + 1
        return self.faults.pop((command, n), None) or (self.faults.pop(command, None) if n == 1 else None)

    def _answered_one(self, numbered: bool) -> None:
        if numbered:
            with self._cond:
                self._answered += 1

    def _handle(self, text: str) -> None:
        if self.halted:
            return  # killed: the firmware runs nothing and answers nothing
        if self._drop_next:
            self._drop()
            return
        m = _NUMBERED.match(text)
        numbered = text.startswith("N")
        if numbered and not m:
            self._answered_one(True)
            self._say(f"Error:No Checksum with line number, Last Line: {self._last}", f"Resend: {self._last + 1}", "ok")
            return
        if m:
            n, command, cs = int(m.group(1)), m.group(2).strip(), int(m.group(3))
            body = text[: text.rindex("*")]
            if checksum(body) != cs:
                self._answered_one(True)
                self._say(f"Error:checksum mismatch, Last Line: {self._last}", f"Resend: {self._last + 1}", "ok")
                return
            if command.startswith("M110"):
                self._last = n
                self._answered_one(True)
                self._say("ok")
                return
            if n != self._last + 1:
                self._answered_one(True)
                self._say(f"Error:Line Number is not Last Line Number+1, Last Line: {self._last}",
                          f"Resend: {self._last + 1}", "ok")
                return
        else:
            command = text
        fault = self._fault(command)
        if fault == "silent_reset":
            self.resets += 1
            self._last = 0
            self.hotend_target = self.bed_target = 0.0
            self.motors_on = False
            self._autoreport_on = False
            self._answered_one(numbered)
            return  # the line was lost in the reset; no banner
        if fault in ("resend0", "resend99999", "double_resend"):
            self._answered_one(numbered)
            r = {"resend0": 0, "resend99999": 99999}.get(fault, self._last + 1)
            pairs = 2 if fault == "double_resend" else 1
            self._say(f"Error:checksum mismatch, Last Line: {self._last}", *([f"Resend: {r}", "ok"] * pairs))
            return
        if m:
            self._last = n
        if fault == "halt":
            self.halted = True
            self.hotend_target = self.bed_target = 0.0
            self._answered_one(numbered)
            self._say("Error:Thermal Runaway, system stopped! Heater_ID: 0", "Error:Printer halted. kill() called!")
            return
        reply = self._run(command, fault)
        self._answered_one(numbered)
        if fault == "drop_before_ok":
            self._drop()
            return
        if fault != "lose_ok":
            self._say(*reply)
        if fault == "drop":
            self._drop_next = True

    def _run(self, command: str, fault: str | None) -> list[str]:
        """Run one command; the lines to answer with (ending in ok)."""
        self.executed.append(command)
        words = command.split()
        code = words[0].upper() if words else ""
        s = _S.search(command)
        value = float(s.group(1)) if s else None
        if fault and fault.startswith("block:"):
            self._block(float(fault.split(":", 1)[1]), "paused for user" if code in ("M0", "M1") else "processing")
        if code in ("M104", "M109") and value is not None:
            self.hotend_target = value
        elif code in ("M140", "M190") and value is not None:
            self.bed_target = value
        elif code in ("G0", "G1", "G2", "G3", "G28", "G29"):
            self.motors_on = True
            if self.move_s and code in ("G0", "G1"):
                time.sleep(self.move_s)
        elif code in ("M84", "M18"):
            self.motors_on = False
        elif code == "M155":
            self._autoreport_on = self.autoreport and (value or 0) > 0
        if code in ("M109", "M190"):
            self._heat_wait("T" if code == "M109" else "B", value or 0.0)
        if code == "M115":
            return ["FIRMWARE_NAME:Marlin emulator (arapp tests)",
                    f"Cap:AUTOREPORT_TEMP:{int(self.autoreport)}", "Cap:EMERGENCY_PARSER:0", "ok"]
        if code == "M105":
            return [f"ok {self._temps()}"]
        return ["ok"]

    def _block(self, seconds: float, what: str) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not self._closed.is_set():
            time.sleep(min(0.1, max(0.0, end - time.monotonic())))
            if self.keepalive:
                self._say(f"echo:busy: {what}")

    def _heat_wait(self, heater: str, target: float) -> None:
        """Marlin prints the temperatures (with its W: countdown) about every second of a heat wait;
        here every report_interval, the heater reaching the target after heat_s (0.05 s by default: one
        report, as the fault tests need a heat wait but not its length; 0.3 s cost them 9 s in all)."""
        start, t0 = self.temp[heater], time.monotonic()
        while not self._closed.is_set():
            frac = min(1.0, (time.monotonic() - t0) / self.heat_s) if self.heat_s > 0 else 1.0
            self.temp[heater] = start + (target - start) * frac
            if frac >= 1.0:
                return
            self._say(self._temps(wait_field=True))
            time.sleep(self.report_interval)

    # -- control ---------------------------------------------------------------------------
    def _idle(self) -> bool:
        """Nothing left to run: every byte the host wrote has been read and handled (or the link is gone)."""
        if self.dropped.is_set() or self._closed.is_set() or self.halted:
            return True
        if self._lines or self._handling:
            return False
        readable, _, _ = select.select([self._master], [], [], 0)
        return not readable

    def settle(self, timeout: float = 10.0) -> None:
        """Wait until the firmware has run everything the host has written so far.

        A host may stop waiting for the answers to its last lines (the safe stop waits at most a second)
        while a loaded machine has not run them yet; a test reading `executed` must wait for them."""
        with self._cond:
            self._cond.wait_for(self._idle, timeout)

    def heaters_off(self) -> bool:
        self.settle()
        return self.hotend_target == 0 and self.bed_target == 0

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        with self._cond:
            self._cond.notify_all()
        os.write(self._stop_w, b"x")
        for t in self._threads:
            t.join(timeout=2.0)
        with self._write_lock:
            self.dropped.set()
            os.close(self._master)
        for fd in (self._slave, self._stop_r, self._stop_w):
            os.close(fd)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
