"""One factory for printer links: a target (where the printer is) -> a `PrintLink`, not connected.

`arapp print` and the GUI both call `make_link`. A new backend is one module
with a `PrintLink` subclass, one target dataclass, and one entry in `_MAKERS`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .base import PrintLink


@dataclass(frozen=True)
class SerialTarget:
    """A Marlin printer on a serial port (device path or pyserial URL).

    window: unacknowledged lines in flight; timeout: seconds without an
    answer before a line is sent again.
    """

    port: str
    baud: int = 115200
    window: int = 1
    timeout: float = 10.0


@dataclass(frozen=True)
class OctoPrintTarget:
    """An OctoPrint server and the file holding its API key."""

    url: str
    api_key_file: str


@dataclass(frozen=True)
class MoonrakerTarget:
    """A Klipper printer behind Moonraker, and the file holding its API key ("" on a trusted LAN)."""

    url: str
    api_key_file: str = ""


@dataclass(frozen=True)
class PrusaLinkTarget:
    """A Prusa printer behind PrusaLink, and the file of mode 600 holding its API key, or its digest user and
    the file holding that user's password."""

    url: str
    api_key_file: str = ""
    user: str = ""
    password_file: str = ""


def _serial(target: SerialTarget, profile, job_path) -> PrintLink:
    from .serial_link import SerialPrinter  # each backend's dependencies load only when it is chosen

    if not target.port:
        raise ValueError("no serial port: give --port DEV (e.g. /dev/ttyUSB0) or set link.port in the printer profile")
    bed_height = getattr(getattr(profile, "bed", None), "height", None)
    return SerialPrinter(target.port, target.baud, window=target.window, timeout=target.timeout,
                         job_path=job_path, bed_height=bed_height)


def _octoprint(target: OctoPrintTarget, profile, job_path) -> PrintLink:
    from .octoprint import OctoPrintLink  # requests: only for the HTTP links
    from .webapi import load_api_key

    if not target.url:
        raise ValueError("give the OctoPrint URL (e.g. http://octopi.local) and the API key file")
    if not target.api_key_file:
        raise ValueError("--octoprint needs --api-key-file F (or --save-key F to store a key first)")
    return OctoPrintLink(target.url, load_api_key(target.api_key_file), job_path=job_path)


def _moonraker(target: MoonrakerTarget, profile, job_path) -> PrintLink:
    # each backend's HTTP/websocket code is imported only when that backend is used
    from .moonraker import MoonrakerLink
    from .webapi import load_api_key

    if not target.url:
        raise ValueError("give the Moonraker URL (e.g. http://mainsailos.local or http://host:7125)")
    key = load_api_key(target.api_key_file) if target.api_key_file else None
    return MoonrakerLink(target.url, key, job_path=job_path)


def _prusalink(target: PrusaLinkTarget, profile, job_path) -> PrintLink:
    # (imported when used, as for Moonraker)
    from .prusalink import PrusaLinkLink
    from .webapi import ApiKeyError, load_api_key

    if not target.url:
        raise ValueError("give the PrusaLink URL (e.g. http://prusa-mk4.local)")
    if target.api_key_file:
        return PrusaLinkLink(target.url, load_api_key(target.api_key_file), job_path=job_path)
    if not (target.user and target.password_file):
        raise ValueError("--prusalink needs --api-key-file F, or --prusalink-user NAME and --password-file F "
                         "(the password in a file of mode 600)")
    try:
        password = load_api_key(target.password_file)
    except ApiKeyError as exc:
        raise ApiKeyError(str(exc).replace("API key file", "password file")) from None
    return PrusaLinkLink(target.url, user=target.user, password=password, job_path=job_path)


_MAKERS: dict[type, Callable] = {SerialTarget: _serial, OctoPrintTarget: _octoprint}
_MAKERS[MoonrakerTarget] = _moonraker
_MAKERS[PrusaLinkTarget] = _prusalink


def make_link(target, *, profile=None, job_path=None) -> PrintLink:
    """The link for `target` (SerialTarget, OctoPrintTarget, MoonrakerTarget, PrusaLinkTarget, ...: `_MAKERS`), not connected yet.

    profile: the printer profile (its bed height caps a cancel's nozzle lift);
    job_path: where the job state is kept. Raises ValueError for an incomplete
    target, ApiKeyError/OSError for an unreadable key file.
    """
    maker = _MAKERS.get(type(target))
    if maker is None:
        raise TypeError(f"no printer link for a {type(target).__name__}; known: "
                        f"{', '.join(t.__name__ for t in _MAKERS)}")
    return maker(target, profile, job_path)
