"""The project's Marlin emulator (OctoPrint's VirtualPrinter on a pty, tests/virtual_printer.py) answering
as Prusa's MK3S firmware (Prusa-Firmware 3.14) does where PrusaLink asks what plain Marlin does not know.

PrusaLink (the Raspberry-Pi PrusaLink, `prusalink` on the package index) identifies the printer before it
takes a job: `PRUSA Fir` (firmware version, `3.14.1-8237`: PrusaLink 0.8 refuses older than 3.14.0), `M862.2 Q` (printer type code, `302` for the
MK3S), `M862.1 Q` (nozzle diameter), `PRUSA SN`; it then polls `M27 P`, `M73`, `M220`, `M221`, `M420`,
EEPROM reads `D3 Ax<addr> C<count>`, the MMU registers `M707 A0x..`, and reads temperatures in the
firmware's own format (`T:... /... B:... /... T0:... /... @:0 B@:0 P:... A:...`). The answers below are the
ones PrusaLink's own regular expressions (prusa/link/printer_adapter/structures/regular_expressions.py)
accept, in the forms Prusa-Firmware prints them.

These queries are answered here, in the bridge, and never reach the VirtualPrinter: its `executed` list
stays the job's commands plus what PrusaLink sends as ordinary G-code (M155, M110, M117...). Each answered
numbered line advances the printer's line counter as if it had run it, so the numbering stays whole.
`prusa_queries` lists what was answered (the host's command, without number and checksum).
"""

from __future__ import annotations

import re
import time

from virtual_printer import VirtualPrinterPty, _LINE_NUMBER

FIRMWARE = "3.14.1-8237"  # PrusaLink 0.8 wants 3.14.0 or newer
PRINTER_TYPE = "302"  # MK3S (PrusaLink's PRINTER_TYPES)
SERIAL_NUMBER = "CZPX4720X004XK12345"
NOZZLE = "0.40"

# the last M73 values (module-wide: one emulated printer per test session)
_PROGRESS = dict.fromkeys("PRCQSD", -1)
_D3 = re.compile(r"^D3 Ax([0-9a-fA-F]+) C(\d+)")
_M110 = re.compile(r"^M110 N(-?\d+)$")
_TEMPS = re.compile(r"^(ok )?\s*T:")


def _body(line: bytes) -> tuple[int | None, str]:
    """(line number or None, command without number and checksum) of a host line."""
    text = line.decode("ascii", errors="replace").strip()
    m = _LINE_NUMBER.match(line)
    number = None
    if m:
        number = int(m.group(1))
        text = text[m.end():]
        text = text.rsplit("*", 1)[0] if "*" in text else text
    return number, text.strip()


def prusa_answer(command: str) -> list[str] | None:
    """What Prusa-Firmware prints (before its `ok`) for a Prusa-only query, or None for other commands."""
    if command.startswith("PRUSA Fir"):
        return [FIRMWARE]
    if command.startswith("PRUSA SN"):
        return [SERIAL_NUMBER]
    if command.startswith("M862.2 Q"):
        return [PRINTER_TYPE]
    if command.startswith("M862.1 Q"):
        return [NOZZLE]
    if command.startswith("M862"):
        return []  # the other print checks pass silently
    if command.startswith("M21") and not command[3:4].isdigit():
        return ["echo:SD init fail"]  # no SD card in the printer: PrusaLink's own storage holds the jobs
    if command.startswith("M601"):
        return ["// action:paused"]
    if command.startswith("M602"):
        return ["// action:resumed"]
    if command.startswith("M603"):
        return ["// action:cancel"]  # PrusaFirmwarePty also turns the heaters off, as the firmware does
    if command in ("M220", "M221"):
        return ["100%"]
    if command == "M73" or command.startswith("M73 "):
        # M73 P<%> R<min> C<min> (normal mode), Q S D (silent): stored, and reported as the firmware does,
        # both modes, also when only asked
        if command != "M73":
            for letter, value in re.findall(r"([PRCQSD])(-?\d+)", command):
                _PROGRESS[letter] = int(value)
        return [f"{mode} MODE: Percent done: {_PROGRESS[p]}; print time remaining in mins: {_PROGRESS[r]}; "
                f"Change in mins: {_PROGRESS[c]}" for mode, p, r, c in (("NORMAL", "P", "R", "C"),
                                                                        ("SILENT", "Q", "S", "D"))]
    if command == "M420":
        return ["Mesh bed leveling not active."]
    if command.startswith("M707"):
        return []  # no MMU: the register reads stay unanswered
    m = _D3.match(command)
    if m:
        # EEPROM dump: `ADDR  b0 b1 ...`, 16 bytes a row; all zero (no sheets, job 0, normal mode)
        address, count = int(m.group(1), 16), int(m.group(2))
        rows = []
        for start in range(0, count, 16):
            n = min(16, count - start)
            rows.append(f"{address + start:06x}  " + " ".join(["00"] * n))
        return rows
    return None


