"""The print panel filled from the saved Printer set-up (File > Printer set-up...), so the port, the
OctoPrint address and its key are not asked for again.

`prefill(dlg)` sets the panel's connection fields (and the profile, when the set-up names a profile
file) from `arapp.gui.print.printer_setup.saved_choice()`; `with_setup_key(target)` completes an OctoPrint
target typed without a key file with the key the set-up stored for that address
(`arapp.printing.connection_check.saved_target`, a file of mode 600 in the user's config folder).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from arapp.store import user_config
from arapp.gui.print.printer_setup import STATE_KEY, saved_choice
from arapp.printing import connection_check as cc
from arapp.printing.link import MoonrakerTarget, OctoPrintTarget

STORED_KEY_HINT = "the key stored by Printer set-up (or a file holding another)"


def _same_url(a: str, b: str) -> bool:
    return a.strip().rstrip("/") == b.strip().rstrip("/")


def prefill(dlg) -> str:
    """Fill PrintDialog `dlg`'s printer fields from the saved set-up; returns a line saying what was used
    ("" when nothing is saved)."""
    choice = saved_choice()
    if not choice:
        return ""
    profile = choice.get("profile")
    if isinstance(profile, str) and profile.startswith("preset:") and dlg.profile.findData(profile) >= 0:
        dlg.profile.setCurrentIndex(dlg.profile.findData(profile))  # the set-up's printer, not the panel's last
    elif isinstance(profile, str) and profile and Path(profile).is_file():
        dlg.set_profile_path(profile)
    if choice.get("link") == "octoprint" and choice.get("url"):
        url = str(choice["url"]).strip()
        dlg.use_octoprint.setChecked(True)
        dlg.octoprint_url.setText(url)
        if cc.stored_octoprint_key(url):
            dlg.api_key_file.clear()
            dlg.api_key_file.setPlaceholderText(STORED_KEY_HINT)
        return f"From Printer set-up: OctoPrint at {url}"
    if choice.get("link") == "moonraker" and choice.get("url"):
        url = str(choice["url"]).strip()
        dlg.use_moonraker.setChecked(True)
        dlg.moonraker_url.setText(url)
        if (cc.saved_target(choice) or MoonrakerTarget("")).api_key_file:
            dlg.api_key_file.clear()
            dlg.api_key_file.setPlaceholderText(STORED_KEY_HINT)
        return f"From Printer set-up: Klipper (Moonraker) at {url}"
    if choice.get("port"):
        dlg.use_serial.setChecked(True)
        dlg.port.setCurrentText(str(choice["port"]))
        dlg.baud.setCurrentText(str(int(choice.get("baud") or 115200)))
        return f"From Printer set-up: {choice['port']} at {int(choice.get('baud') or 115200)} baud"
    return ""


def remember_printer(key: str) -> None:
    """The printer chosen in the print panel becomes the set-up's choice too (one printer choice)."""
    choice = saved_choice()
    if key and choice.get("profile") != key:
        user_config.remember(STATE_KEY, {**choice, "profile": key})


def with_setup_key(target):
    """`target` unchanged, except an OctoPrint or Moonraker target with no key file at the set-up's address:
    then the set-up's own target, which reads the stored key."""
    if not isinstance(target, (OctoPrintTarget, MoonrakerTarget)) or target.api_key_file:
        return target
    choice = saved_choice()
    saved = cc.saved_target(choice) if choice.get("link") in ("octoprint", "moonraker") else None
    if (type(saved) is type(target) and _same_url(saved.url, target.url) and saved.api_key_file
            and Path(saved.api_key_file).is_file()):
        return replace(target, api_key_file=saved.api_key_file)
    return target
