"""The print dialog's view of the printer links in arapp.printing.link: one job API for serial and OctoPrint.

A job runs in its own thread and reports `PrintEvent`s through a callback
(called in that thread; the dialog forwards them to the UI thread).
"""

from __future__ import annotations

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
            self._run_link()
        except Exception as exc:  # noqa: BLE001 - the printer's message goes to the dialog
            self.callback(PrintEvent(text="Print stopped", finished=True, error=str(exc) or type(exc).__name__))
            return
        self.callback(PrintEvent(fraction=None if self._cancel.is_set() else 1.0,
                                 text="Cancelled" if self._cancel.is_set() else "Done", finished=True))

    def _on_progress(self, pr) -> None:
        """A link's Progress -> PrintEvent (temperatures T/B renamed hotend/bed)."""
        temps = {}
        for key, name in (("T", "hotend"), ("B", "bed")):
            if key in pr.temperatures:
                actual, target = pr.temperatures[key]
                temps[name] = (actual, target if target is not None else actual)
        fraction = max(0.0, min(1.0, pr.percent / 100.0))
        layer = pr.layer + 1 if pr.layer >= 0 else None
        parts = [f"{pr.percent:.1f} %"]
        if layer is not None:
            parts.append(f"layer {layer}" + (f"/{pr.layer_count}" if pr.layer_count else ""))
        parts.append(f"line {pr.lines_done}/{pr.lines_total}")
        if pr.eta_s is not None:
            parts.append(f"ETA {pr.eta_s / 60:.0f} min" if pr.eta_s >= 60 else f"ETA {pr.eta_s:.0f} s")
        if pr.message:
            parts.append(pr.message)
        self.callback(PrintEvent(fraction=fraction, layer=layer, text="  ".join(parts), temperatures=temps))

    def _make_link(self):
        from arapp.printing.link import OctoPrintLink, SerialPrinter

        bed = getattr(getattr(self.profile, "bed", None), "height", None)
        if isinstance(self.target, OctoPrintTarget):
            from arapp.printing.link.octoprint import load_api_key

            return OctoPrintLink(self.target.url, load_api_key(self.target.api_key_file))
        return SerialPrinter(self.target.port, self.target.baud, bed_height=bed)

    def _run_link(self) -> None:
        link = self._make_link()
        self._host = link
        where = self.target.url if isinstance(self.target, OctoPrintTarget) else self.target.port
        self.callback(PrintEvent(text=f"Connecting to {where}..."))
        with link:
            if self._cancel.is_set():
                return
            link.print_gcode(self.gcode.splitlines(), progress=self._on_progress, cancel=self._cancel)
