"""The docks' panels in scroll areas: their height scrolls (a 768 px screen is short), their width never does.

A panel's width can change after the window is shown (loading a model puts its unit after each
control-point field), so the scroll area watches its panel and widens to keep every field whole: a
sideways scroll bar in a side panel hid the ends of the fields on a 1366x768 screen. Widths are in
device-independent pixels.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject
from PySide6.QtWidgets import QDockWidget, QScrollArea, QWidget

# a panel gets the width it prefers up to this (its fields at their natural size); beyond it only its
# minimum, so a panel with long texts does not take the view's room
PREFERRED_MAX_PX = 460


class PanelScroll(QScrollArea):
    """A frameless scroll area around `panel` whose minimum width is the panel's need (see `need`), kept up
    to date as the panel's layout changes. It only grows: a panel whose texts change (the tracking numbers)
    does not make the dock's edge twitch."""

    def __init__(self, panel: QWidget, parent: QWidget | None = None):
        super().__init__(parent)
        self.setWidgetResizable(True)
        self.setFrameShape(QScrollArea.Shape.NoFrame)
        self.setWidget(panel)  # QScrollArea filters the panel's events (eventFilter below sees them too)
        self.refit()

    def need(self) -> int:
        """The width that shows the panel without a sideways scroll bar: its minimum, or what it prefers up
        to PREFERRED_MAX_PX, plus the vertical scroll bar (px)."""
        panel = self.widget()
        inner = max(panel.minimumSizeHint().width(), min(panel.sizeHint().width(), PREFERRED_MAX_PX))
        return inner + self.verticalScrollBar().sizeHint().width()

    def refit(self) -> None:
        want = self.need()
        if want > self.minimumWidth():
            self.setMinimumWidth(want)

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:  # noqa: N802 - Qt's name
        # LayoutRequest: the panel's contents changed size; its hints are fresh when asked now
        if watched is self.widget() and event.type() == QEvent.Type.LayoutRequest:
            self.refit()
        return super().eventFilter(watched, event)


def scroll_side_panels(window) -> None:
    """Put each dock's panel of `window` (a QMainWindow) into a `PanelScroll` (once)."""
    for dock in window.findChildren(QDockWidget):
        panel = dock.widget()
        if panel is None or isinstance(panel, QScrollArea):
            continue
        dock.setWidget(PanelScroll(panel))
