"""Printer set-up checks a host runs before a print (no Qt here): serial ports, Test connection, the
OctoPrint key kept once in the user's config folder.

`list_ports()` lists serial ports as serial.tools.list_ports sees them, with
the USB description a user recognises ("Original Prusa i3 MK3", "USB
Serial"); nothing is chosen for the user. `check_serial(port, baud)` opens the
port, resets line numbers and asks M115 (SerialPrinter.connect), and reports
the firmware name. `check_octoprint(url, key)` asks OctoPrint's REST API for
its version (`GET /api/version`) and the printer's state (`GET
/api/connection`). `check_moonraker(url, key)` asks Moonraker for its version
and Klipper's state (the key is optional on a trusted LAN). The API key travels
in the X-Api-Key header only and is never part of a message; `store_key` (and
`store_octoprint_key`) writes it with mode 600 in the user's config folder.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import requests
from serial.tools import list_ports as lp

from arapp.printing.link.base import LinkError
from arapp.printing.link.factory import MoonrakerTarget, OctoPrintTarget, SerialTarget
from arapp.printing.link.webapi import ApiKeyError, load_api_key, save_api_key
from arapp.printing.link.serial_link import SerialPrinter
from arapp.printing.presets import preset_profile
from arapp.printing.profile import load_profile
from arapp.store.user_config import secret_path

# a serial check gives up after this long without an `ok` (the printer's 15 s default is for prints)
SERIAL_CHECK_TIMEOUT_S = 6.0


@dataclass
class CheckResult:
    """`ok`; `summary` one line for the user; `details` what was learnt (firmware, version, state)."""

    ok: bool
    summary: str
    details: dict


def list_ports() -> list[tuple[str, str]]:
    """(device, description) of the serial ports present, USB ones first; the description adds the
    maker's product name when the port has one."""
    out = []
    for p in lp.comports():
        desc = p.description if p.description and p.description != "n/a" else ""
        if p.manufacturer and p.manufacturer not in desc:
            desc = f"{desc} ({p.manufacturer})" if desc else p.manufacturer
        usb = p.vid is not None
        out.append((usb, p.device, desc or ("USB serial" if usb else "serial port")))
    out.sort(key=lambda x: (not x[0], x[1]))
    return [(dev, desc) for _, dev, desc in out]


def firmware_name(m115: str) -> str:
    """'Marlin 2.1.2' style name from an M115 reply ('FIRMWARE_NAME:Marlin 2.1.2 (...) SOURCE_CODE_URL:...')."""
    m = re.search(r"FIRMWARE_NAME:(.*?)(?:\s+[A-Z_]+:|$)", m115)
    return m.group(1).strip() if m else m115.strip()


def check_serial(port: str, baud: int = 115200, timeout_s: float = SERIAL_CHECK_TIMEOUT_S) -> CheckResult:
    """Open `port`, say hello (M110), ask M115, close. Never raises for a printer that is off or absent."""
    if not port:
        return CheckResult(False, "Choose the printer's port first", {})
    link = SerialPrinter(port, int(baud), connect_timeout=timeout_s, boot_wait=min(2.0, timeout_s / 2))
    try:
        link.connect()
    except (OSError, LinkError) as exc:
        return CheckResult(False, str(exc), {})
    finally:
        link.close()
    name = firmware_name(link.firmware) if link.firmware else "a printer (no firmware name in the M115 reply)"
    caps = sorted(k for k, v in link.capabilities.items() if v)
    return CheckResult(True, f"Connected on {port} at {baud} baud: {name}",
                       {"firmware": link.firmware, "capabilities": caps})


