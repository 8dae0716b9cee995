"""The Model dock at a 1366x768 window (pytest-qt, offscreen): its panel needs no sideways scrolling and every
field shows its whole value, with a model in millimetres and one in centimetres loaded.

Old code: the three control-point fields were sized for their range's ends (-1000000.000) and the dock's
width was fixed before a model put its unit after each field, so the panel was ~100 px wider than the
dock and a horizontal scroll bar hid the fields' ends."""

from __future__ import annotations

from pathlib import Path

import pytest
from gui_helpers import TIMEOUT_MS
from PySide6.QtWidgets import QAbstractSpinBox, QDockWidget, QScrollArea

MODELS = Path(__file__).resolve().parents[1] / "models"


@pytest.fixture()
def window(threads_window):
    return threads_window


def _shows_whole_text(box: QAbstractSpinBox) -> bool:
    """The rule: the field's text, as the font draws it, fits in the field's text area."""
    edit = box.lineEdit()
    return edit.fontMetrics().horizontalAdvance(edit.text()) <= edit.width()


@pytest.mark.parametrize("name", ["vase.json", "hyperbolic_paraboloid.json"])  # mm, cm
def test_model_dock_fits_a_1366x768_window(qtbot, window, name):
    w = window
    w.resize(1366, 768)
    w.open_model(str(MODELS / name))
    qtbot.waitUntil(lambda: w.model is not None and Path(w.model_path).name == name, timeout=TIMEOUT_MS)
    qtbot.wait(200)  # the layout settles (posted layout requests)
    assert (w.width(), w.height()) == (1366, 768)
    area = w.findChild(QDockWidget, "dock_model").widget()
    assert isinstance(area, QScrollArea)
    panel = area.widget()
    assert area.horizontalScrollBar().maximum() == 0, (panel.minimumSizeHint().width(), area.viewport().width())
    assert panel.minimumSizeHint().width() <= area.viewport().width()
    assert panel.width() <= area.viewport().width()
    boxes = [b for b in panel.findChildren(QAbstractSpinBox) if b.isVisibleTo(panel)]
    assert len(boxes) >= 8  # size, offset x y z, rotation, weight, position x y z (and the point's indices)
    clipped = [(b.text(), b.width()) for b in boxes if not _shows_whole_text(b)]
    assert not clipped
    # the view keeps most of the window
    assert w.view.width() >= 0.6 * w.width()
