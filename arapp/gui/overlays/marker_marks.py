"""Detected markers outlined with their axes, painted over the live view (View > Show detected markers).

What to draw comes from `arapp.app.overlay_marks.marker_marks` (frame pixels, no Qt) for the frame
being shown; this module only paints it over the VideoView's frame rectangle. The marks lie on the paper
under the model: where the placed model covers a line it is painted only as much as the display mode's
surface lets it show through (not at all when shaded).
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QPointF, Qt
from PySide6.QtGui import QAction, QColor, QPainter, QPen
from PySide6.QtWidgets import QWidget

from arapp.app.overlay_marks import MarkerMarks, marker_marks, model_cover, model_world_vertices

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

        outline_pen = QPen(OUTLINE, 2.0)
        axis_pen = QPen(OUTLINE, 3.0, Qt.PenStyle.SolidLine, Qt.PenCapStyle.FlatCap)
        lines = m.lines()
        for (_a, _b, kind), runs in zip(lines, m.runs([(a, b) for a, b, _ in lines])):
            colour, pen = (OUTLINE, outline_pen) if kind < 0 else (AXIS_COLOURS[kind], axis_pen)
            for s, e, covered in runs:
                if covered and m.under_opacity <= 0:
                    continue  # under an opaque model: hidden, as the paper there is
                c = QColor(colour)
                if covered:
                    c.setAlphaF(m.under_opacity)  # seen through the model's surface
                pen.setColor(c)
                p.setPen(pen)
                p.drawLine(pt(s), pt(e))
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

    placed = {}  # (model, mesh, placement, anchor) ids -> the mesh's world vertices: moved only when they change

    def cover_of(info, r):
        mesh = (session.mesh_lines or (None,))[0]
        if session.model is None or mesh is None or r.world_from_camera is None or not info.anchors:
            return None
        key = (id(session.model), id(mesh), repr(session.placement), id(info.anchors[0]))
        if key not in placed:
            placed.clear()
            placed[key] = model_world_vertices(session.model, mesh, session.placement, info.anchors[0])
        return model_cover(info.camera, placed[key], mesh.faces, r.world_from_camera)

    def refresh(_shown=None):
        shown, info = session.last_shown, session.source_info
        if not action.isChecked() or shown is None or info is None or info.camera is None:
            overlay.marks = None
        else:
            r = shown.result
            seen = r.markers if r.state == "marker" else 0
            cover = cover_of(info, r) if seen else None
            overlay.marks = marker_marks(info.camera, info.anchors, r.world_from_camera, seen, cover=cover,
                                         mode=session.display_mode)
        overlay.update()

    def toggled(checked: bool):
        session.settings.setValue(SETTING, bool(checked))
        refresh()

    action.toggled.connect(toggled)
    session.events.frame.connect(refresh)
    return overlay
