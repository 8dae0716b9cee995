"""The app's use of the printer links (arapp.printing.link): one job API for serial and OctoPrint.

A `PrintJob` runs `connect()` and `print_gcode()` of the link `make_link(target)`
makes (arapp.printing.link: serial or OctoPrint) in its own thread and reports `PrintEvent`s through a callback
called in that thread (the dialog forwards them to the UI thread). Pause,
resume and cancel never block the caller: OctoPrint's are HTTP requests, so
they run in a short-lived thread of their own.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from serial.tools import list_ports

from arapp.printing.link import LinkLost, MoonrakerTarget, OctoPrintTarget, PrinterHalted, SerialTarget, make_link
from arapp.printing.gcode import format_duration

__all__ = ["SerialTarget", "OctoPrintTarget", "MoonrakerTarget", "PrintEvent", "PrintJob", "start_job", "serial_ports"]


@dataclass
class PrintEvent:
    """One report of a print job.

    progress: the link's `arapp.printing.link.Progress` (None for connection
    notes and the final event of a job that failed before printing); text: a
    line for the dialog; finished: the job is over (done, cancelled or
    failed); error_title/error: why it failed (for a halt, the printer's own
    message); job_path: the saved job state to resume from, when there is one;
    job_state: the link's JobState when the job stopped on a failure (what ran).
    """

    progress: object | None = None
    text: str = ""
    finished: bool = False
    error_title: str = ""
    error: str | None = None
    job_path: str | None = None
    job_state: object | None = None


def serial_ports() -> list[str]:
    """Serial devices that look like printers (USB/ACM first)."""
    ports = [p.device for p in list_ports.comports()]
    return sorted(ports, key=lambda d: (not ("USB" in d or "ACM" in d), d))


def format_duration_s(seconds: float | None) -> str:
    """arapp.printing.gcode.format_duration ('1 h 05 min', '48 min 0 s', '40 s'); '?' when unknown."""
    return "?" if seconds is None else format_duration(seconds)


def layer_text(progress) -> str:
    """'layer 3 / 27' (1-based for people), or '' before the first layer."""
    if progress is None or progress.layer < 0:
        return ""
    total = f" / {progress.layer_count}" if progress.layer_count else ""
    return f"layer {progress.layer + 1}{total}"


def progress_text(progress) -> str:
    """The status line of a Progress: state, lines sent, elapsed time, the printer's message."""
    # the percent, layer and time left have their own places in the dialog: shown once, there
    parts = [progress.state, f"line {progress.lines_done} / {progress.lines_total}",
             f"elapsed {format_duration_s(progress.elapsed_s)}"]
    if progress.message:
        parts.append(progress.message)
    return "   ".join(parts)


def temperatures(progress) -> dict:
    """{"hotend": (actual, target), "bed": (actual, target)} in degrees C from a Progress ("T"/"B"); a target
    the printer did not report is None."""
    out = {}
    for key, name in (("T", "hotend"), ("B", "bed")):
        if key in (progress.temperatures or {}):
            actual, target = progress.temperatures[key]
            out[name] = (None if actual is None else float(actual), None if target is None else float(target))
    return out


def start_job(target, gcode: str, profile, callback, *, job_path=None, gcode_path: str = "",
              resume=None) -> "PrintJob":
    """Start printing `gcode` on `target`; callback(PrintEvent) from the job's thread. Raises ValueError/OSError
    at once for a target that cannot work (no port, no URL, unreadable key file). `resume`: an
    arapp.app.saved_job.SavedJob to continue (serial links only, as `arapp print --resume`)."""
    if resume is not None and not isinstance(target, SerialTarget):
        raise ValueError("a stopped print can be resumed over USB serial only (OctoPrint keeps its own job)")
    job = PrintJob(make_link(target, profile=profile, job_path=job_path), gcode, callback, job_path=job_path,
                   gcode_path=gcode_path, resume=resume)
    job.start()
    return job


