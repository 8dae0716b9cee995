"""Recording a live source from the app into a new `arapp-recording/1` folder (tracking.recording.writer writes it).

Frames are handed over from the capture thread to a writer thread through a
bounded queue, so encoding never slows capture; if the disk cannot keep up,
frames are dropped and counted rather than stalling the view.
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

from tracking.recording.writer import RecordingWriter


def new_recording_folder(root: str | Path = "recordings") -> Path:
    """recordings/gui-YYYYmmdd-HHMMSS (with a counter when that exists already)."""
    root = Path(root)
    stamp = time.strftime("gui-%Y%m%d-%H%M%S")
    folder = root / stamp
    k = 1
    while folder.exists():
        k += 1
        folder = root / f"{stamp}-{k}"
    return folder


class GuiRecorder:
    """Receives `Captured` frames (capture thread) and writes them in its own thread; `close()` finishes the files."""

    def __init__(self, folder: Path, camera, fps: float, anchors: list, source: dict | None = None,
                 max_queue: int = 90):
        self.folder = Path(folder)
        self.writer = RecordingWriter(self.folder, camera, fps if fps > 0 else 30.0, anchors=anchors,
                                      source=source or {"kind": "gui"})
        self._queue: queue.Queue = queue.Queue(maxsize=max_queue)
        self.dropped = 0
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="arapp-record", daemon=True)
        self._thread.start()

    def write(self, item) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self.error is None:
                try:
                    self.writer.write(item.image, item.t)
                except Exception as exc:  # noqa: BLE001 - reported by close()
                    self.error = exc

    def close(self):
        """Write the rest, finish the video, frames.csv and session.json; return the written Session."""
        self._queue.put(None)
        self._thread.join()
        if self.error is not None:
            raise self.error
        return self.writer.close()


def start(folder: Path, info, source) -> GuiRecorder:
    """Start recording the open live source described by `info` (SourceInfo) into `folder`."""
    kind = type(source).__name__
    return GuiRecorder(folder, info.camera, info.fps, info.anchors, {"kind": "gui", "device": info.name,
                                                                     "class": kind})
