"""Source picker: attached V4L2 and DepthAI cameras (listed in a worker, refreshed on demand),
recordings, videos with calibration, and recent sources."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QDialog,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
)

from arapp.engine import sourcespec
from arapp.gui.tasks import Task
from tracking.sources.images import IMAGE_SUFFIXES



def ask_recording(parent) -> str | None:
    """Ask for a recording folder (or a folder of images, played as frames); None when cancelled."""
    folder = QFileDialog.getExistingDirectory(parent, "Open a recording folder or a folder of images",
                                              str(Path.cwd() / "recordings"))
    return folder or None


def ask_video(parent) -> tuple[str, str | None] | None:
    """Ask for a video (or one image), then its calibration YAML: (video, calibration or None); None when
    cancelled."""
    images = " ".join(f"*{s}" for s in IMAGE_SUFFIXES)
    video, _ = QFileDialog.getOpenFileName(parent, "Open a video or a photo", str(Path.cwd()),
                                           f"Videos (*.mp4 *.mkv *.avi *.mov *.webm);;Images ({images});;All files (*)")
    if not video:
        return None
    calib, _ = QFileDialog.getOpenFileName(parent, "Its camera calibration (OpenCV YAML; Cancel: estimate it)",
                                           str(Path(video).parent),
                                           "Calibration (*.yaml *.yml *.json);;All files (*)")
    return video, calib or None


def ask_video_spec(parent, report) -> str | None:
    """Ask for a video and its calibration: the source spec, or None when cancelled. Without a calibration
    the video opens with a stored or estimated camera (arapp.store.camera_store); `report` is kept for callers."""
    chosen = ask_video(parent)
    if chosen is None:
        return None
    video, calib = chosen
    return sourcespec.video_spec(video, calib)  # no calibration: a stored or estimated one (camera_store)


class SourceDialog(QDialog):
    """Emits source_chosen(spec) and closes when the user picks something."""

    source_chosen = Signal(str)
    devices_listed = Signal(list)

    def __init__(self, recent: list[str], parent=None):
        super().__init__(parent)
        self.setWindowTitle("Open a source")
        self.resize(520, 420)
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Cameras attached to this computer"))
        self.devices = QListWidget()
        self.devices.itemActivated.connect(self._pick)
        self.devices.itemDoubleClicked.connect(self._pick)
        lay.addWidget(self.devices, 1)
        row = QHBoxLayout()
        self.refresh_button = QPushButton("Refresh")
        self.refresh_button.clicked.connect(self.refresh)
        self.open_button = QPushButton("Open camera")
        self.open_button.clicked.connect(lambda: self._pick(self.devices.currentItem()))
        row.addWidget(self.refresh_button)
        row.addWidget(self.open_button)
        row.addStretch(1)
        lay.addLayout(row)
        lay.addWidget(QLabel("Recent"))
        self.recent = QListWidget()
        for spec in recent:
            item = QListWidgetItem(spec)
            item.setData(Qt.ItemDataRole.UserRole, spec)
            self.recent.addItem(item)
        self.recent.itemActivated.connect(self._pick)
        self.recent.itemDoubleClicked.connect(self._pick)
        lay.addWidget(self.recent, 1)
        row2 = QHBoxLayout()
        rec = QPushButton("Recording folder...")
        rec.clicked.connect(self._choose_recording)
        vid = QPushButton("Video or photo + calibration...")
        vid.clicked.connect(self._choose_video)
        close = QPushButton("Close")
        close.clicked.connect(self.reject)
        for b in (rec, vid):
            row2.addWidget(b)
        row2.addStretch(1)
        row2.addWidget(close)
        lay.addLayout(row2)
        self.status = QLabel("")
        self.status.setWordWrap(True)
        lay.addWidget(self.status)
        self._task = None
        self.refresh()

    def refresh(self) -> None:
        """List devices in a worker thread (DepthAI's USB search takes a moment)."""
        if self._task is not None and self._task.running:
            return
        self.status.setText("Looking for cameras...")
        self.refresh_button.setEnabled(False)
        self._task = Task(sourcespec.list_devices, done=self._listed, failed=self._list_failed,
                          name="arapp-list-devices", owner=self).start()

    def _listed(self, devices: list) -> None:
        self.refresh_button.setEnabled(True)
        self.devices.clear()
        for spec, desc in devices:
            item = QListWidgetItem(f"{desc}   [{spec}]")
            item.setData(Qt.ItemDataRole.UserRole, spec)
            self.devices.addItem(item)
        self.status.setText(f"{len(devices)} camera{'s' if len(devices) != 1 else ''} found"
                            if devices else "No V4L2 or DepthAI camera is attached.")
        self.devices_listed.emit(devices)

    def _list_failed(self, exc: BaseException) -> None:
        self.refresh_button.setEnabled(True)
        self.status.setText(f"Cannot list cameras: {exc}")
        self.devices_listed.emit([])

    def _pick(self, item) -> None:
        if item is None:
            return
        self._choose(item.data(Qt.ItemDataRole.UserRole))

    def _choose(self, spec: str) -> None:
        self.source_chosen.emit(spec)
        self.accept()

    def _choose_recording(self) -> None:
        folder = ask_recording(self)
        if folder:
            self._choose(folder)

    def _choose_video(self) -> None:
        chosen = ask_video(self)
        if chosen is None:
            return
        video, calib = chosen
        self._choose(sourcespec.video_spec(video, calib))  # no calibration: a stored or estimated one
