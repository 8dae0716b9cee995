"""The print dialog's temperature graph: hotend and bed, actual (solid) and target (dashed), in degrees C,
over the last minutes, with a time axis (seconds or minutes before now)."""

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
        self.setMinimumHeight(130)

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

    LEFT, TOP, RIGHT, BOTTOM = 40, 20, 8, 18  # margins (px): °C axis, reading line, -, time axis

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
        x0, y0 = self.LEFT, self.TOP
        w, h = self.width() - self.LEFT - self.RIGHT, self.height() - self.TOP - self.BOTTOM

        def xy(t, v):
            return QPointF(x0 + w * (1 - (t_end - t) / span), y0 + h * (1 - v / top))

        # axes: degrees on the left, time before now along the bottom
        grid, label = QColor(225, 225, 230), QColor(110, 110, 120)
        p.setPen(grid)
        p.drawRect(x0, y0, w, h)
        p.setPen(label)
        p.drawText(2, y0 + 10, f"{top:.0f} °C")
        p.drawText(2, y0 + h, "0 °C")
        for t_back, text in time_ticks(span):
            x = x0 + w * (1 - t_back / span)
            p.setPen(grid)
            p.drawLine(QPointF(x, y0), QPointF(x, y0 + h))
            p.setPen(label)
            fm = p.fontMetrics()
            tw = fm.horizontalAdvance(text)
            p.drawText(int(min(max(x - tw / 2, x0), x0 + w - tw)), self.height() - 4, text)
        for name, colour in self.SERIES.items():
            for k, style in ((0, Qt.PenStyle.SolidLine), (1, Qt.PenStyle.DashLine)):
                pts = [xy(t, d[name][k]) for t, d in self.samples
                       if name in d and d[name][k] is not None and t_end - t <= span]
                if len(pts) >= 2:
                    p.setPen(QPen(colour, 1.6, style))
                    p.drawPolyline(QPolygonF(pts))
        # the readings above the plot, in each series' colour: never over a line
        x = x0
        for n, (a, tg) in self.samples[-1][1].items():
            if a is None:
                continue
            text = f"{n} {a:.0f}" + (f" / {tg:.0f}" if tg is not None else "") + " °C   "
            p.setPen(self.SERIES.get(n, QColor(40, 40, 50)))
            p.drawText(x, 14, text)
            x += p.fontMetrics().horizontalAdvance(text)


def time_ticks(span_s: float) -> list[tuple[float, str]]:
    """Ticks of the time axis: (seconds before now, label), 'now' at the right edge, 3 to 6 in all."""
    step = next(s for s in (10, 15, 30, 60, 120, 300, 600, 1800, 3600) if span_s / s <= 5)
    ticks = [(0.0, "now")]
    k = 1
    while k * step <= span_s + 1e-9:
        t = k * step
        ticks.append((float(t), f"-{t // 60:.0f} min" if t % 60 == 0 else f"-{t:.0f} s"))
        k += 1
    return ticks