def check_octoprint(url: str, api_key: str, timeout_s: float = 5.0) -> CheckResult:
    """Ask OctoPrint at `url` for its version and the printer's connection state."""
    url = url.strip().rstrip("/")
    if not re.match(r"^https?://", url):
        return CheckResult(False, f"OctoPrint address must start with http:// or https://, got {url!r}", {})
    if not api_key:
        return CheckResult(False, "Paste the API key (OctoPrint: Settings > API, or a user's Application Key)", {})
    headers = {"X-Api-Key": api_key}
    try:
        r = requests.get(url + "/api/version", headers=headers, timeout=timeout_s)
        if r.status_code in (401, 403):
            return CheckResult(False, f"OctoPrint at {url} refused the API key (HTTP {r.status_code})", {})
        r.raise_for_status()
        version = r.json().get("text", "OctoPrint")
        c = requests.get(url + "/api/connection", headers=headers, timeout=timeout_s)
        c.raise_for_status()
        current = c.json().get("current", {})
    except requests.RequestException as exc:
        return CheckResult(False, f"OctoPrint at {url} cannot be reached ({type(exc).__name__}); check the "
                                  "address and that the server is running", {})
    except ValueError:
        return CheckResult(False, f"{url} answered, but not as OctoPrint does (no JSON); check the address", {})
    state = current.get("state") or "unknown"
    port = current.get("port")
    printer = f"printer {state}" + (f" on {port}" if port else "")
    if state in ("Closed", "Offline") or state.startswith("Offline"):
        printer += "; connect the printer in OctoPrint"
    return CheckResult(True, f"{version}: {printer}", {"version": version, "state": state, "port": port})


def check_moonraker(url: str, api_key: str | None = None, timeout_s: float = 5.0) -> CheckResult:
    """Ask Moonraker at `url` for its version and whether Klipper is ready (no key: a trusted client)."""
    from arapp.printing.link.moonraker import check_moonraker as check  # the Moonraker link: only when checked

    ok, summary, details = check(url, api_key or None, timeout_s)
    return CheckResult(ok, summary, details)


def key_path(kind: str, url: str) -> Path:
    """Where the API key of the `kind` ("octoprint", "moonraker", ...) server at `url` is kept (mode 600)."""
    return secret_path(f"{kind} {url.strip().rstrip('/')}")


def store_key(kind: str, url: str, api_key: str) -> Path:
    """Keep the key for the `kind` server at `url` in the user's config folder (mode 600); returns the file."""
    return save_api_key(key_path(kind, url), api_key)


def stored_key(kind: str, url: str) -> str | None:
    """The key kept for the `kind` server at `url`, or None when there is none (or it is unusable)."""
    path = key_path(kind, url)
    if not path.exists():
        return None
    try:
        return load_api_key(path)
    except ApiKeyError:
        return None


def octoprint_key_path(url: str) -> Path:
    return key_path("octoprint", url)


def store_octoprint_key(url: str, api_key: str) -> Path:
    """Keep the key for `url` in the user's config folder (mode 600); returns the file."""
    return store_key("octoprint", url, api_key)


def stored_octoprint_key(url: str) -> str | None:
    """The key kept for `url`, or None when there is none (or it is unusable: the user pastes it again)."""
    return stored_key("octoprint", url)


def saved_target(choice: dict):
    """The printer-link target (arapp.printing.link.factory SerialTarget / OctoPrintTarget / MoonrakerTarget) of a saved
    printer set-up (arapp.gui.print.printer_setup.saved_choice()), or None when it names no port or server.
    An OctoPrint target points at the stored key file."""
    if choice.get("link") == "octoprint":
        url = str(choice.get("url") or "").strip().rstrip("/")
        return OctoPrintTarget(url, str(octoprint_key_path(url))) if url else None
    if choice.get("link") == "moonraker":
        url = str(choice.get("url") or "").strip().rstrip("/")
        if not url:
            return None
        path = key_path("moonraker", url)
        return MoonrakerTarget(url, str(path) if path.exists() else "")
    port = str(choice.get("port") or "")
    return SerialTarget(port, int(choice.get("baud") or 115200)) if port else None


def saved_profile(choice: dict):
    """The printer profile of a saved set-up (a preset or a profile file), or None when it names none."""
    profile = choice.get("profile")
    if not isinstance(profile, str) or not profile or profile == "file":
        return None
    if profile.startswith("preset:"):
        return preset_profile(profile[len("preset:"):])
    return load_profile(profile)
