"""View > Show detected markers: outline each detected marker and draw the anchor's axes on the live view.

The engine's processing thread draws the marks into the picture it hands over, under the model
(arapp.engine.overlay_marks.draw_marks), so the UI thread neither computes nor paints them; this module
only holds the menu toggle, remembered in the settings.
"""

from __future__ import annotations

from PySide6.QtGui import QAction

SETTING = "view/show_marker_marks"


def install_marks(window) -> QAction:
    """Add the View menu toggle to MainWindow `window` (default on, remembered); returns the action."""
    session = window.session
    stored = session.settings.value(SETTING, True)
    on = stored if isinstance(stored, bool) else str(stored).lower() not in ("false", "0")
    action = QAction("Show detected markers", window)
    action.setCheckable(True)
    action.setChecked(on)
    action.setToolTip("Outline each detected marker and draw the anchor's axes (x red, y green, z blue)")
    window.marker_marks_action = action
    for a in window.menuBar().actions():
        if a.menu() is not None and a.text().replace("&", "") == "View":
            a.menu().addAction(action)
            break

    def toggled(checked: bool):
        session.settings.setValue(SETTING, bool(checked))
        session.set_show_marks(bool(checked))

    action.toggled.connect(toggled)
    session.set_show_marks(on)
    return action