class PrintJob:
    """One print on a link, in a worker thread.

    `pause()`, `resume()` and `cancel()` may be called from any thread and
    return at once; `cancel()` makes the link stop safely (heaters off, nozzle
    lifted; OctoPrint runs its own cancel script).
    """

    def __init__(self, link, gcode: str, callback, *, job_path=None, gcode_path: str = "", resume=None):
        self.link, self.gcode, self.callback = link, gcode, callback
        self.resume_from = resume  # a SavedJob: its state, program and preamble go to the link
        self.job_path = None if job_path is None else str(job_path)
        self.gcode_path = str(gcode_path)
        self._cancel = threading.Event()
        self._connected = threading.Event()
        self._thread = threading.Thread(target=self._run, name="arapp-print", daemon=True)
        self.paused = False
        self.started = time.monotonic()
        self.state = None  # the link's final JobState

    def start(self) -> None:
        self._thread.start()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float | None = None) -> None:
        self._thread.join(timeout)

    # -- controls (any thread, never blocking) ----------------------------------------------
    def _control(self, name: str) -> None:
        def call():
            try:
                getattr(self.link, name)()
            except Exception as exc:  # noqa: BLE001 - e.g. OctoPrint unreachable: the dialog shows it
                self.callback(PrintEvent(text=f"{name} failed", error_title=f"Cannot {name} the print",
                                         error=str(exc) or type(exc).__name__))

        threading.Thread(target=call, name=f"arapp-print-{name}", daemon=True).start()

    def pause(self) -> None:
        """Stop sending after the lines in flight (heaters stay on)."""
        if self._connected.is_set() and not self._cancel.is_set():
            self.paused = True
            self._control("pause")

    def resume(self) -> None:
        if self._connected.is_set() and not self._cancel.is_set():
            self.paused = False
            self._control("resume")

    def cancel(self) -> None:
        # every link's print_gcode watches the event (at least 4 times a second, arapp.printing.link.base)
        # and stops safely itself; OctoPrint's cancel request is made there, off this thread
        self._cancel.set()

    # -- the job thread ---------------------------------------------------------------------
    def _run(self) -> None:
        where = getattr(self.link, "url", None) or getattr(self.link, "port", "the printer")
        self.callback(PrintEvent(text=f"Connecting to {where}..."))
        try:
            self.link.connect()
            self._connected.set()
            if self._cancel.is_set():
                self.callback(PrintEvent(text="Cancelled before printing", finished=True))
                return
            self.callback(PrintEvent(text=f"Connected to {where}; printing"))
            extra = {}
            if self.resume_from is not None:
                r = self.resume_from
                extra = {"program": r.program, "state": r.state, "preamble": r.preamble()}
                self.callback(PrintEvent(text=f"Connected to {where}; resuming at line {r.state.next_line + 1:,}: "
                                              "heating, homing X and Y"))
            self.state = self.link.print_gcode(self.gcode.splitlines(), progress=self._progress,
                                               cancel=self._cancel, gcode_path=self.gcode_path, **extra)
        except PrinterHalted as exc:
            self._failed("The printer halted", exc)
            return
        except LinkLost as exc:
            self._failed("Printer connection lost", exc)
            return
        except Exception as exc:  # noqa: BLE001 - any link failure goes to the dialog with its message
            self._failed("Printer error", exc)
            return
        finally:
            try:
                self.link.close()
            except Exception:  # noqa: BLE001 - closing a dead port can fail; nothing left to do
                pass
        status = getattr(self.state, "status", "done")
        self.callback(PrintEvent(text="Print cancelled" if status == "cancelled" else "Print finished",
                                 finished=True, job_path=self.job_path))

    def _failed(self, title: str, exc: BaseException) -> None:
        job_path = getattr(exc, "job_path", None)
        self.callback(PrintEvent(text=f"{title}", finished=True, error_title=title,
                                 error=str(exc) or type(exc).__name__,
                                 job_path=None if job_path is None else str(job_path),
                                 job_state=getattr(exc, "job", None)))

    def _progress(self, progress) -> None:
        self.callback(PrintEvent(progress=progress, text=progress_text(progress)))
