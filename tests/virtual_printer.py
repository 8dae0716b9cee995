"""OctoPrint's VirtualPrinter on a pseudo-terminal, for tests and benchmarks.

`VirtualPrinterPty` runs the real `octoprint.plugins.virtual_printer.virtual.
VirtualPrinter` (with the plugin's own default settings) behind a Linux
pseudo-terminal: a host opens `vp.port` (the pty slave path) with real pyserial
exactly as it would open /dev/ttyUSB0. Two bridge threads move bytes between
the pty master and the printer's `write()` / `readline()`.

Outside OctoPrint the printer needs a settings object, a printer-profile
object and a stand-in for the plugin manager; those are the small classes
below. Nothing in the printer's protocol handling is replaced.

Instrumentation: the printer records every command that reaches its command
handling (after line-number, checksum and simulated-fault checks) in
`vp.executed`, in order, without line number or checksum. That is the
"executed exactly once, in order" reference for the host tests.

Faults: the plugin's defaults inject `100:resend`, `105:resend_with_timeout`,
`110:missing_lineno` and `115:checksum_mismatch`; `simulated_errors=` replaces
that list. `inject={line_number: "debug command"}` makes the bridge write
`!!DEBUG:<command>` to the printer right after the host's line with that
number has gone through (the printer's own debug-command interface: line
noise is `resend_ratio <percent>`, and `trigger_fatal_error_marlin`,
`drop_connection`, `mintemp_error`, `reset`, ...).

Printrun's line-number reset `N-1 M110 N-1` is handled as Marlin does (the
VirtualPrinter's parser would crash on the minus sign).

`corrupt_every=n` is line noise on the wire: the bridge changes one byte of
every n-th numbered host line, which the printer finds by its checksum.

`busy={line_number: seconds}` makes the printer busy after it has run the
host's line with that number (the first copy it accepts): its command thread
sleeps that long before the `ok`, so every line behind waits in its buffer,
as during M600, a long G29 or a slow move. Silent by default;
`busy_keepalive="busy: processing"` (or `"echo:busy: paused for user"`)
sends that line every `busy_interval` seconds meanwhile, as Marlin's
HOST_KEEPALIVE does. `corrupt_lines={n, ...}` damages the first copy of each of
those numbered lines on the wire (a resend of it is then certain).

`marlin_resend=True` makes the printer's checksum-error resend request ask
for the last accepted line + 1 as Marlin does (docs/domain.md §4: the
VirtualPrinter asks for `current_line + 1`, a counter that drifts once other
faults have happened). It changes nothing else.
"""

from __future__ import annotations

import os
import re
import select
import tempfile
import threading
import time
import tty
from pathlib import Path

from serial import SerialTimeoutException

from octoprint.plugins.virtual_printer import VirtualPrinterPlugin
from octoprint.plugins.virtual_printer import virtual as _virtual

from pty_hangup import hang_up

_LINE_NUMBER = re.compile(rb"^N(-?\d+)")
_NEGATIVE_M110 = re.compile(rb"^N-1 M110\b")


class _Settings:
    """The slice of OctoPrint's plugin-settings API the VirtualPrinter reads."""

    def __init__(self, values: dict, basefolder: str):
        self._values = values
        self._basefolder = basefolder

    def get(self, path, merged=False):
        node = self._values
        for key in path:
            if not isinstance(node, dict) or key not in node:
                return None
            node = node[key]
        return node

    def get_int(self, path):
        value = self.get(path)
        return None if value is None else int(value)

    def get_float(self, path):
        value = self.get(path)
        return None if value is None else float(value)

    def get_boolean(self, path):
        return bool(self.get(path))

    def global_get_basefolder(self, name):
        folder = Path(self._basefolder) / name
        folder.mkdir(parents=True, exist_ok=True)
        return str(folder)


class _ProfileManager:
    def get_current_or_default(self):
        return {"volume": {"width": 250, "depth": 210, "height": 210, "origin": "lowerleft"}}


class _PluginManager:
    def get_hooks(self, name):
        return {}


# The printer asks the plugin manager for action hooks in its constructor.
_virtual.plugin_manager = lambda: _PluginManager()


