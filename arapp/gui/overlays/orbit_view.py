"""The 3D orbit view of the model, shown in the view area when there is nothing to put it on.

With a model loaded and no source open it fills the view (the welcome view steps aside); with a
source open and the marker lost it is an inset in the view's lower right corner, so the camera
picture stays visible for aiming at the marker. Drag turns the virtual camera around the model,
the wheel zooms. The pose comes from `arapp.app.orbit` (no Qt); the picture from the overlay
renderer (arapp.render, offscreen GL) made lazily on the UI thread, only while the view is shown.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, QObject, QPointF, QRect, Qt
from PySide6.QtGui import QColor, QImage, QPainter
from PySide6.QtWidgets import QWidget

from arapp.app.orbit import Orbit, camera_from_model, virtual_camera

BACKGROUND_BGR = (46, 40, 40)  # a dark grey-blue, apart from the view's near-black letter-box
MAX_WIDTH = 960                # device pixels rendered at most across: the picture is scaled beyond
INSET_SHARE = 0.34             # the inset's width as a share of the view's


class OrbitView(QWidget):
    """Child of the VideoView drawing `session`'s model from the orbit camera; `placement()` says where."""

    def __init__(self, view, session):
        super().__init__(view)
        self.view, self.session = view, session
        self.orbit = Orbit()
        self.error: str | None = None
        self._renderer = None
        self._size = None
        self._picture: QImage | None = None
        self._dirty = True
        self._last_pos: QPointF | None = None
        self.setToolTip("The model in 3D: drag to turn it, the wheel zooms")
        view.installEventFilter(self)
        self.hide()

    # -- where ---------------------------------------------------------------------------------
    def wanted(self) -> str | None:
        """'full' (a model, no source), 'inset' (a model, a source, no pose on the frame shown) or None."""
        s = self.session
        if s.model is None or s.mesh_lines is None:
            return None
        if s.source_info is None and s.engine is None:
            return "full"
        shown = s.last_shown
        if shown is not None and shown.result.world_from_camera is None:
            return "inset"
        return None

    def place(self) -> None:
        """Show, hide and size the view for the session's state now."""
        mode = self.wanted()
        if mode is None:
            self.hide()
            return
        r = self.view.rect()
        if mode == "full":
            geo = r
        else:
            w = max(160, int(r.width() * INSET_SHARE))
            h = int(w * 3 / 4)
            geo = QRect(r.right() - w - 8, r.bottom() - h - 8, w, h)
        if geo != self.geometry():
            self.setGeometry(geo)
            self._dirty = True
        if not self.isVisible():
            self.show()
            self.raise_()

    def eventFilter(self, obj: QObject, event: QEvent) -> bool:  # noqa: N802
        if obj is self.view and event.type() == QEvent.Type.Resize:
            self.place()
        return False

    def model_changed(self, *_args) -> None:
        self._dirty = True
        self.place()
        self.update()

    # -- picture -------------------------------------------------------------------------------
    def _render(self) -> None:
        ratio = self.devicePixelRatioF()
        w, h = int(self.width() * ratio), int(self.height() * ratio)
        if w > MAX_WIDTH:
            w, h = MAX_WIDTH, max(1, int(h * MAX_WIDTH / w))
        w, h = max(w, 16), max(h, 16)
        from arapp.render import OverlayRenderer, RendererError  # GL only once the view is needed

        try:
            if self._renderer is None or self._size != (w, h):
                if self._renderer is not None:
                    self._renderer.close()
                cam = virtual_camera(w, h)
                self._renderer = OverlayRenderer(cam.K, cam.dist, w, h)
                self._size = (w, h)
            mesh, lines = self.session.mesh_lines
            cam = virtual_camera(w, h)
            cfm = camera_from_model(self.orbit, np.asarray(mesh.vertices), cam)
            mode = self.session.mode
            bg = np.empty((h, w, 3), np.uint8)
            bg[:] = BACKGROUND_BGR
            out = self._renderer.draw(bg, mesh, cfm, mode=mode, lines=lines if mode == "isolines" else None,
                                      color=getattr(self.session.model, "color", None), inplace=True)
        except RendererError as exc:
            self.error = f"No 3D view: {exc}"
            self._picture = None
            return
        self.error = None
        rgb = np.ascontiguousarray(out[:, :, ::-1])
        self._picture = QImage(rgb.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()

    def picture(self) -> QImage | None:
        """The last rendered picture (RGB, device pixels), None before the first paint."""
        return self._picture

    def paintEvent(self, event):  # noqa: N802
        if self._dirty or self._picture is None:
            self._dirty = False
            self._render()
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(*BACKGROUND_BGR[::-1]))
        if self._picture is not None:
            p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, True)
            p.drawImage(self.rect(), self._picture)
        p.setPen(QColor(200, 200, 210))
        text = self.error or ("3D view (no marker in view): drag to turn, wheel to zoom"
                              if self.wanted() == "inset" else "3D view: drag to turn, wheel to zoom")
        p.drawText(self.rect().adjusted(8, 4, -8, -4), Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignBottom
                   | Qt.TextFlag.TextWordWrap, text)
        if self.wanted() == "inset":
            p.setPen(QColor(120, 120, 130))
            p.drawRect(self.rect().adjusted(0, 0, -1, -1))
        p.end()

    # -- pointer -------------------------------------------------------------------------------
    def mousePressEvent(self, event):  # noqa: N802
        self._last_pos = event.position()
        event.accept()

    def mouseMoveEvent(self, event):  # noqa: N802
        if self._last_pos is None:
            return
        d = event.position() - self._last_pos
        self._last_pos = event.position()
        self.orbit = self.orbit.dragged(d.x(), d.y())
        self._dirty = True
        self.update()
        event.accept()

    def mouseReleaseEvent(self, event):  # noqa: N802
        self._last_pos = None
        event.accept()

    def wheelEvent(self, event):  # noqa: N802
        self.orbit = self.orbit.zoomed(event.angleDelta().y() / 120.0)
        self._dirty = True
        self.update()
        event.accept()

    def close_renderer(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def install_orbit(window) -> OrbitView:
    """Add the orbit view to MainWindow `window`'s view, following the session's model and source."""
    s = window.session
    orbit = OrbitView(window.view, s)
    ev = s.events

    def model_loaded(*_args):
        fh = getattr(window, "first_hour", None)
        if s.source_info is None and s.engine is None and fh is not None:
            fh.show_welcome(False)  # a model and nothing to put it on: show it in 3D
        orbit.model_changed()

    ev.model_loaded.connect(model_loaded)
    ev.model_edited.connect(orbit.model_changed)
    ev.mode_changed.connect(orbit.model_changed)
    ev.source_opened.connect(lambda *_a: orbit.place())
    ev.frame.connect(lambda *_a: orbit.place())
    for name in ("source_closed", "source_failed"):
        if hasattr(ev, name):
            getattr(ev, name).connect(lambda *_a: orbit.place())
    window.destroyed.connect(lambda *_a: orbit.close_renderer())
    return orbit
