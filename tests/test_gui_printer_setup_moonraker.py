"""Printer set-up with a Klipper printer's Moonraker: the link-kind choice, Test connection against the
real Moonraker and Klippy (tests/moonraker_server.py), the key kept once with mode 600, the saved target.

Oracles: the real Moonraker's version and Klipper's state, Moonraker's own API key (`/access/api_key`).
"""

from __future__ import annotations

import stat

import pytest


@pytest.fixture(autouse=True)
def _own_config(config_dir):
    return config_dir


def test_moonraker_test_connection_save_and_reopen(qtbot, moonraker_server, config_dir):
    from arapp.gui.print.printer_setup import PrinterSetupDialog, saved_choice
    from arapp.printing.connection_check import key_path, saved_target
    from arapp.printing.link import MoonrakerTarget

    url = moonraker_server.url
    dlg = PrinterSetupDialog(ports=[])
    qtbot.addWidget(dlg)
    dlg.moonraker_radio.setChecked(True)
    assert dlg.octo_box.isVisibleTo(dlg) and not dlg.serial_box.isVisibleTo(dlg)
    assert "trusted_clients" in dlg.key.placeholderText()
    dlg.url.setText(url)
    with qtbot.waitSignal(dlg.tested, timeout=20000):
        dlg.test_button.click()  # no key: this machine is one of Moonraker's trusted clients
    assert dlg.result.text() == "OK: Moonraker 0.11.0: Klipper ready (Printer is ready)"
    dlg.key.setText("0" * 32)
    with qtbot.waitSignal(dlg.tested, timeout=20000):
        dlg.test_button.click()
    assert dlg.result.text().startswith(f"Failed: Moonraker at {url} refused the API key (HTTP 401)")
    key = moonraker_server.api_key()
    dlg.key.setText(key)
    with qtbot.waitSignal(dlg.tested, timeout=20000):
        dlg.test_button.click()
    assert dlg.result.text().startswith("OK: Moonraker 0.11.0")
    dlg.save_button.click()
    path = key_path("moonraker", url)
    assert path.is_relative_to(config_dir) and stat.S_IMODE(path.stat().st_mode) == 0o600
    assert path.read_text().strip() == key
    assert saved_choice()["link"] == "moonraker"
    assert saved_target(saved_choice()) == MoonrakerTarget(url, str(path))
    again = PrinterSetupDialog(ports=[])
    qtbot.addWidget(again)
    assert again.moonraker_radio.isChecked() and again.url.text() == url and again.key.text() == ""
    assert "stored" in again.key.placeholderText()
    with qtbot.waitSignal(again.tested, timeout=20000):
        again.test_button.click()
    assert again.result.text().startswith("OK: Moonraker 0.11.0")
    assert key not in again.result.text()
