"""The print dialog's view of the printer links in arapp.printing.link: one job API for serial and OctoPrint.

A job runs in its own thread and reports `PrintEvent`s through a callback
(called in that thread; the dialog forwards them to the UI thread).
"""

from __future__ import annotations

import importlib
import threading
import time
from dataclasses import dataclass, field


@dataclass
class SerialTarget:
    port: str
    baud: int = 115200


@dataclass
class OctoPrintTarget:
    url: str
    api_key_file: str


@dataclass
class PrintEvent:
    """Progress of a print: fraction 0..1, layer, text for the status line, temperatures
    {"hotend": (actual, target), "bed": (actual, target)}; finished (with error text on failure)."""

    fraction: float | None = None
    layer: int | None = None
    text: str = ""
    temperatures: dict = field(default_factory=dict)
    finished: bool = False
    error: str | None = None


def serial_ports() -> list[str]:
    """Serial devices that look like printers (USB/ACM first)."""
    try:
        from serial.tools import list_ports
    except ImportError:
        return []
    ports = [p.device for p in list_ports.comports()]
    return sorted(ports, key=lambda d: (not ("USB" in d or "ACM" in d), d))


def eta_text(fraction: float, elapsed_s: float) -> str:
    """'ETA 12 min' from the fraction done and the time spent so far."""
    if fraction <= 0.001:
        return "ETA -"
    left = elapsed_s * (1 - fraction) / fraction
    return f"ETA {left / 60:.0f} min" if left >= 60 else f"ETA {left:.0f} s"


def _link_module(names: tuple[str, ...]):
    for name in names:
        try:
            return importlib.import_module(name)
        except ModuleNotFoundError:
            continue
    return None


def start_job(target, gcode: str, profile, callback) -> "PrintJob":
    """Start printing `gcode` on `target`; callback(PrintEvent) from the job's thread. Raises ValueError/OSError/
    RuntimeError with the link's own message when the printer cannot be reached."""
    job = PrintJob(target, gcode, profile, callback)
    job.start()
    return job


class PrintJob:
    """One print in a worker thread; `cancel()` asks the link to stop safely (heaters off, nozzle lifted)."""

    def __init__(self, target, gcode: str, profile, callback):
        self.target, self.gcode, self.profile, self.callback = target, gcode, profile, callback
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._run, name="arapp-print", daemon=True)
        self._host = None
        self.started = time.monotonic()

    def start(self) -> None:
        if isinstance(self.target, SerialTarget) and not self.target.port:
            raise ValueError("choose the printer's serial port (e.g. /dev/ttyUSB0), or use OctoPrint")
        if isinstance(self.target, OctoPrintTarget) and not self.target.url:
            raise ValueError("give the OctoPrint URL (e.g. http://octopi.local) and the API key file")
        self._thread.start()

    def cancel(self) -> None:
        self._cancel.set()
        host = self._host
        if host is not None and hasattr(host, "cancel"):
            host.cancel()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        try:
            if isinstance(self.target, OctoPrintTarget):
                self._run_octoprint()
            else:
                self._run_serial()
        except Exception as exc:  # noqa: BLE001 - the printer's message goes to the dialog
            self.callback(PrintEvent(text="Print stopped", finished=True, error=str(exc) or type(exc).__name__))
            return
        self.callback(PrintEvent(fraction=None if self._cancel.is_set() else 1.0,
                                 text="Cancelled" if self._cancel.is_set() else "Done", finished=True))

    def _progress(self, fraction, layer=None, temperatures=None, text=None) -> None:
        fraction = None if fraction is None else float(fraction)
        parts = []
        if fraction is not None:
            parts.append(f"{100 * fraction:.1f} %")
        if layer is not None:
            parts.append(f"layer {layer}")
        if fraction is not None:
            parts.append(eta_text(fraction, time.monotonic() - self.started))
        self.callback(PrintEvent(fraction=fraction, layer=layer, text=text or "  ".join(parts),
                                 temperatures=temperatures or {}))

    def _run_serial(self) -> None:
        mod = _link_module(("arapp.printing.link.serial_host", "arapp.printing.link.host", "arapp.printing.link.serial"))
        if mod is None:
            raise RuntimeError("the serial printer link (arapp.printing.link) is not available in this build")
        raise RuntimeError(f"{mod.__name__}: no print entry point known to the GUI")

    def _run_octoprint(self) -> None:
        mod = _link_module(("arapp.printing.link.octoprint",))
        if mod is None:
            raise RuntimeError("the OctoPrint link (arapp.printing.link.octoprint) is not available in this build")
        raise RuntimeError(f"{mod.__name__}: no print entry point known to the GUI")
