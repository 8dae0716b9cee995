"""Printer set-up: presets, ports, Test connection against the printer emulator and OctoPrint, the
OctoPrint key kept once (mode 600), the choice remembered.

Oracles: the makers' published build volumes (written here), the firmware
name the emulator (OctoPrint's VirtualPrinter) sends, the real OctoPrint
server's version and state.
"""

from __future__ import annotations

import os
import stat

import pytest
from test_octoprint_link import KEY as FAKE_KEY
from test_octoprint_link import octo  # noqa: F401 - fixture
from octoprint_server import KEY as REAL_KEY
from virtual_printer import VirtualPrinterPty

PORTS = [("/dev/ttyS0", "serial port"), ("/dev/ttyACM0", "Original Prusa i3 MK3 (Prusa Research)")]


@pytest.fixture(autouse=True)
def _own_config(config_dir):
    """Every test here reads and writes its own config folder (conftest's config_dir)."""
    return config_dir


def test_presets_have_the_makers_build_volumes():
    from arapp.printing.presets import preset_names, preset_profile

    volumes = {"prusa_mk3s": (250, 210, 210), "ender3": (220, 220, 250), "ender3_s1": (220, 220, 270),
               "ender3_max": (300, 300, 340), "generic_220": (220, 220, 250)}
    assert set(preset_names()) == set(volumes)
    for key, (w, d, h) in volumes.items():
        p = preset_profile(key)
        assert (p.bed.width, p.bed.depth, p.bed.height) == (w, d, h)
        assert p.link.port == "" and p.bed_anchor is None and p.flavor == "marlin"


def test_written_preset_loads_as_a_profile_file(tmp_path):
    from arapp.printing.presets import write_preset
    from arapp.printing.profile import load_profile

    path = write_preset("ender3", tmp_path / "my_ender.json", port="/dev/ttyUSB1", baud=115200)
    p = load_profile(path)
    assert p.name.startswith("Creality Ender-3") and p.link.port == "/dev/ttyUSB1"


def test_list_ports_describes_and_puts_usb_first(monkeypatch):
    from serial.tools import list_ports_common

    from arapp.printing import connection_check as cc

    def info(dev, desc, vid=None, manufacturer=None):
        p = list_ports_common.ListPortInfo(dev, skip_link_detection=True)
        p.description, p.vid, p.manufacturer = desc, vid, manufacturer
        return p

    monkeypatch.setattr("serial.tools.list_ports.comports",
                        lambda: [info("/dev/ttyS0", "n/a"), info("/dev/ttyACM0", "Original Prusa i3 MK3", 0x2C99,
                                                                 "Prusa Research (prusa3d.com)")])
    assert cc.list_ports() == [("/dev/ttyACM0", "Original Prusa i3 MK3 (Prusa Research (prusa3d.com))"),
                               ("/dev/ttyS0", "serial port")]


def test_no_port_is_preselected(qtbot):
    from arapp.gui.print.printer_setup import PrinterSetupDialog

    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    assert dlg.port.currentData() == "" and dlg.port.currentText() == "Choose a port"
    assert [dlg.port.itemText(i) for i in range(1, 3)] == ["/dev/ttyS0 - serial port",
                                                          "/dev/ttyACM0 - Original Prusa i3 MK3 (Prusa Research)"]
    with qtbot.waitSignal(dlg.tested, timeout=2000) as sig:
        dlg.test_button.click()
    assert not sig.args[0].ok and "Choose the printer's port" in dlg.result.text()


def test_serial_test_reports_the_emulators_firmware(qtbot):
    from arapp.gui.print.printer_setup import PrinterSetupDialog

    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        dlg.set_port(vp.port)
        with qtbot.waitSignal(dlg.tested, timeout=15000) as sig:
            dlg.test_button.click()
        sent = [line for line in vp.executed if line.startswith("M115")]
    res = sig.args[0]
    assert res.ok, res.summary
    assert dlg.result.text() == f"OK: Connected on {vp.port} at 115200 baud: Virtual Marlin 1.0"
    assert sent == ["M115"]


def test_serial_test_of_a_silent_port_gives_up_with_advice(qtbot, monkeypatch):
    from arapp.gui.print.printer_setup import PrinterSetupDialog
    from arapp.printing import connection_check as cc

    monkeypatch.setattr(cc, "SERIAL_CHECK_TIMEOUT_S", 1.0)
    monkeypatch.setattr(cc.check_serial, "__defaults__", (115200, 1.0))
    master, slave = os.openpty()  # a port where nothing answers
    try:
        dlg = PrinterSetupDialog(ports=[])
        qtbot.addWidget(dlg)
        dlg.set_port(os.ttyname(slave))
        with qtbot.waitSignal(dlg.tested, timeout=10000) as sig:
            dlg.test_button.click()
    finally:
        os.close(master)
        os.close(slave)
    assert not sig.args[0].ok
    assert "no answer from a printer" in dlg.result.text() and "baud rate" in dlg.result.text()


