"""Shared scaffolding of the desktop-app tests: the synthetic arc recording and the main window.

The arc: a slow orbit around one 80 mm ArUco marker at ~0.35 m, written by
tracking.recording.writer with the true camera poses (world_from_camera) next to the frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings

ANCHORS = [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.08}]
N_FRAMES = 24
TIMEOUT_MS = 30000


def camera_poses(n: int) -> list[np.ndarray]:
    """A slow arc around the marker at ~0.35 m, looking at its centre (world_from_camera)."""
    from tracking.anchors.render import look_at

    return [look_at([0.22 * np.cos(a), 0.22 * np.sin(a), 0.28], [0.0, 0.0, 0.0])
            for a in (0.3 + 0.5 * i / max(n - 1, 1) for i in range(n))]


def write_arc_recording(folder: Path, n: int = N_FRAMES) -> Path:
    """Write the arc (n frames at 30 fps, 640x480, K known) to folder and return it."""
    from tracking.anchors.render import render_view
    from tracking.camera import Camera
    from tracking.recording.writer import RecordingWriter
    from tracking.recording.schema import parse_anchors

    cam = Camera(np.array([[560.0, 0, 322.5], [0, 560.0, 236.5], [0, 0, 1]]), np.zeros(5), 640, 480)
    anchors = parse_anchors(ANCHORS)
    with RecordingWriter(folder, cam, 30.0, anchors=ANCHORS, source={"kind": "synthetic"}) as w:
        for i, pose in enumerate(camera_poses(n)):
            w.write(render_view(anchors, cam, pose, bgr=True), i / 30.0, pose)
    return folder


def open_main_window(qtbot, tmp_path: Path):
    """A shown MainWindow with its settings in tmp_path (not the user's), registered with qtbot."""
    from arapp.gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat))
    qtbot.addWidget(w)
    return w


def close_main_window(w) -> None:
    """Close the error boxes a test left open, then the window."""
    for box in w.open_error_boxes():
        box.close()
    w.close()


def grab_rgb(widget) -> np.ndarray:
    """The widget as painted (overlay children included), RGB uint8 (H,W,3), widget pixels."""
    img = widget.grab().toImage()
    img = img.convertToFormat(img.Format.Format_RGB888)
    w, h = img.width(), img.height()
    return np.frombuffer(img.constBits(), np.uint8).reshape(h, img.bytesPerLine())[:, : w * 3].reshape(h, w, 3).copy()
