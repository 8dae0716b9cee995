"""The bed anchor set up in the GUI (pytest-qt): Printer set-up > Bed marker..., the marker centre or two
touched corners, saved into the printer profile and read back with load_profile.

Oracles: the geometry written here (a marker turned 90 degrees about z has bed_from_anchor's x axis
along bed +y; two touched corners 40 mm apart along +x put the centre 20 mm above their midpoint), and
the CLI (`arapp printer bed-anchor`) writing the same numbers for the same entry.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from PySide6.QtWidgets import QDialog

PORTS = [("/dev/ttyACM0", "a printer")]


@pytest.fixture(autouse=True)
def config_dir(tmp_path, monkeypatch):
    d = tmp_path / "config"
    monkeypatch.setenv("ARAPP_CONFIG_DIR", str(d))
    return d


@pytest.fixture()
def setup(qtbot):
    from arapp.gui.print.printer_setup import PrinterSetupDialog

    dlg = PrinterSetupDialog(ports=PORTS)
    qtbot.addWidget(dlg)
    dlg.profile.setCurrentIndex(dlg.profile.findData("preset:ender3"))
    dlg.show()
    return dlg


def open_bed_dialog(qtbot, setup):
    setup.bed_anchor_button.click()
    qtbot.waitUntil(lambda: getattr(setup, "bed_anchor_dialog", None) is not None
                    and setup.bed_anchor_dialog.isVisible(), timeout=5000)
    return setup.bed_anchor_dialog


def test_marker_centre_saved_into_a_profile_written_from_the_preset(qtbot, setup, config_dir):
    from arapp.printing.profile import load_profile

    assert "no bed marker" in setup.profile_info.text()
    d = open_bed_dialog(qtbot, setup)
    d.dictionary.setCurrentText("DICT_4X4_50")
    d.marker_id.setValue(7)
    d.length.setValue(30.0)
    d.centre_radio.setChecked(True)
    d.cx.setValue(110.0)
    d.cy.setValue(60.0)
    d.rotation.setValue(90.0)
    d.save_button.click()
    assert d.result() == QDialog.DialogCode.Accepted, d.message.text()

    path = config_dir / "printers" / "ender3.json"
    assert d.saved_path == path and path.is_file()
    p = load_profile(path)
    assert (p.bed.width, p.bed.depth) == (220, 220)  # the preset's bed, kept
    a, T = p.bed_anchor, p.bed_from_anchor
    assert (a.kind, a.dictionary, a.id) == ("aruco", "DICT_4X4_50", 7)
    assert a.length == pytest.approx(0.030)
    assert np.allclose(T[:3, 3], [110.0, 60.0, 0.0])
    assert np.allclose(T[:3, 0], [0.0, 1.0, 0.0], atol=1e-6)  # turned 90 deg: anchor x along bed +y

    # the set-up now uses that file, says so, and remembers it
    assert setup.profile.currentData() == str(path)
    assert "bed marker set up" in setup.profile_info.text()
    setup.save_button.click()
    from arapp.gui.print.printer_setup import saved_choice
    from arapp.printing.connection_check import saved_profile

    assert saved_choice()["profile"] == str(path)
    assert saved_profile(saved_choice()).bed_anchor.id == 7

    # opened again, the dialog shows what is stored
    setup2 = type(setup)(ports=PORTS)
    qtbot.addWidget(setup2)
    setup2.show()
    d2 = open_bed_dialog(qtbot, setup2)
    assert d2.marker_id.value() == 7 and d2.length.value() == pytest.approx(30.0)
    assert (d2.cx.value(), d2.cy.value(), d2.rotation.value()) == pytest.approx((110.0, 60.0, 90.0))


def test_touched_corners_give_the_same_anchor_as_the_cli(qtbot, setup, config_dir, tmp_path):
    from arapp.commands import printer as cli
    from arapp.printing.profile import load_profile

    d = open_bed_dialog(qtbot, setup)
    d.touch_radio.setChecked(True)
    assert d.touch_box.isVisible() and not d.centre_box.isVisible()
    d.length.setValue(40.0)
    d.marker_id.setValue(42)
    for box, v in zip((d.x1, d.y1, d.x2, d.y2), (100.0, 50.0, 140.0, 50.0)):
        box.setValue(v)
    d.save_button.click()
    assert d.result() == QDialog.DialogCode.Accepted, d.message.text()
    T = load_profile(d.saved_path).bed_from_anchor
    assert np.allclose(T[:3, 3], [120.0, 70.0, 0.0])  # midpoint (120, 50) + 20 mm up the marker
    assert np.allclose(T[:3, :3], np.eye(3), atol=1e-6)

    cli_path = tmp_path / "cli.json"
    from arapp.printing.presets import write_preset

    write_preset("ender3", cli_path)
    from tracking.anchors.defaults import DEFAULT_DICTIONARY

    assert d.dictionary.currentText() == DEFAULT_DICTIONARY  # the CLI's default marker
    args = argparse.Namespace(printer=str(cli_path), create=False, dictionary=DEFAULT_DICTIONARY, id=42, length=0.04,
                              center=None, touched=[100.0, 50.0, 140.0, 50.0], rotation=0.0)
    assert cli.run(args) == 0
    assert json.loads(cli_path.read_text())["bed_anchor"] == json.loads(d.saved_path.read_text())["bed_anchor"]


def test_corners_that_do_not_fit_the_side_are_refused_in_one_line(qtbot, setup, config_dir):
    d = open_bed_dialog(qtbot, setup)
    d.touch_radio.setChecked(True)
    d.length.setValue(40.0)
    for box, v in zip((d.x1, d.y1, d.x2, d.y2), (100.0, 50.0, 130.0, 50.0)):
        box.setValue(v)
    d.save_button.click()
    assert d.isVisible() and d.result() != QDialog.DialogCode.Accepted
    assert d.message.text().startswith("Not saved: the touched corners are 30.0 mm apart")
    assert "\n" not in d.message.text()
    written = config_dir / "printers" / "ender3.json"
    assert not written.exists() or "bed_anchor" not in json.loads(written.read_text())
