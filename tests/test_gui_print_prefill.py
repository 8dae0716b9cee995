"""The print panel filled from the saved Printer set-up (pytest-qt): the port and baud, or the OctoPrint
address with the key the set-up stored (mode 600), and the profile file the set-up names; the target
the panel prints to reads that stored key, with no key file typed.

Oracles: the choice and key written here through the set-up's own storage, and the key file read back
with the OctoPrint link's reader (load_api_key)."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

MODELS = Path(__file__).resolve().parents[1] / "models"
KEY = "Zq8v3KJ2x9TEST0KEY0do0not0log0Wm"
TIMEOUT_MS = 30000


@pytest.fixture()
def window(threads_window):
    return threads_window


def print_panel(qtbot, w):
    w.open_model(str(MODELS / "sphere.json"))
    qtbot.waitUntil(lambda: w.model is not None, timeout=TIMEOUT_MS)
    w.open_print_dialog()
    assert w._print_dialog is not None
    return w._print_dialog


def test_octoprint_from_the_setup_uses_the_stored_key(qtbot, window, tmp_path):
    from arapp.store import user_config
    from arapp.gui.print.bed_anchor_dialog import profile_file_for
    from arapp.printing import connection_check as cc
    from arapp.printing.link import OctoPrintTarget
    from arapp.printing.link.webapi import load_api_key

    profile = profile_file_for("preset:ender3")  # the set-up's own profile file (as Bed marker... writes it)
    url = "http://octopi.local:5000"
    cc.store_octoprint_key(url, KEY)
    user_config.remember("printer", {"profile": str(profile), "link": "octoprint", "port": "", "baud": 115200,
                                     "url": url})
    dlg = print_panel(qtbot, window)
    assert dlg.use_octoprint.isChecked() and dlg.octoprint_url.text() == url
    assert dlg.api_key_file.text() == ""  # not asked for again
    assert dlg.profile_key() == str(profile)
    t = dlg.target()
    assert isinstance(t, OctoPrintTarget) and t.url == url
    assert load_api_key(t.api_key_file) == KEY
    assert stat.S_IMODE(Path(t.api_key_file).stat().st_mode) == 0o600
    # another address typed in the panel: no stored key is slipped in
    dlg.octoprint_url.setText("http://other.local")
    assert dlg.target().api_key_file == ""


def test_serial_port_and_baud_from_the_setup(qtbot, window):
    from arapp.store import user_config
    from arapp.printing.link import SerialTarget

    user_config.remember("printer", {"profile": "preset:prusa_mk3s", "link": "serial", "port": "/dev/ttyACM7",
                                     "baud": 250000, "url": ""})
    dlg = print_panel(qtbot, window)
    assert not dlg.use_octoprint.isChecked()
    assert dlg.target() == SerialTarget("/dev/ttyACM7", 250000)
