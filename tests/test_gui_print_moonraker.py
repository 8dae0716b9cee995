"""The print panel prints through Klipper's Moonraker (issue 27): the Printer set-up's Moonraker choice fills
the panel, the sliced job goes to the real Moonraker and Klippy (tests/moonraker_server.py), and the job's
progress reaches the panel.

Oracles: the file Moonraker stored (compared with the panel's own G-code) and Klipper's `print_stats`.
"""

from __future__ import annotations

from PySide6.QtCore import Qt

from test_gui_print import TIMEOUT_MS, bed_profile, sliced_dialog, window  # noqa: F401  (fixtures)


def test_print_panel_prints_through_moonraker(qtbot, window, tmp_path, bed_profile, moonraker_server,  # noqa: F811
                                              config_dir):
    from arapp.store import user_config
    from arapp.gui.print.setup_prefill import prefill
    from arapp.gui.print.printer_setup import STATE_KEY
    from arapp.printing.link import MoonrakerTarget

    user_config.remember(STATE_KEY, {"link": "moonraker", "url": moonraker_server.url})
    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=6.0)
    assert prefill(dlg) == f"From Printer set-up: Klipper (Moonraker) at {moonraker_server.url}"
    assert dlg.use_moonraker.isChecked()
    assert dlg.target() == MoonrakerTarget(moonraker_server.url, "")  # a trusted client: no key
    finished, reports = [], []
    dlg.print_finished.connect(finished.append)
    dlg.progress_reported.connect(reports.append)
    qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
    assert finished[0].error is None, finished[0].error
    ps = moonraker_server.query("print_stats")["print_stats"]
    assert ps["state"] == "complete", ps
    stored = (moonraker_server.gcodes / ps["filename"]).read_text()
    assert stored.splitlines() == dlg.result.gcode.splitlines()
    assert reports[-1].state == "done" and reports[-1].percent == 100.0
    n = dlg.result.layers
    assert dlg.print_layer_label.text() == f"layer {n} / {n}"
