"""What every printer link (USB serial, OctoPrint) offers, and the progress it reports.

The GUI and `arapp print` drive either link the same way: `make_link(target)`
(factory.py), `connect()`, then
`print_gcode(lines, progress=callback, cancel=event, gcode_path=path)` (blocking; run it on a
worker thread in the GUI), `pause()`, `resume()`, `cancel()` from any thread,
and `close()`. The callback receives `Progress`; the AR preview highlights
`Progress.layer`.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .job import JobState

# Progress.state values
CONNECTING = "connecting"
HEATING = "heating"
PRINTING = "printing"
PAUSED = "paused"
CANCELLING = "cancelling"
DONE = "done"
CANCELLED = "cancelled"


@dataclass
class Progress:
    """A snapshot of a running job.

    `lines_done`/`lines_total` count G-code commands (comments excluded) the
    printer has executed; `layer` is 0-based (-1 before the first layer) and
    `layer_count` is 0 when the G-code has no layer comments. Times in seconds,
    temperatures in degrees C as {"T": (actual, target), "B": (...)}; target is
    None where the printer did not report one.
    """

    state: str
    lines_done: int = 0
    lines_total: int = 0
    layer: int = -1
    layer_count: int = 0
    percent: float = 0.0
    elapsed_s: float = 0.0
    eta_s: float | None = None
    temperatures: dict = field(default_factory=dict)
    message: str = ""


ProgressCallback = Callable[[Progress], None]


class LinkError(RuntimeError):
    """A printer link failed. `job` is the job state when it happened (or None),
    `job_path` where it was saved (or None)."""

    def __init__(self, message: str, job: JobState | None = None, job_path=None):
        if job_path:
            message = f"{message} (job state saved to {job_path}; resume with --resume {job_path})"
        super().__init__(message)
        self.job = job
        self.job_path = job_path


class PrinterHalted(LinkError):
    """The firmware halted (`Error:`/`!!`); the message is the printer's own."""


class LinkLost(LinkError):
    """The connection went away or the printer stopped answering mid-job."""


class PrinterReset(LinkLost):
    """The firmware restarted (`start`) mid-job: its position and heaters were lost."""


class PrintLink(ABC):
    """A connection to a printer that can run a G-code job."""

    @abstractmethod
    def connect(self) -> None:
        """Open the connection; raise OSError/LinkError with a specific message on failure."""

    @abstractmethod
    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        gcode_path: str = "",
    ) -> JobState:
        """Run the G-code to the end (or until `cancel` is set); return the final job state.

        `gcode_path` is the file the lines came from (kept in the job state for
        a resume). Setting `cancel` is all a caller needs to stop a print (the
        link looks at it at least 4 times a second); `cancel()` does the same.
        Raises PrinterHalted, LinkLost (job state saved where configured).
        """

    @abstractmethod
    def pause(self) -> None: ...

    @abstractmethod
    def resume(self) -> None: ...

    @abstractmethod
    def cancel(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc):
        self.close()


def eta(done: int, total: int, elapsed: float) -> float | None:
    """Seconds left at the average rate so far (None before any progress)."""
    if done <= 0 or elapsed <= 0 or total <= 0:
        return None
    return max(0.0, elapsed / done * (total - done))
