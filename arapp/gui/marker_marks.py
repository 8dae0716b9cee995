"""Detected markers outlined with their axes, painted over the live view (View > Show detected markers).

What to draw comes from `arapp.app.overlay_marks.marker_marks` (frame pixels, no Qt) for the frame
being shown; this module only paints it over the VideoView's frame rectangle.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QPointF, Qt
from PySide6.QtGui import QAction, QColor, QPainter, QPen
from PySide6.QtWidgets import QWidget

from arapp.app.overlay_marks import MarkerMarks, marker_marks

SETTING = "view/show_marker_marks"
OUTLINE = QColor(0, 230, 255)            # cyan: stands out on paper, skin and wood alike
AXIS_COLOURS = (QColor(255, 40, 40), QColor(40, 220, 40), QColor(60, 110, 255))  # x red, y green, z blue


class MarksOverlay(QWidget):
    """Transparent child of the VideoView painting `marks` (MarkerMarks or None) over the frame."""

    def __init__(self, view):
        super().__init__(view)
        self.view = view
        self.marks: MarkerMarks | None = None
        self.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents, True)
        self.setAttribute(Qt.WidgetAttribute.WA_NoSystemBackground, True)
        self.setGeometry(view.rect())
        view.installEventFilter(self)

    def eventFilter(self, obj: QObject, event: QEvent) -> bool:  # noqa: N802
        if obj is self.view and event.type() == QEvent.Type.Resize:
            self.setGeometry(self.view.rect())
        return False

    def paintEvent(self, event):  # noqa: N802
        m = self.marks
        if m is None or self.view.image() is None or (not m.quads and not m.axes):
            return
        rect = self.view.image_rect()
        sx, sy = rect.width() / m.width, rect.height() / m.height

        def pt(uv):  # frame pixel (centres at integers) -> widget point
            return QPointF(rect.x() + (float(uv[0]) + 0.5) * sx, rect.y() + (float(uv[1]) + 0.5) * sy)

        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, True)
        p.setClipRect(rect)
        p.setPen(QPen(OUTLINE, 2.0))
        for quad in m.quads:
            pts = [pt(uv) for uv in quad]
            for a, b in zip(pts, pts[1:] + pts[:1]):
                p.drawLine(a, b)
        for origin, *ends in m.axes:
            o = pt(origin)
            for colour, end in zip(AXIS_COLOURS, ends):
                p.setPen(QPen(colour, 3.0, Qt.PenStyle.SolidLine, Qt.PenCapStyle.RoundCap))
                p.drawLine(o, pt(end))
        p.end()


def install_marks(window) -> MarksOverlay:
    """Add the overlay to MainWindow `window`'s view and the View menu toggle (default on, remembered)."""
    overlay = MarksOverlay(window.view)
    window.marks_overlay = overlay
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

    def refresh(_shown=None):
        shown, info = session.last_shown, session.source_info
        if not action.isChecked() or shown is None or info is None or info.camera is None:
            overlay.marks = None
        else:
            r = shown.result
            overlay.marks = marker_marks(info.camera, info.anchors, r.world_from_camera,
                                         r.markers if r.state == "marker" else 0)
        overlay.update()

    def toggled(checked: bool):
        session.settings.setValue(SETTING, bool(checked))
        refresh()

    action.toggled.connect(toggled)
    session.events.frame.connect(refresh)
    return overlay
