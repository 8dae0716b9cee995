"""The welcome view shown before any source is open, and the hint shown over the view when tracking is lost.

Welcome: the bundled recordings (one click replays one with the vase), "Print
a marker sheet", "Open a camera", "Calibrate a camera" and "Open a model";
each is a signal the main window connects. The hint (`LostHint`) says what
the tracker looks for and where to hold it (arapp.app.guidance), after tracking
has been lost for `delay_s` seconds.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QFrame,
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from tracking.default_intrinsics import is_estimated

from arapp.app.guidance import ambiguous_hint, lost_hint

RECORDINGS_DIR = Path(__file__).resolve().parents[3] / "recordings"
# what each bundled recording shows (tracking.synth.presets makes them)
RECORDING_NOTES = {
    "board_orbit": "a marker board seen from an orbit (the demo)",
    "board_orbit_720p": "the same board at 1280x720",
    "marker_occluded": "one marker covered by a hand, then out of view",
    "qr_anchor": "a QR code as the anchor",
    "fast_motion": "fast, blurred pans over the board",
    "static_camera": "a camera on a tripod",
    "printer_bed": "a marker on a printer bed (for the print preview)",
}


def bundled_recordings(folder: Path = RECORDINGS_DIR) -> list[tuple[str, str]]:
    """(folder path, one-line description) of the recordings shipped with arapp, by name."""
    out = []
    if not folder.is_dir():
        return out
    for sub in sorted(p for p in folder.iterdir() if (p / "session.json").is_file()):
        if sub.name.startswith(("test_", "tune_")):
            continue  # the tracker's test and tuning data (recordings/README.md), not examples
        try:
            session = json.loads((sub / "session.json").read_text())
        except (OSError, ValueError):
            continue
        cam = session.get("camera", {})
        kinds = ", ".join(sorted({a.get("kind", "?") for a in session.get("anchors", [])}))
        what = RECORDING_NOTES.get(sub.name, "")
        out.append((str(sub), f"{sub.name}  ({cam.get('width', '?')}x{cam.get('height', '?')}, {kinds})"
                              + (f": {what}" if what else "")))
    return out


class WelcomeView(QWidget):
    """The first thing a new user sees: ways to get a model on a marker within a minute."""

    recording_chosen = Signal(str)
    open_camera_requested = Signal()
    print_sheet_requested = Signal()
    calibrate_requested = Signal()
    open_model_requested = Signal()

    def __init__(self, recordings: list[tuple[str, str]] | None = None, parent=None):
        super().__init__(parent)
        self.setObjectName("welcome")
        lay = QVBoxLayout(self)
        lay.setContentsMargins(24, 18, 24, 18)
        title = QLabel("<h2>Welcome to arapp</h2>See a 3D model on a printed marker, change it, print it.")
        title.setWordWrap(True)
        lay.addWidget(title)

        grid = QGridLayout()
        self.camera_button = QPushButton("Open a camera")
        self.camera_button.setToolTip("A webcam works at once with an estimated calibration; "
                                      "calibrate it later for true sizes")
        self.sheet_button = QPushButton("Print a marker sheet")
        self.sheet_button.setToolTip("The marker the app looks for, at true scale (PDF and PNG)")
        self.calibrate_button = QPushButton("Calibrate a camera")
        self.calibrate_button.setToolTip("Print a ChArUco board, show it to the camera, get exact sizes")
        self.model_button = QPushButton("Open a model")
        steps = ((self.sheet_button, "1. Print the marker the app looks for."),
                 (self.camera_button, "2. Point your webcam at it."),
                 (self.model_button, "3. Choose a model (or one from the Model panel)."),
                 (self.calibrate_button, "Optional: calibrate the camera for true sizes."))
        for row, (button, text) in enumerate(steps):
            button.setMinimumWidth(180)
            grid.addWidget(button, row, 0)
            label = QLabel(text)
            label.setWordWrap(True)
            grid.addWidget(label, row, 1)
        grid.setColumnStretch(1, 1)
        lay.addLayout(grid)
        self.camera_button.clicked.connect(self.open_camera_requested)
        self.sheet_button.clicked.connect(self.print_sheet_requested)
        self.calibrate_button.clicked.connect(self.calibrate_requested)
        self.model_button.clicked.connect(self.open_model_requested)

        line = QFrame()
        line.setFrameShape(QFrame.Shape.HLine)
        lay.addWidget(line)
        lay.addWidget(QLabel("No camera or marker at hand? Replay a bundled recording (double-click):"))
        self.recordings = QListWidget()
        for path, text in (bundled_recordings() if recordings is None else recordings):
            item = QListWidgetItem(text)
            item.setData(Qt.ItemDataRole.UserRole, path)
            self.recordings.addItem(item)
        self.recordings.itemActivated.connect(self._activated)
        self.recordings.itemDoubleClicked.connect(self._activated)
        rows = max(3, min(self.recordings.count(), 10))
        self.recordings.setMaximumHeight(rows * self.recordings.sizeHintForRow(0) + 2 * self.recordings.frameWidth()
                                         if self.recordings.count() else 120)
        lay.addWidget(self.recordings)
        lay.addStretch(1)

    def _activated(self, item: QListWidgetItem) -> None:
        self.recording_chosen.emit(item.data(Qt.ItemDataRole.UserRole))


class LostHint(QLabel):
    """A label showing `arapp.app.guidance.lost_hint` once tracking has been 'lost' for `delay_s` seconds, or
    `ambiguous_hint` ("tilt the camera") while the pose is `ambiguous`; hidden while anything else is tracked.
    `update_state(state, anchors, camera, estimated, ambiguous=...)` per frame shown."""

    def __init__(self, delay_s: float = 1.0, parent=None):
        super().__init__(parent)
        self.delay_s = float(delay_s)
        self.setWordWrap(True)
        self.setObjectName("lost_hint")
        self.setStyleSheet("#lost_hint { background: rgba(0, 0, 0, 170); color: white; padding: 6px; }")
        self._lost_since: float | None = None
        self.hide()

    def update_state(self, state: str, anchors, camera=None, estimated: bool = False,
                     now: float | None = None, ambiguous: bool = False) -> None:
        now = time.monotonic() if now is None else now
        if ambiguous and state != "lost":
            # tracked, but on a head-on marker whose tilt is not yet decided: ask for a tilt at once
            self._lost_since = None
            self.setText(ambiguous_hint())
            self.show()
            return
        if state != "lost":
            self._lost_since = None
            self.hide()
            return
        if self._lost_since is None:
            self._lost_since = now
        if now - self._lost_since >= self.delay_s:
            self.setText(lost_hint(anchors, camera, estimated))
            self.show()


class CalibrationBanner(QFrame):
    """A strip over the view while the camera is the estimated one: "Uncalibrated (estimated) ..." and a
    Calibrate button. `set_camera(camera)` shows or hides it (tracking.default_intrinsics.is_estimated)."""

    calibrate_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("calibration_banner")
        self.setStyleSheet("#calibration_banner { background: #fff3cd; color: #5c4400; }")
        lay = QHBoxLayout(self)
        lay.setContentsMargins(8, 2, 8, 2)
        self.label = QLabel("Uncalibrated camera (estimated): sizes are approximate; calibrate for accuracy")
        self.label.setWordWrap(True)
        self.button = QPushButton("Calibrate...")
        self.button.clicked.connect(self.calibrate_requested)
        lay.addWidget(self.label, 1)
        lay.addWidget(self.button)
        self.hide()

    def set_camera(self, camera) -> None:
        self.setVisible(is_estimated(camera))
