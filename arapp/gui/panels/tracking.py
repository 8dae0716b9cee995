"""Tracking panel: state, anchors seen, inliers, fps, latency; reset; the anchors in use and their editor."""

from __future__ import annotations

import json
import time

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QPlainTextEdit,
    QPushButton,
    QTreeWidget,
    QTreeWidgetItem,
    QVBoxLayout,
    QWidget,
)

from tracking.recording.schema import parse_anchors

STATE_STYLE = {"marker": "color: #2a2; font-weight: bold", "slam": "color: #29c; font-weight: bold",
               "lost": "color: #c33; font-weight: bold"}


def anchor_summary(anchor) -> tuple[str, str, str, str]:
    """(kind, dictionary, ids, size) strings for one AnchorSpec, sizes in millimetres (the kind's own words,
    tracking.anchors.kinds)."""
    ids, size = anchor.anchor_kind.summary(anchor)
    return anchor.kind, anchor.dictionary or "", ids, size


class TrackingPanel(QWidget):
    """Shows what the tracker reports for the newest painted frame."""

    reset_requested = Signal()
    edit_anchors_requested = Signal()
    marker_sheets_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.state = QLabel("-")
        self.markers = QLabel("-")
        self.inliers = QLabel("-")
        self.fps = QLabel("-")
        self.latency = QLabel("-")
        self.timing = QLabel("-")
        self.dropped = QLabel("-")
        form.addRow("State", self.state)
        form.addRow("Anchors seen", self.markers)
        form.addRow("Map points matched", self.inliers)
        form.addRow("Frame rate", self.fps)
        form.addRow("Latency", self.latency)
        form.addRow("Time per frame", self.timing)
        form.addRow("Frames skipped", self.dropped)
        self._dropped_marks: list[tuple[float, int]] = []  # (monotonic s, cumulative skipped) for a recent rate
        lay.addLayout(form)
        self.reset_button = QPushButton("Reset tracking (R)")
        self.reset_button.clicked.connect(self.reset_requested)
        lay.addWidget(self.reset_button)
        lay.addWidget(QLabel("Anchors (the first defines the world)"))
        self.anchor_tree = QTreeWidget()
        self.anchor_tree.setHeaderLabels(["Kind", "Dictionary", "Ids", "Size"])
        self.anchor_tree.setRootIsDecorated(False)
        self.anchor_tree.setMaximumHeight(120)
        lay.addWidget(self.anchor_tree)
        row = QHBoxLayout()
        self.edit_anchors = QPushButton("Edit anchors...")
        self.edit_anchors.setToolTip("Anchors for live cameras and plain videos (recordings bring their own)")
        self.edit_anchors.clicked.connect(self.edit_anchors_requested)
        self.sheets = QPushButton("Marker sheets...")
        self.sheets.setToolTip("Save printable sheets of these anchors at true size")
        self.sheets.clicked.connect(self.marker_sheets_requested)
        row.addWidget(self.edit_anchors)
        row.addWidget(self.sheets)
        lay.addLayout(row)
        lay.addStretch(1)

    def set_anchors(self, anchors: list) -> None:
        self.anchor_tree.clear()
        for a in anchors:
            self.anchor_tree.addTopLevelItem(QTreeWidgetItem(list(anchor_summary(a))))
        for i in range(4):
            self.anchor_tree.resizeColumnToContents(i)

    def clear_stats(self) -> None:
        """Back to "-" everywhere: nothing is being tracked (a source opening, or none)."""
        for label in (self.state, self.markers, self.inliers, self.fps, self.latency, self.timing, self.dropped):
            label.setText("-")
        self.state.setStyleSheet("")
        self._dropped_marks.clear()

    def update_stats(self, result, fps: float, latency_ms: float, dropped: int) -> None:
        """result: the pipeline's FrameResult of the frame just painted."""
        self.state.setText(result.state)
        style = STATE_STYLE.get(result.state, "")
        if style != self.state.styleSheet():
            # setting a style sheet re-polishes the label and lays the panel out again (milliseconds on the UI
            # thread), even when it is the same one: only when the state changes
            self.state.setStyleSheet(style)
        self.markers.setText(str(result.markers))
        self.inliers.setText(str(result.inliers))
        self.fps.setText(f"{fps:.1f} fps")
        self.latency.setText(f"{latency_ms:.0f} ms (capture to paint)")
        self.timing.setText(f"tracking {result.ms_track:.1f} ms, drawing {result.ms_render:.1f} ms")
        self.dropped.setText(skipped_text(self._dropped_marks, dropped, time.monotonic()))


SKIP_WINDOW_S = 10.0


def skipped_text(marks: list, cumulative: int, now: float) -> str:
    """'2 in the last 10 s' from the running total of frames skipped (kept in `marks`, trimmed here): the
    recent count says whether the machine keeps up now, which a total since opening does not."""
    marks.append((now, int(cumulative)))
    while len(marks) > 1 and marks[0][0] < now - SKIP_WINDOW_S:
        marks.pop(0)
    recent = max(0, int(cumulative) - marks[0][1])
    return f"{recent} in the last {SKIP_WINDOW_S:.0f} s" if recent else "none lately"


class AnchorsDialog(QDialog):
    """Edits the anchors list as session.json writes it (JSON), validated by tracking.recording.schema.parse_anchors."""

    def __init__(self, anchors_json: list, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Anchors")
        self.resize(520, 420)
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Anchors as in session.json: lengths in metres there (0.05 is 50 mm; see "
                             "docs/recording-format.md). Used for live cameras and videos without a session."))
        self.text = QPlainTextEdit(json.dumps(anchors_json, indent=2))
        lay.addWidget(self.text, 1)
        self.in_mm = QLabel("")  # what the text means, in millimetres, as it is typed
        self.in_mm.setWordWrap(True)
        lay.addWidget(self.in_mm)
        self.text.textChanged.connect(self._describe)
        self.problem = QLabel("")
        self.problem.setStyleSheet("color: #c33")
        self.problem.setWordWrap(True)
        lay.addWidget(self.problem)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self._accept)
        buttons.rejected.connect(self.reject)
        lay.addWidget(buttons)
        self.anchors_json = anchors_json
        self._describe()

    def _describe(self) -> None:
        try:
            anchors = parse_anchors(json.loads(self.text.toPlainText()))
        except (ValueError, TypeError, KeyError):
            self.in_mm.setText("")
            return
        self.in_mm.setText("In millimetres: " + "; ".join(a.anchor_kind.describe(a) for a in anchors))

    def _accept(self) -> None:
        try:
            data = json.loads(self.text.toPlainText())
            parse_anchors(data)
        except (ValueError, TypeError, KeyError) as exc:
            self.problem.setText(str(exc))
            return
        self.anchors_json = data
        self.accept()
