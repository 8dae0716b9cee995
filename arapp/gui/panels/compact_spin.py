"""A spin box sized for the values it usually shows rather than for the ends of its range.

Qt sizes a QDoubleSpinBox for the longest text its range can produce: a control-point field taking
-1000000.000 to 1000000.000 asks for room for twelve digits, and three of them in a row made the Model
panel wider than its dock on a 1366x768 screen. A value longer than the sample still fits: the field
scrolls its text while it is edited and shows it whole when the panel is wider.
"""

from __future__ import annotations

from PySide6.QtCore import QSize
from PySide6.QtWidgets import QDoubleSpinBox, QStyle, QStyleOptionSpinBox


class CompactSpin(QDoubleSpinBox):
    """A QDoubleSpinBox whose size hints fit `sample` (a typical value's text, e.g. "-000.000") with the
    prefix and suffix in force, instead of the range's longest value. `suffix_room`: a suffix the field
    keeps room for before it has one (a unit set later), so the panel keeps its width when it is set."""

    def __init__(self, sample: str, suffix_room: str = "", parent=None):
        super().__init__(parent)
        self.sample = sample
        self.suffix_room = suffix_room

    def _hint(self, base: QSize) -> QSize:
        # as QAbstractSpinBox::sizeHint does, with the sample as the text: the text's advance, a space and
        # 2 px for the cursor, then the style adds the frame and the arrow buttons
        fm = self.fontMetrics()
        suffix = max(fm.horizontalAdvance(self.suffix()), fm.horizontalAdvance(self.suffix_room))
        width = fm.horizontalAdvance(self.prefix() + self.sample + " ") + suffix + 2
        opt = QStyleOptionSpinBox()
        self.initStyleOption(opt)
        height = self.lineEdit().sizeHint().height()
        size = self.style().sizeFromContents(QStyle.ContentsType.CT_SpinBox, opt, QSize(width, height), self)
        return QSize(min(size.width(), base.width()), base.height())

    def sizeHint(self) -> QSize:  # noqa: N802 - Qt's name
        return self._hint(super().sizeHint())

    def minimumSizeHint(self) -> QSize:  # noqa: N802 - Qt's name
        return self._hint(super().minimumSizeHint())
