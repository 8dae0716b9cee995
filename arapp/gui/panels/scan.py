"""Scan mode in the window: the Scan panel (start, coverage, Reconstruct with progress and Cancel, use the
result as the model) and the dome of view directions painted over the live view.

The state and rules live in arapp.app.scan_session.ScanSession (no Qt). The
dome is drawn here with QPainter over the shown frame, not into the frame:
the composited frame is made in the engine (a child process by default), the
dome changes with every capture and needs no depth test against the model,
and the projection (ScanSession.dome_drawing, Camera.project) gives frame
pixels that only need the view's letter-box mapping. The frame and the dome
come from the same processed frame's pose, so they stay together.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, QPointF, Qt
from PySide6.QtGui import QBrush, QColor, QFont, QPainter, QPen, QPolygonF
from PySide6.QtWidgets import (
    QDockWidget,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from arapp.app.scan_session import ScanSession

STAGES = {"tracking": "Placing the views", "refining poses": "Refining the poses",
          "dense matching": "Matching depth", "depth maps": "Depth maps", "fusing": "Fusing the surface"}


class DomeOverlay(QWidget):
    """Transparent child of the VideoView painting the scan dome, the move-here arrow and the hint text."""

    def __init__(self, view, scan: ScanSession):
        super().__init__(view)
        self.view, self.scan = view, scan
        self.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents, True)
        self.setAttribute(Qt.WidgetAttribute.WA_NoSystemBackground, True)
        self.setGeometry(view.rect())
        view.installEventFilter(self)
        self.hide()

    def eventFilter(self, obj: QObject, event: QEvent) -> bool:  # noqa: N802
        if obj is self.view and event.type() == QEvent.Type.Resize:
            self.setGeometry(self.view.rect())
        return False

    def paintEvent(self, event):  # noqa: N802
        scan = self.scan
        if scan.state != "scanning" or self.view.image() is None or scan.camera is None:
            return
        drawing = scan.dome_drawing()
        if drawing is None:
            return
        rect = self.view.image_rect()
        sx, sy = rect.width() / scan.camera.width, rect.height() / scan.camera.height

        def pt(uv):  # frame pixel (centres at integers) -> widget point
            return QPointF(rect.x() + (uv[0] + 0.5) * sx, rect.y() + (uv[1] + 0.5) * sy)

        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, True)
        p.setClipRect(rect)
        # the far side first, faint, then the near side over it
        for near in (False, True):
            for poly, covered, facing in zip(drawing.polygons, drawing.covered, drawing.facing):
                if poly is None or facing != near:
                    continue
                q = QPolygonF([pt(uv) for uv in poly])
                p.setPen(QPen(QColor(255, 255, 255, 170 if near else 60), 1.2 if near else 0.8))
                fill = QColor(40, 200, 90, 120 if near else 45)
                p.setBrush(QBrush(fill) if covered else Qt.BrushStyle.NoBrush)
                p.drawPolygon(q)
        if drawing.arrow is not None:
            a, b = pt(drawing.arrow[0]), pt(drawing.arrow[1])
            p.setPen(QPen(QColor(255, 210, 0), 4.0, Qt.PenStyle.SolidLine, Qt.PenCapStyle.RoundCap))
            p.drawLine(a, b)
            d = b - a
            n = max(1e-6, (d.x() ** 2 + d.y() ** 2) ** 0.5)
            u = QPointF(d.x() / n, d.y() / n)
            w = QPointF(-u.y(), u.x())
            p.setBrush(QColor(255, 210, 0))
            p.drawPolygon(QPolygonF([b, b - u * 16 + w * 8, b - u * 16 - w * 8]))
        text = f"{scan.coverage * 100:.0f} % covered, {len(scan.views)} views - {drawing.text}"
        f = QFont(self.font())
        f.setPointSizeF(f.pointSizeF() * 1.2)
        f.setBold(True)
        p.setFont(f)
        box = rect.adjusted(10, 10, -10, -10)
        p.setPen(QColor(0, 0, 0, 200))
        p.drawText(box.translated(1, 1), Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignHCenter, text)
        p.setPen(QColor(255, 230, 80))
        p.drawText(box, Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignHCenter, text)
        p.end()


class ScanPanel(QWidget):
    """Start or stop scanning, coverage, Reconstruct / Cancel with progress, and Use as model. `start()`
    begins scanning (default ScanSession.start; the window's also makes sure frames come as captured)."""

    def __init__(self, scan: ScanSession, start=None, parent=None):
        super().__init__(parent)
        self.scan = scan
        self._start = start or scan.start
        lay = QVBoxLayout(self)
        self.intro = QLabel("Stand the object on the marker board and circle it slowly, low and high, "
                            "until the dome is filled; then Reconstruct.")
        self.intro.setWordWrap(True)
        self.start_button = QPushButton("Start scan")
        self.coverage_bar = QProgressBar()
        self.coverage_bar.setRange(0, 100)
        self.coverage_bar.setFormat("%p % of directions covered")
        self.views_label = QLabel("")
        self.reconstruct_button = QPushButton("Reconstruct")
        self.cancel_button = QPushButton("Cancel")
        row = QHBoxLayout()
        row.addWidget(self.reconstruct_button)
        row.addWidget(self.cancel_button)
        self.stage_label = QLabel("")
        self.progress_bar = QProgressBar()
        self.progress_bar.setRange(0, 100)
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.use_button = QPushButton("Use as model")
        for w in (self.intro, self.start_button, self.coverage_bar, self.views_label):
            lay.addWidget(w)
        lay.addLayout(row)
        for w in (self.stage_label, self.progress_bar, self.result_label, self.use_button):
            lay.addWidget(w)
        lay.addStretch(1)
        self.start_button.clicked.connect(self.toggle_scan)
        self.reconstruct_button.clicked.connect(scan.reconstruct)
        self.cancel_button.clicked.connect(scan.cancel)
        self.use_button.clicked.connect(scan.finish)
        scan.events.changed.connect(self.refresh)
        scan.events.progress.connect(self._progress)
        scan.events.finished.connect(self._finished)
        self.refresh()

    def toggle_scan(self) -> None:
        self.scan.stop() if self.scan.state != "idle" else self._start()

    def refresh(self) -> None:
        s = self.scan
        self.start_button.setText("Start scan" if s.state == "idle" else "Stop scan")
        self.coverage_bar.setValue(int(round(s.coverage * 100)))
        self.views_label.setText(f"{len(s.views)} views captured" if s.state != "idle" else "")
        self.reconstruct_button.setEnabled(s.state in ("scanning", "done") and len(s.views) >= 3)
        self.cancel_button.setEnabled(s.state == "reconstructing")
        self.progress_bar.setVisible(s.state == "reconstructing")
        self.stage_label.setVisible(s.state == "reconstructing")
        self.use_button.setEnabled(s.state == "done")
        if s.state != "done":
            self.result_label.setText("")

    def _progress(self, stage: str, done: int, total: int) -> None:
        self.stage_label.setText(STAGES.get(stage, stage.capitalize()) + f" ({done}/{total})" if total else stage)
        self.progress_bar.setValue(int(100 * done / total) if total else 0)

    def _finished(self, model, stats: dict) -> None:
        self.result_label.setText(
            f"Reconstructed from {stats.get('views', '?')} of {stats.get('views_captured', '?')} views in "
            f"{stats.get('seconds', 0):.0f} s; shown over the object (where it differs, views are missing). "
            f"Saved as {stats.get('path', '')}.")


def install_scan(window) -> ScanSession:
    """Add scan mode to MainWindow `window`: a ScanSession over its session, the Scan dock (tabbed with the
    Tracking dock) and the dome over its view. Scanning needs the frames as captured: a process engine
    that does not send them is reopened with full frames first."""
    scan = ScanSession(window.session)
    window.scan_session = scan

    def start():
        s = window.session
        shown = s.last_shown
        if s.source_spec and not window.full_frames and (shown is None or shown.frame is None):
            window.full_frames = True  # the engine must hand over frames as captured

            def reopened(_info):
                s.events.source_opened.disconnect(reopened)
                scan.start()
            s.events.source_opened.connect(reopened)
            window.open_source(s.source_spec)
            return
        scan.start()

    window.scan_panel = panel = ScanPanel(scan, start)
    dock = QDockWidget("Scan", window)
    dock.setObjectName("dock_scan")
    dock.setWidget(panel)
    dock.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable
                     | QDockWidget.DockWidgetFeature.DockWidgetFloatable)
    window.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
    tracking = window.findChild(QDockWidget, "dock_tracking")
    if tracking is not None:
        window.tabifyDockWidget(tracking, dock)
        tracking.raise_()  # the Tracking tab shows until the user picks Scan
    window.scan_dock = dock
    overlay = DomeOverlay(window.view, scan)
    window.scan_overlay = overlay

    def changed():
        overlay.setVisible(scan.state == "scanning")
        overlay.update()

    scan.events.changed.connect(changed)
    window.session.events.frame.connect(lambda _shown: overlay.update() if scan.scanning else None)
    return scan
