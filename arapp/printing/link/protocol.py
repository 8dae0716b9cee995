"""Marlin serial protocol: line framing and classification of printer replies.

Host to printer: `N<n> <command>*<checksum>`, the checksum the XOR of all bytes
before `*`. Printer to host: `ok`, `Resend: <n>` (or `rs <n>`), `busy:`,
`wait`, `echo:...`, temperature reports (`T:210.0 /210.0 B:60.0 /60.0`),
`start` (the firmware has just booted), `Error:...` and `!!...`.

A `Resend: n` means (Marlin): "the last line I accepted is n - 1". Errors about
line numbers and checksums are followed by such a request and are part of the
normal protocol; any other `Error:` or `!!` means the firmware has halted.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

# Kinds of printer reply (Reply.kind).
OK = "ok"
RESEND = "resend"
BUSY = "busy"
WAIT = "wait"
ECHO = "echo"
START = "start"
ERROR = "error"  # recoverable communication error; a resend request follows
FATAL = "fatal"  # the firmware halted
ACTION = "action"  # `//action:...` host action command
TEMPERATURE = "temperature"
OTHER = "other"

_RESEND = re.compile(r"^(?:resend|rs)\s*:?\s*N?\s*(-?\d+)", re.IGNORECASE)
_TEMP = re.compile(r"(?:^|\s)(T\d*|B|C)\s*:\s*(-?\d+(?:\.\d+)?)(?:\s*/\s*(-?\d+(?:\.\d+)?))?")
# Firmware messages about a damaged or out-of-sequence line (Marlin, and
# OctoPrint's VirtualPrinter wording): not fatal, a resend request follows or
# the line gets no answer and is sent again.
_RECOVERABLE = re.compile(
    r"checksum|line ?number|lineno|last line|expected line|format error", re.IGNORECASE
)
_COMMENT = re.compile(r";.*$")


@dataclass(frozen=True)
class Reply:
    """One line from the printer, classified.

    `line` is the resend line number for RESEND; `temperatures` maps heater
    names (`T`, `T0`, `B`, `C`) to (actual, target or None) in degrees C for any
    reply that carries them (ok replies to M105 do).
    """

    kind: str
    text: str
    line: int | None = None
    temperatures: dict = field(default_factory=dict)


def checksum(text: str) -> int:
    """XOR of the bytes of `text` (ASCII), as Marlin checks it."""
    value = 0
    for byte in text.encode("ascii", errors="replace"):
        value ^= byte
    return value


def frame(number: int, command: str) -> bytes:
    """The numbered, checksummed line for `command`, newline-terminated."""
    body = f"N{number} {command}"
    return f"{body}*{checksum(body)}\n".encode("ascii", errors="replace")


def clean_command(raw: str) -> str:
    """The command of a G-code source line without comment and surrounding blanks.

    Returns "" for comment-only and blank lines. A `*` would end the command
    early on the printer side, so it is an error for the caller to send one.
    """
    return _COMMENT.sub("", raw).strip()


def parse_temperatures(text: str) -> dict:
    """Heater readings in a reply: {"T": (210.0, 210.0), "B": (60.0, 60.0), ...}."""
    temps = {}
    for name, actual, target in _TEMP.findall(text):
        temps[name] = (float(actual), float(target) if target else None)
    return temps


def parse_reply(raw: str) -> Reply:
    """Classify one line the printer sent (without its newline)."""
    text = raw.strip()
    low = text.lower()
    if low.startswith("ok"):
        return Reply(OK, text, temperatures=parse_temperatures(text[2:]))
    m = _RESEND.match(text)
    if m:
        return Reply(RESEND, text, line=int(m.group(1)))
    if low.startswith("error:") or low.startswith("error "):
        message = text[6:].strip()
        kind = ERROR if _RECOVERABLE.search(message) else FATAL
        return Reply(kind, message)
    if text.startswith("!!"):
        return Reply(FATAL, text[2:].strip() or text)
    if low.startswith("fatal:"):
        return Reply(FATAL, text[6:].strip())
    if low == "start":
        return Reply(START, text)
    if low == "wait":
        return Reply(WAIT, text)
    if low.startswith("busy:") or low.startswith("echo:busy"):
        return Reply(BUSY, text)
    if text.startswith("//"):
        body = text[2:].strip()
        if body.lower().startswith("action:"):
            return Reply(ACTION, body[len("action:"):].strip())
        return Reply(OTHER, text)
    temps = parse_temperatures(text)
    if temps and re.match(r"^\s*(T\d*|B|C)\s*:", text):
        return Reply(TEMPERATURE, text, temperatures=temps)
    if low.startswith("echo:"):
        return Reply(ECHO, text[5:].strip())
    return Reply(OTHER, text)
