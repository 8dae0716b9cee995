"""The print dialog's temperature graph: hotend and bed, actual and target, over the last minutes."""

from __future__ import annotations

import time
from collections import deque

from PySide6.QtCore import QPointF, Qt
from PySide6.QtGui import QColor, QPainter, QPen, QPolygonF
from PySide6.QtWidgets import QWidget


class TemperatureGraph(QWidget):
    """Hotend and bed temperatures (actual solid, target dashed) over the last few minutes."""

    SERIES = {"hotend": QColor(230, 90, 40), "bed": QColor(60, 130, 230)}

    def __init__(self, span_s: float = 300.0, parent=None):
        super().__init__(parent)
        self.span_s = span_s
        self.samples: deque = deque(maxlen=2000)  # (t, {name: (actual, target)})
        self.setMinimumHeight(110)

    def add(self, temps: dict, t: float | None = None) -> None:
        """temps: {"hotend": (actual, target), "bed": (actual, target)} in degrees C (missing keys allowed,
        a target may be None)."""
        if not temps:
            return
        t = time.monotonic() if t is None else t
        if self.samples and t - self.samples[-1][0] < 0.5 and self.samples[-1][1] == temps:
            return  # the link reports up to 10 times a second; unchanged readings add nothing
        self.samples.append((t, dict(temps)))
        self.update()

    def clear(self) -> None:
        self.samples.clear()
        self.update()

    def paintEvent(self, event):  # noqa: N802
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(250, 250, 252))
        p.setPen(QColor(200, 200, 205))
        p.drawRect(self.rect().adjusted(0, 0, -1, -1))
        if not self.samples:
            p.setPen(QColor(120, 120, 130))
            p.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "temperatures appear while printing")
            return
        t_end = self.samples[-1][0]
        # the time axis spans the samples so far, up to span_s (a fresh print fills the width)
        span = max(1.0, min(self.span_s, t_end - self.samples[0][0]))
        values = [v for _, d in self.samples for pair in d.values() for v in pair if v is not None]
        top = max(50.0, max(values) * 1.1 if values else 50.0)
        w, h = self.width() - 40, self.height() - 8

        def xy(t, v):
            return QPointF(36 + w * (1 - (t_end - t) / span), 4 + h * (1 - v / top))

        p.setPen(QColor(120, 120, 130))
        p.drawText(2, 14, f"{top:.0f}")
        p.drawText(2, self.height() - 4, "0 °C")
        for name, colour in self.SERIES.items():
            for k, style in ((0, Qt.PenStyle.SolidLine), (1, Qt.PenStyle.DashLine)):
                pts = [xy(t, d[name][k]) for t, d in self.samples
                       if name in d and d[name][k] is not None and t_end - t <= span]
                if len(pts) >= 2:
                    p.setPen(QPen(colour, 1.6, style))
                    p.drawPolyline(QPolygonF(pts))
        last = self.samples[-1][1]
        text = "   ".join(f"{n} {a:.0f}" + (f"/{tg:.0f}" if tg is not None else "") + " °C"
                           for n, (a, tg) in last.items() if a is not None)
        p.setPen(QColor(40, 40, 50))
        p.drawText(40, 16, text)
