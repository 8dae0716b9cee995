"""Error boxes: one non-modal box per distinct (title, message), so frames keep flowing and a message
already on screen is not stacked again."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QMessageBox, QWidget


class ErrorBoxes:
    """The error boxes open over `parent`."""

    def __init__(self, parent: QWidget):
        self.parent = parent
        self._open: dict[tuple[str, str], QMessageBox] = {}

    def show(self, title: str, message: str) -> None:
        key = (title, message)
        if key in self._open:
            return
        box = QMessageBox(QMessageBox.Icon.Critical, title, message, QMessageBox.StandardButton.Ok, self.parent)
        box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose, True)
        box.finished.connect(lambda _r, k=key: self._open.pop(k, None))
        self._open[key] = box
        box.open()

    def open_boxes(self) -> list[QMessageBox]:
        return list(self._open.values())
