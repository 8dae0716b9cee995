"""Printer links: Marlin over USB serial, OctoPrint's REST API, Moonraker (Klipper) and PrusaLink.

`SerialPrinter` and `OctoPrintLink` share the `PrintLink` interface and report
`Progress` (lines, layer, percent, ETA, temperatures); `make_link(target)`
makes either from a `SerialTarget` or an `OctoPrintTarget`. The serial
protocol's rules are the state object `stream.LineStream`.
"""

from .base import LinkError, LinkLost, PrinterHalted, PrinterReset, PrintLink, Progress
from .factory import MoonrakerTarget, OctoPrintTarget, SerialTarget, make_link
from .job import JobFileError, JobState, Program, cancel_commands, resume_commands

__all__ = [
    "LinkError", "LinkLost", "PrinterHalted", "PrinterReset", "PrintLink", "Progress",
    "JobFileError", "JobState", "Program", "cancel_commands", "resume_commands",
    "SerialPrinter", "OctoPrintLink", "make_link", "SerialTarget", "OctoPrintTarget",
    "MoonrakerTarget",
]


def __getattr__(name):
    # Imported on use: pyserial / HTTP code stays out of `import arapp.printing.link`.
    if name == "SerialPrinter":
        from .serial_link import SerialPrinter

        return SerialPrinter
    if name == "OctoPrintLink":
        from .octoprint import OctoPrintLink

        return OctoPrintLink
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