def test_octoprint_key_pasted_once_is_stored_600_and_used(qtbot, octo, config_dir):  # noqa: F811
    from arapp.gui.print.printer_setup import PrinterSetupDialog, saved_choice
    from arapp.printing.connection_check import octoprint_key_path

    url = f"http://127.0.0.1:{octo.server.server_address[1]}"
    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.octo_radio.setChecked(True)
    dlg.url.setText(url)
    dlg.key.setText("wrong-key")
    with qtbot.waitSignal(dlg.tested, timeout=10000):
        dlg.test_button.click()
    assert "refused the API key (HTTP 403)" in dlg.result.text()
    dlg.key.setText(FAKE_KEY)
    with qtbot.waitSignal(dlg.tested, timeout=10000):
        dlg.test_button.click()
    assert dlg.result.text() == "OK: OctoPrint 1.11.8: printer Operational on VIRTUAL"
    dlg.save_button.click()
    path = octoprint_key_path(url)
    assert path.is_relative_to(config_dir)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert path.read_text().strip() == FAKE_KEY
    assert saved_choice()["link"] == "octoprint" and saved_choice()["url"] == url
    # next time: nothing to paste, the stored key is used
    again = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(again)
    assert again.octo_radio.isChecked() and again.url.text() == url and again.key.text() == ""
    assert "stored" in again.key.placeholderText()
    with qtbot.waitSignal(again.tested, timeout=10000):
        again.test_button.click()
    assert again.result.text().startswith("OK: OctoPrint 1.11.8")
    assert FAKE_KEY not in again.result.text() + again.profile_info.text()


def test_octoprint_test_against_the_real_server(qtbot, octoprint):  # noqa: F811
    from arapp.gui.print.printer_setup import PrinterSetupDialog

    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.octo_radio.setChecked(True)
    dlg.url.setText(octoprint)
    dlg.key.setText(REAL_KEY)
    with qtbot.waitSignal(dlg.tested, timeout=20000) as sig:
        dlg.test_button.click()
    res = sig.args[0]
    assert res.ok, res.summary
    assert res.details["version"].startswith("OctoPrint 1.")
    assert res.details["state"] == "Operational"


def test_the_printer_and_port_are_remembered(qtbot, tmp_path):
    from arapp.gui.print.printer_setup import PrinterSetupDialog
    from arapp.printing.presets import write_preset

    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.profile.setCurrentIndex(dlg.profile.findData("preset:ender3"))
    dlg.port.setCurrentIndex(dlg.port.findData("/dev/ttyACM0"))
    dlg.save_button.click()
    again = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(again)
    assert again.profile.currentData() == "preset:ender3" and again.port.currentData() == "/dev/ttyACM0"
    assert "220 x 220 x 250 mm" in again.profile_info.text()
    # a profile file of the user's is remembered too
    path = str(write_preset("prusa_mk3s", tmp_path / "mine.json"))
    again.set_profile_file(path)
    again.save_button.click()
    third = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(third)
    assert third.profile.currentData() == path and "250 x 210 x 210 mm" in third.profile_info.text()


def test_saved_choice_gives_the_link_target_and_profile(qtbot, octo):  # noqa: F811
    from arapp.gui.print.printer_setup import PrinterSetupDialog, saved_choice
    from arapp.printing.connection_check import saved_profile, saved_target
    from arapp.printing.link.factory import OctoPrintTarget, SerialTarget, make_link

    assert saved_target({}) is None and saved_profile({}) is None
    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.profile.setCurrentIndex(dlg.profile.findData("preset:prusa_mk3s"))
    dlg.port.setCurrentIndex(dlg.port.findData("/dev/ttyACM0"))
    dlg.save_button.click()
    assert saved_target(saved_choice()) == SerialTarget("/dev/ttyACM0", 115200)
    assert saved_profile(saved_choice()).name == "Prusa i3 MK3S"
    url = octo.url
    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.octo_radio.setChecked(True)
    dlg.url.setText(url)
    dlg.key.setText(FAKE_KEY)
    dlg.save_button.click()
    target = saved_target(saved_choice())
    assert isinstance(target, OctoPrintTarget) and target.url == url
    link = make_link(target)  # the stored key file is what the print link reads
    link.connect()
    assert link.version == "OctoPrint 1.11.8"
    link.close()