class RecordingVirtualPrinter(_virtual.VirtualPrinter):
    """The VirtualPrinter, logging each command that reaches command handling."""

    def __init__(self, *args, marlin_resend: bool = False, busy: dict | None = None,
                 busy_keepalive: str | None = None, busy_interval: float = 0.05, **kwargs):
        # Set before the parent constructor: it starts the printer's threads.
        self.executed: list[str] = []
        self.busy_periods: list[tuple[int, float]] = []  # (line number, seconds) as they happened
        self._busy_after = dict(busy or {})
        self._busy_keepalive = busy_keepalive
        self._busy_interval = busy_interval
        self.busy_started = threading.Event()
        self._ran_cond = threading.Condition()
        self.swallowed: list[int] = []  # line numbers taken but not run (noise)
        self._marlin_resend = marlin_resend
        self._current_line = 0
        super().__init__(*args, **kwargs)

    def write(self, data):
        # Marlin takes `N-1 M110 N-1` (Printrun's line-number reset: the next
        # line is N0); the VirtualPrinter's line-number regex has no minus sign
        # and its command thread dies on it. Do what Marlin does. Hosts send it
        # while nothing else is in flight.
        if _NEGATIVE_M110.match(bytes(data)):
            with self._incoming_lock:
                self.lastN = -1
                self._current_line = -1
                self._sendOk()
            return len(data)
        return super().write(data)

    # `current_line` drives the checksum-error resend request (see module doc).
    @property
    def current_line(self):
        return self.lastN if self._marlin_resend else self._current_line

    @current_line.setter
    def current_line(self, value):
        self._current_line = value

    def _triggerResend(self, expected=None, actual=None, checksum=None):
        # The printer's line-noise simulation (`resend_ratio`) answers a line it
        # has already taken as its last (lastN) with a checksum error and asks
        # for the next one: that line never runs. Record which it was.
        if (
            checksum
            and expected is None
            and actual is None
            and self._resend_every_n
            and self._received_lines % self._resend_every_n == 0
        ):
            self.swallowed.append(self.lastN)
        return super()._triggerResend(expected=expected, actual=actual, checksum=checksum)

    def wait_until_ran(self, predicate, timeout: float) -> bool:
        """Wait (at most `timeout` s) until predicate(executed) holds; whether it does."""
        with self._ran_cond:
            return self._ran_cond.wait_for(lambda: predicate(self.executed), timeout)

    def _ran(self, data):
        with self._ran_cond:
            self.executed.append(data)
            self._ran_cond.notify_all()
        seconds = self._busy_after.pop(self.lastN, None)
        if seconds is not None:
            # The command thread sleeps: nothing behind this line is read, run or answered meanwhile.
            self.busy_periods.append((self.lastN, seconds))
            self.busy_started.set()
            end = time.monotonic() + seconds
            while (left := end - time.monotonic()) > 0 and not self._killed:
                if self._busy_keepalive:
                    self._send(self._busy_keepalive)
                    time.sleep(min(left, self._busy_interval))
                else:
                    time.sleep(left)

    # The printer has no _gcode_G/_gcode_M letter handlers; returning False
    # lets the normal command handler run.
    def _gcode_G(self, code, data):
        self._ran(data)
        return False

    def _gcode_M(self, code, data):
        self._ran(data)
        return False

    def _gcode_T(self, code, data):
        self._ran(data)
        return super()._gcode_T(code, data)

    def _gcode_F(self, code, data):
        self._ran(data)
        return super()._gcode_F(code, data)


def default_settings() -> dict:
    """The VirtualPrinter plugin's own default settings."""
    return VirtualPrinterPlugin().get_settings_defaults()


