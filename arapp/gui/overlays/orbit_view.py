"""The 3D orbit view of the model, shown in the view area when there is nothing to put it on.

With a model loaded and no source open it fills the view (the welcome view steps aside); with a
source open and the marker lost it is an inset in the view's lower right corner, so the camera
picture stays visible for aiming at the marker. Drag turns the virtual camera around the model,
the wheel zooms. The pose comes from `arapp.app.orbit` (no Qt); the picture from the overlay
renderer (arapp.render, offscreen GL) on the view's own render thread, made when the view is first shown:
making a GL context and its shaders takes tens of milliseconds and each picture a few, which on the UI
thread would stall the live view (the UI-block goal of issue 29 is under 10 ms). A marker lost for a
moment does not flash the inset: it shows once the pose has been missing for LOST_DELAY_S.
"""

from __future__ import annotations

import threading
import time

import numpy as np
from PySide6.QtCore import QEvent, QObject, QPointF, QRect, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QImage, QPainter
from PySide6.QtWidgets import QWidget

from arapp.app.orbit import Orbit, camera_from_model, virtual_camera

BACKGROUND_BGR = (46, 40, 40)  # a dark grey-blue, apart from the view's near-black letter-box
MAX_WIDTH = 960                # device pixels rendered at most across: the picture is scaled beyond
INSET_SHARE = 0.34             # the inset's width as a share of the view's
LOST_DELAY_S = 0.5             # the pose missing this long (seconds) before the inset shows


class OrbitRenderThread(threading.Thread):
    """The orbit view's render thread: it owns the overlay renderer and its GL context (a context belongs
    to the thread that made it). `request(spec)` asks for a picture, the newest request wins;
    `done(image, error)` is called on this thread with the RGB QImage (or None and the error's text)."""

    def __init__(self, done):
        super().__init__(name="arapp-orbit-render", daemon=True)
        self._done = done
        self._cond = threading.Condition()
        self._spec: dict | None = None
        self._stopping = False
        self._renderer = None
        self._size = None

    def request(self, spec: dict) -> None:
        """spec: width, height (device pixels), mesh, lines, camera_from_model (4x4), mode, color."""
        with self._cond:
            self._spec = spec
            self._cond.notify()

    def stop(self, timeout: float = 2.0) -> None:
        with self._cond:
            self._stopping = True
            self._cond.notify()
        if self.is_alive() and self is not threading.current_thread():
            self.join(timeout)

    def run(self) -> None:
        try:
            while True:
                with self._cond:
                    self._cond.wait_for(lambda: self._stopping or self._spec is not None)
                    if self._stopping:
                        return
                    spec, self._spec = self._spec, None
                try:
                    self._done(*self._draw(spec))
                except RuntimeError:  # the view was deleted while this picture was drawn: no one to show it
                    return
        finally:
            if self._renderer is not None:
                self._renderer.close()

    def _draw(self, spec: dict):
        from arapp.render import OverlayRenderer, RendererError  # GL only once the view is needed

        w, h = spec["width"], spec["height"]
        try:
            if self._renderer is None or self._size != (w, h):
                if self._renderer is not None:
                    self._renderer.close()
                cam = virtual_camera(w, h)
                self._renderer = OverlayRenderer(cam.K, cam.dist, w, h)
                self._size = (w, h)
            mode = spec["mode"]
            bg = np.empty((h, w, 3), np.uint8)
            bg[:] = BACKGROUND_BGR
            out = self._renderer.draw(bg, spec["mesh"], spec["camera_from_model"], mode=mode,
                                      lines=spec["lines"] if mode == "isolines" else None, color=spec["color"],
                                      inplace=True)
        except RendererError as exc:
            return None, f"No 3D view: {exc}"
        rgb = np.ascontiguousarray(out[:, :, ::-1])
        return QImage(rgb.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy(), None


class OrbitView(QWidget):
    """Child of the VideoView drawing `session`'s model from the orbit camera; `place()` says where."""

    _rendered = Signal(object, object)  # (QImage or None, error or None), from the render thread

    def __init__(self, view, session):
        super().__init__(view)
        self.view, self.session = view, session
        self.orbit = Orbit()
        self.error: str | None = None
        self._thread: OrbitRenderThread | None = None
        self._picture: QImage | None = None
        self._dirty = True
        self._last_pos: QPointF | None = None
        self._lost_since: float | None = None  # time.monotonic() when the shown frames lost their pose
        self._lost_timer = QTimer(self)  # shows the inset when the pose stays missing, frames or not
        self._lost_timer.setSingleShot(True)
        self._lost_timer.timeout.connect(self.place)
        self._rendered.connect(self._picture_done)  # queued: emitted on the render thread
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
        return "inset" if self._lost_long_enough() else None

    def _lost_long_enough(self) -> bool:
        """The frame shown has no pose, and the frames before it had none for LOST_DELAY_S."""
        shown = self.session.last_shown
        if shown is None or shown.result.world_from_camera is not None:
            self._lost_since = None
            self._lost_timer.stop()
            return False
        now = time.monotonic()
        if self._lost_since is None:
            self._lost_since = now
            self._lost_timer.start(int(LOST_DELAY_S * 1000) + 20)
        return now - self._lost_since >= LOST_DELAY_S

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
    def _request_picture(self) -> None:
        """Ask the render thread for the picture at the view's size (device pixels, at most MAX_WIDTH)."""
        ratio = self.devicePixelRatioF()
        w, h = int(self.width() * ratio), int(self.height() * ratio)
        if w > MAX_WIDTH:
            w, h = MAX_WIDTH, max(1, int(h * MAX_WIDTH / w))
        w, h = max(w, 16), max(h, 16)
        mesh, lines = self.session.mesh_lines
        cfm = camera_from_model(self.orbit, np.asarray(mesh.vertices), virtual_camera(w, h))
        if self._thread is None:
            self._thread = OrbitRenderThread(self._rendered.emit)
            self._thread.start()
        self._thread.request({"width": w, "height": h, "mesh": mesh, "lines": lines, "camera_from_model": cfm,
                              "mode": self.session.mode, "color": getattr(self.session.model, "color", None)})

    def _picture_done(self, image: QImage | None, error: str | None) -> None:
        self._picture, self.error = image, error
        self.update()

    def picture(self) -> QImage | None:
        """The last rendered picture (RGB, device pixels), None before the first paint."""
        return self._picture

    def paintEvent(self, event):  # noqa: N802
        if self._dirty and self.session.mesh_lines is not None:
            self._dirty = False
            self._request_picture()  # painted when it comes (_picture_done); the last one meanwhile
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
        """End the render thread (its GL context goes with it)."""
        if self._thread is not None:
            self._thread.stop()
            self._thread = None


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