class PrusaFirmwarePty(VirtualPrinterPty):
    """A VirtualPrinterPty whose firmware answers PrusaLink's Prusa-only queries (see module doc)."""

    def __init__(self, *, m400_delay: float = 0.2, m400_max: float = 5.0, **kwargs):
        self.prusa_queries: list[str] = []
        self.m400_delay = m400_delay
        self.m400_max = m400_max
        # set by the PrusaLink fixture: whether PrusaLink has recorded the starting job's path (see _hold_m400)
        self.job_recorded = None
        self.answered: list[bytes] = []  # the lines the firmware wrote to the host, as they went
        kwargs.setdefault("simulated_errors", [])  # PrusaLink's own serial tests are not the subject here
        super().__init__(**kwargs)

    def _write_to_printer(self, data: bytes) -> bool:
        number, command = _body(data)
        if command == "M400":
            self._hold_m400()
        answer = prusa_answer(command)
        printer = self.printer
        m110 = _M110.match(command)
        if m110 and number is None:
            # Marlin (Prusa's too) takes an unnumbered `M110 N<n>` as "the next line is n + 1"; the
            # VirtualPrinter reads the N of the line itself only. PrusaLink starts each job's numbering so.
            number, answer = int(m110.group(1)), []
        if answer is None:
            return super()._write_to_printer(data)
        if command.startswith("M603"):
            # Prusa-Firmware's stop (lcd_print_stop): heaters off, then it tells the host the print is cancelled
            printer.targetTemp[0] = 0.0
            printer.bedTargetTemp = 0.0
            answer = ["// action:cancel"]
        with printer._incoming_lock:
            if number is not None:
                printer.lastN = number
                printer._current_line = number
            self.prusa_queries.append(command)
            for line in answer:
                printer._send(line)
            printer._send("ok")
        return True

    def _hold_m400(self) -> None:
        """M400 waits for the moves in the planner to end: on a printer that takes a while. PrusaLink 0.8.1
        needs that while: it starts its file printer thread before it records the job's path, and the
        thread's first numbered line (M110 N0) writes the power-panic record, which fails on the missing path
        and breaks PrusaLink for good ("connect_path none is not an allowed value"); the upload chime's M400
        is the line in flight just then. A fixed 0.2 s was not always enough on a loaded machine (PrusaLink's
        command thread not run in time: every later upload then hung), so the answer also waits, up to
        `m400_max` seconds, until PrusaLink shows the job's path."""
        time.sleep(self.m400_delay)
        deadline = time.monotonic() + self.m400_max
        # polled: the path is PrusaLink's state, in another process, with nothing to wait on
        while self.job_recorded is not None and not self._closed.is_set() and time.monotonic() < deadline:
            if self.job_recorded():
                return
            time.sleep(0.05)

    def _prusa_temperatures(self) -> str:
        p = self.printer
        t, tt = p.temp[0], p.targetTemp[0]
        b, bt = p.bedTemp, p.bedTargetTemp
        return (f"T:{t:.1f} /{tt:.1f} B:{b:.1f} /{bt:.1f} T0:{t:.1f} /{tt:.1f} @:0 B@:0 "
                f"P:{b:.1f} A:{b:.1f}")

    def _printer_to_host(self):
        # as VirtualPrinterPty's, with the temperature report in Prusa's format
        from serial import SerialTimeoutException
        import os

        while not self._closed.is_set():
            try:
                line = self.printer.readline()
            except SerialTimeoutException:
                self._drop()
                return
            if not line:
                if self.printer.outgoing is None:
                    return
                continue
            text = line.decode("ascii", errors="replace")
            m = _TEMPS.match(text)
            if m:
                line = (self._prusa_temperatures() + "\n").encode()
                if m.group(1):
                    line += b"ok\n"
            elif not line.endswith(b"\n"):
                line += b"\n"
            self.answered.append(line)
            with self._master_lock:
                if not self._master_open:
                    return
                try:
                    os.write(self._master, line)
                except OSError:
                    return