class VirtualPrinterPty:
    """A VirtualPrinter behind a pty; `port` is the slave path for pyserial.

    Use as a context manager, or call `close()`.
    """

    def __init__(
        self,
        *,
        simulated_errors: list[str] | None = None,
        inject: dict[int, str] | None = None,
        settings: dict | None = None,
        marlin_resend: bool = False,
        corrupt_every: int = 0,
        corrupt_lines=(),
        busy: dict | None = None,
        busy_keepalive: str | None = None,
        busy_interval: float = 0.05,
        read_timeout: float = 0.5,
    ):
        values = default_settings()
        if simulated_errors is not None:
            values["simulated_errors"] = list(simulated_errors)
        values.update(settings or {})
        self._tmp = tempfile.TemporaryDirectory(prefix="arapp-vp-")
        self.printer = RecordingVirtualPrinter(
            _Settings(values, self._tmp.name),
            _ProfileManager(),
            data_folder=self._tmp.name,
            read_timeout=read_timeout,
            marlin_resend=marlin_resend,
            busy=busy,
            busy_keepalive=busy_keepalive,
            busy_interval=busy_interval,
        )
        self._inject = dict(inject or {})
        self._corrupt_every = corrupt_every
        self._corrupt_lines = set(corrupt_lines)
        self._line_count = 0
        self.corrupted = 0
        self.received_lines: list[bytes] = []  # host lines, as they went through
        self.dropped = threading.Event()
        self._closed = threading.Event()

        self._master, self._slave = os.openpty()
        # Raw mode before anything is written: no echo, no line editing.
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._stop_r, self._stop_w = os.pipe()
        self._master_lock = threading.Lock()
        self._master_open = True

        self._threads = [
            threading.Thread(target=self._host_to_printer, name="vp-bridge-in", daemon=True),
            threading.Thread(target=self._printer_to_host, name="vp-bridge-out", daemon=True),
        ]
        for t in self._threads:
            t.start()

    @property
    def executed(self) -> list[str]:
        return self.printer.executed

    def sent_command(self, number: int) -> str:
        """The command the host sent as line `number` (without N and checksum)."""
        for line in self.received_lines:
            m = _LINE_NUMBER.match(line)
            if m and int(m.group(1)) == number:
                body = line[m.end():].rsplit(b"*", 1)[0]
                return body.decode("ascii").strip()
        raise KeyError(number)

    # -- bridge ---------------------------------------------------------------
    def _write_to_printer(self, data: bytes) -> bool:
        """Feed bytes to the printer, which may take only part of them."""
        while data:
            if self._closed.is_set():
                return False
            try:
                n = self.printer.write(data)
            except SerialTimeoutException:
                if self.printer._debug_drop_connection:
                    return False
                continue  # receive buffer stayed full for write_timeout: try again
            if n == 0 and self.printer.incoming is None:
                return False
            data = data[n:]
        return True

    def _host_to_printer(self):
        pending = b""
        while not self._closed.is_set():
            ready, _, _ = select.select([self._master, self._stop_r], [], [])
            if self._stop_r in ready:
                return
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            if not chunk:
                return
            pending += chunk
            # One line per write: the printer only handles the first line of
            # each chunk it receives until more data arrives.
            while b"\n" in pending:
                line, pending = pending.split(b"\n", 1)
                line += b"\n"
                self.received_lines.append(line)
                line = self._maybe_corrupt(line)
                if not self._write_to_printer(line):
                    self._drop()
                    return
                m = _LINE_NUMBER.match(line)
                if m and int(m.group(1)) in self._inject:
                    command = self._inject.pop(int(m.group(1)))
                    if not self._write_to_printer(f"!!DEBUG:{command}\n".encode()):
                        self._drop()
                        return

    def _maybe_corrupt(self, line: bytes) -> bytes:
        """Line noise on the wire: change one byte of every n-th numbered line.

        The byte is in the command, never in `N<n> ` or the checksum, so the
        printer sees a checksum mismatch (its parser would crash on a damaged
        checksum field).
        """
        m = _LINE_NUMBER.match(line)
        if not m or b"M110" in line:
            return line
        star = line.rfind(b"*")
        start = m.end() + 1
        if star - start < 1:
            return line
        if int(m.group(1)) in self._corrupt_lines:
            self._corrupt_lines.discard(int(m.group(1)))
            pos = start
        else:
            if not self._corrupt_every:
                return line
            self._line_count += 1
            if self._line_count % self._corrupt_every:
                return line
            pos = start + (self._line_count // self._corrupt_every) % (star - start)
        flipped = line[pos] ^ 0x01
        if flipped in b"*\n\r":
            flipped = line[pos] ^ 0x02
        self.corrupted += 1
        return line[:pos] + bytes([flipped]) + line[pos + 1:]

    def _printer_to_host(self):
        while not self._closed.is_set():
            try:
                line = self.printer.readline()
            except SerialTimeoutException:
                self._drop()
                return
            if not line:
                if self.printer.outgoing is None:
                    return
                continue  # read timeout of the printer: nothing to say
            if not line.endswith(b"\n"):
                line += b"\n"
            with self._master_lock:
                if not self._master_open:
                    return
                try:
                    os.write(self._master, line)
                except OSError:
                    return

    def _drop(self):
        """The link goes away: the master hung up, the host sees it (the number is closed by close())."""
        self.dropped.set()
        with self._master_lock:
            if self._master_open:
                self._master_open = False
                hang_up(self._master)

    def close(self):
        if self._closed.is_set():
            return
        self._closed.set()
        os.write(self._stop_w, b"x")
        for t in self._threads:
            t.join(timeout=2.0)
        with self._master_lock:
            self._master_open = False
            os.close(self._master)
        # Stop the printer's command loop, let its move buffer drain, then close
        # (closing while a move is running makes its buffer thread fail).
        self.printer._killed = True
        buffered = self.printer.buffered
        if buffered is not None:
            with buffered.all_tasks_done:
                buffered.all_tasks_done.wait_for(lambda: buffered.unfinished_tasks == 0, timeout=2.0)
        self.printer.close()
        for fd in (self._slave, self._stop_r, self._stop_w):
            os.close(fd)
        self._tmp.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
