"""The live view widget: paints the newest composited frame, scaled to fit, and reports the pointer
over it (drag, wheel) as positions within the frame; what a drag means is the main window's business."""

from __future__ import annotations

import math
import time

from PySide6.QtCore import QPoint, QPointF, QRect, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QImage, QPainter, QRegion
from PySide6.QtWidgets import QSizePolicy, QWidget


class VideoView(QWidget):
    """Shows a QImage letter-boxed in the widget; `painted(perf_counter)` is emitted after each new frame is painted.

    Painting a frame is a single scaled blit on the UI thread; every
    per-pixel step (tracking, rendering, compositing, BGR wrapping) happened
    in the workers.
    """

    painted = Signal(float)
    resized = Signal(int, int)  # device pixels available for the frame
    # the pointer over the frame, as fractions (0..1) of its width and height
    drag_started = Signal(float, float, str)   # x, y, mode: "move" (left button) or "turn" (right or Shift)
    drag_moved = Signal(float, float)
    drag_ended = Signal()
    wheel_steps = Signal(float)                # notches, positive away from the user

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumSize(320, 180)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent, True)
        self._image: QImage | None = None
        self._new = False
        self.message = "Open a recording or a camera (File menu), or drop a recording folder here"
        self._dragging = False
        self.setToolTip("Drag the model on the marker to move it; Shift+drag or right-drag turns it; "
                        "the wheel scales it")

    def set_image(self, image: QImage | None) -> None:
        self._image = image
        self._new = image is not None
        if self._new and self.isVisible():
            # paint now, not at the event loop's next turn: a new frame's latency ends when it is on screen
            self.repaint()
        else:
            self.update()

    def image(self) -> QImage | None:
        return self._image

    def resizeEvent(self, event):  # noqa: N802
        super().resizeEvent(event)
        r = self.devicePixelRatioF()
        self.resized.emit(int(self.width() * r), int(self.height() * r))

    def image_rect(self) -> QRectF:
        """Where the frame lands in widget coordinates (aspect kept, centred)."""
        if self._image is None or self._image.width() == 0:
            return QRectF(self.rect())
        r = self._image.devicePixelRatio()
        iw, ih = self._image.width() / r, self._image.height() / r
        s = min(self.width() / iw, self.height() / ih)
        w, h = iw * s, ih * s
        return QRectF((self.width() - w) / 2, (self.height() - h) / 2, w, h)

    def frame_fraction(self, pos: QPointF) -> tuple[float, float] | None:
        """Where widget position `pos` falls in the frame, as fractions of its width and height; None
        off the frame or with no frame shown."""
        if self._image is None:
            return None
        rect = self.image_rect()
        fx = (pos.x() - rect.x()) / rect.width()
        fy = (pos.y() - rect.y()) / rect.height()
        return (fx, fy) if 0.0 <= fx <= 1.0 and 0.0 <= fy <= 1.0 else None

    def mousePressEvent(self, event):  # noqa: N802
        f = self.frame_fraction(event.position())
        if f is None or event.button() not in (Qt.MouseButton.LeftButton, Qt.MouseButton.RightButton):
            return super().mousePressEvent(event)
        turn = (event.button() == Qt.MouseButton.RightButton
                or bool(event.modifiers() & Qt.KeyboardModifier.ShiftModifier))
        self._dragging = True
        self.drag_started.emit(f[0], f[1], "turn" if turn else "move")
        event.accept()

    def mouseMoveEvent(self, event):  # noqa: N802
        if not self._dragging:
            return super().mouseMoveEvent(event)
        rect = self.image_rect()
        # beyond the frame's edge the pointer still steers (fractions outside 0..1)
        self.drag_moved.emit((event.position().x() - rect.x()) / rect.width(),
                             (event.position().y() - rect.y()) / rect.height())
        event.accept()

    def mouseReleaseEvent(self, event):  # noqa: N802
        if not self._dragging:
            return super().mouseReleaseEvent(event)
        self._dragging = False
        self.drag_ended.emit()
        event.accept()

    def wheelEvent(self, event):  # noqa: N802
        if self._image is None:
            return super().wheelEvent(event)
        self.wheel_steps.emit(event.angleDelta().y() / 120.0)
        event.accept()

    def paintEvent(self, event):  # noqa: N802 - Qt's name
        p = QPainter(self)
        if self._image is None:
            p.fillRect(self.rect(), QColor(24, 24, 28))
            p.setPen(QColor(180, 180, 190))
            p.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap, self.message)
            p.end()
            return
        rect = self.image_rect()
        # the bars beside the picture only: filling the whole view under it wrote every pixel twice a frame
        inner = QRect(QPoint(math.ceil(rect.left()), math.ceil(rect.top())),
                      QPoint(math.floor(rect.right()) - 1, math.floor(rect.bottom()) - 1))   # pixels it covers whole
        p.setClipRegion(QRegion(self.rect()).subtracted(QRegion(inner)))
        p.fillRect(self.rect(), QColor(24, 24, 28))
        p.setClipping(False)
        ratio = self.devicePixelRatioF()
        if abs(rect.width() * ratio - self._image.width()) > 1.5:
            # only while the window is being resized: the workers scale frames to the view's size
            p.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, True)
        p.drawImage(rect, self._image)
        p.end()
        if self._new:
            self._new = False
            self.painted.emit(time.perf_counter())
