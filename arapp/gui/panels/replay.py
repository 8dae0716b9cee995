"""Replay controls (play/pause, step, seek slider with time, speed, loop) and the record button for live sources."""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QLabel, QPushButton, QSlider, QWidget

SPEEDS = (0.25, 0.5, 1.0, 1.5, 2.0, 4.0)


def format_time(seconds: float) -> str:
    """m:ss.s for the time label."""
    seconds = max(0.0, float(seconds))
    m, s = divmod(seconds, 60.0)
    return f"{int(m)}:{s:04.1f}"


class ReplayBar(QWidget):
    """A row of replay controls. Emits intents; the window forwards them to the capture thread.

    The slider follows the shown frame unless the user is dragging it; a
    release (or a click on the groove) seeks.
    """

    play_toggled = Signal()
    step_requested = Signal()
    seek_requested = Signal(int)
    speed_changed = Signal(float)
    loop_changed = Signal(bool)
    record_toggled = Signal(bool)

    def __init__(self, parent=None):
        super().__init__(parent)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(6, 2, 6, 2)
        self.play_button = QPushButton("Play")
        self.play_button.setToolTip("Play / pause (Space)")
        self.play_button.clicked.connect(self.play_toggled)
        self.step_button = QPushButton("Step")
        self.step_button.setToolTip("Pause and show the next frame")
        self.step_button.clicked.connect(self.step_requested)
        self.slider = QSlider(Qt.Orientation.Horizontal)
        self.slider.setRange(0, 0)
        self.slider.sliderReleased.connect(lambda: self.seek_requested.emit(self.slider.value()))
        self.slider.actionTriggered.connect(self._slider_action)
        self.time_label = QLabel("0:00.0 / 0:00.0")
        self.time_label.setMinimumWidth(130)
        self.speed = QComboBox()
        for s in SPEEDS:
            self.speed.addItem(f"{s:g}x", s)
        self.speed.setCurrentIndex(SPEEDS.index(1.0))
        self.speed.setToolTip("Replay speed")
        self.speed.currentIndexChanged.connect(lambda i: self.speed_changed.emit(float(self.speed.itemData(i))))
        self.loop = QCheckBox("Loop")
        self.loop.toggled.connect(self.loop_changed)
        self.record_button = QPushButton("Record")
        self.record_button.setCheckable(True)
        self.record_button.setToolTip("Record the live camera to a new recording (with calibration and anchors)")
        self.record_button.toggled.connect(self.record_toggled)
        for w in (self.play_button, self.step_button):
            lay.addWidget(w)
        lay.addWidget(self.slider, 1)
        for w in (self.time_label, self.speed, self.loop, self.record_button):
            lay.addWidget(w)
        self._fps = 30.0
        self.set_source(seekable=False, frame_count=0, fps=30.0)

    def _slider_action(self, action: int) -> None:
        # Clicks on the groove and keyboard steps seek at once; drags seek on release.
        if not self.slider.isSliderDown():
            self.seek_requested.emit(self.slider.sliderPosition())

    def set_source(self, *, seekable: bool, frame_count: int, fps: float) -> None:
        """Adapt to a recording (seek, speed, loop) or a live camera (record)."""
        self._fps = fps if fps > 0 else 30.0
        self.slider.setRange(0, max(0, frame_count - 1))
        for w in (self.step_button, self.slider, self.speed, self.loop):
            w.setEnabled(seekable)
        self.record_button.setEnabled(not seekable and frame_count == 0)
        self.record_button.setVisible(not seekable)
        self._total = frame_count / self._fps if frame_count else 0.0
        self.set_position(0, 0.0)

    def set_playing(self, playing: bool) -> None:
        self.play_button.setText("Pause" if playing else "Play")

    def set_position(self, index: int, t: float) -> None:
        if not self.slider.isSliderDown():
            self.slider.blockSignals(True)
            self.slider.setValue(index)
            self.slider.blockSignals(False)
        # a source with no known length (a plain video read straight through, a camera) shows the time only
        self.time_label.setText(f"{format_time(t)} / {format_time(self._total)}" if self._total else format_time(t))
