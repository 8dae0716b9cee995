"""One printer choice, used everywhere (pytest-qt): the printer saved in Printer set-up is the one the
print panel slices for; the panel lists the presets and the user's own profiles; a printer chosen in the
panel becomes the set-up's choice. Oracles: the presets' table (arapp.printing.presets.PRESETS) and a
profile file written here."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6.QtCore import Qt

MODELS = Path(__file__).resolve().parents[1] / "models"
TIMEOUT_MS = 60000


@pytest.fixture()
def window(threads_window):
    return threads_window


def test_setup_printer_is_sliced_for_and_listed(qtbot, window, tmp_path):
    from arapp.store import user_config
    from arapp.gui.print.printer_setup import saved_choice
    from arapp.printing.presets import PRESETS, write_preset

    own = write_preset("ender3", user_config.config_dir() / "printers" / "my_ender.json")
    user_config.remember("printer", {"profile": "preset:prusa_mk3s", "link": "serial", "port": "", "baud": 115200,
                                     "url": ""})
    window.open_model(str(MODELS / "sphere.json"))
    qtbot.waitUntil(lambda: window.model is not None, timeout=TIMEOUT_MS)
    window.model_panel.size.setValue(10.0)
    window.open_print_dialog()
    dlg = window._print_dialog
    dlg.work_dir = tmp_path / "jobs"
    keys = [dlg.profile.itemData(i) for i in range(dlg.profile.count())]
    assert {f"preset:{k}" for k in PRESETS} <= set(keys) and str(own) in keys and "generic" in keys
    assert dlg.profile_key() == "preset:prusa_mk3s" and dlg.profile.currentText() == "Prusa i3 MK3S"
    dlg.layer_height.setValue(0.3)
    qtbot.mouseClick(dlg.slice_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dlg.result is not None, timeout=TIMEOUT_MS)
    bed = dlg.session.profile.bed
    want = PRESETS["prusa_mk3s"]["bed"]
    assert (bed.width, bed.depth, bed.height) == (want["width"], want["depth"], want["height"])
    assert 'M862.3 P "MK3S"' in dlg.result.gcode  # the preset's own start G-code
    # the user's own profile chosen in the panel: the set-up's choice follows
    i = dlg.profile.findData(str(own))
    dlg.profile.setCurrentIndex(i)
    dlg.profile.activated.emit(i)
    assert saved_choice()["profile"] == str(own) and saved_choice()["link"] == "serial"
    dlg.close()
