"""Saving what is on screen: a screenshot of the composited view and the AR video (the camera with the model
drawn over it, as shown). No Qt.

The composited frame is the pipeline's `FrameResult.image` (BGR, the source's
full resolution); where an engine hands over only the picture scaled to the
view (`Shown.display`, BGRA), that is used. The AR video is written by
`ArVideoWriter` in a thread of its own behind a bounded queue, so encoding
never slows the processing thread; frames it cannot take in time are dropped
and counted (the video then runs short of frames, not late).
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

import cv2
import numpy as np

VIDEO_CODECS = {".mp4": "mp4v", ".avi": "MJPG"}  # fourcc per container; both ship with OpenCV's own FFmpeg
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")


def composited_image(shown) -> np.ndarray:
    """The composited frame of a `Shown` as BGR uint8: full size when the engine kept it, else the view's."""
    image = getattr(getattr(shown, "result", None), "image", None)
    if isinstance(image, np.ndarray) and image.size:
        return image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    display = np.asarray(shown.display)
    return cv2.cvtColor(display, cv2.COLOR_BGRA2BGR)


def new_capture_path(kind: str, suffix: str, root: str | Path = "captures") -> Path:
    """captures/<kind>-YYYYmmdd-HHMMSS<suffix>, with a counter when that exists already."""
    root = Path(root)
    stamp = time.strftime(f"{kind}-%Y%m%d-%H%M%S")
    path, k = root / f"{stamp}{suffix}", 1
    while path.exists():
        k += 1
        path = root / f"{stamp}-{k}{suffix}"
    return path


def save_screenshot(shown, path) -> Path:
    """Write the composited view of `shown` to `path` (.png, .jpg or .bmp). ValueError (one line) on failure."""
    p = Path(path)
    if p.suffix.lower() not in IMAGE_SUFFIXES:
        raise ValueError(f"{p}: a screenshot is saved as {', '.join(IMAGE_SUFFIXES)}; give one of those suffixes")
    if shown is None:
        raise ValueError("no frame is shown yet: open a source first")
    p.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(p), composited_image(shown)):
        raise ValueError(f"{p}: cannot write the image (is the folder writable?)")
    return p


class ArVideoWriter:
    """The composited frames, written as a video at `fps` (frames per second of the source).

    `write(shown)` is called from the processing thread; frames are encoded in
    this writer's thread. The first frame fixes the size; later frames of
    another size (the source changed) are scaled to it. `close()` finishes the
    file and returns its path; an encoding error is raised there.
    """

    def __init__(self, path, fps: float = 30.0, max_queue: int = 60):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in VIDEO_CODECS:
            raise ValueError(f"{self.path}: the AR video is written as {' or '.join(VIDEO_CODECS)}; "
                             "give one of those suffixes")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fps = float(fps) if fps and fps > 0 else 30.0
        self.fourcc = cv2.VideoWriter_fourcc(*VIDEO_CODECS[suffix])
        self.frames = 0
        self.dropped = 0
        self.error: BaseException | None = None
        self._writer = None
        self._size = None
        self._queue: queue.Queue = queue.Queue(maxsize=max_queue)
        self._thread = threading.Thread(target=self._run, name="arapp-ar-video", daemon=True)
        self._thread.start()

    def write(self, shown) -> None:
        try:
            self._queue.put_nowait(composited_image(shown))
        except queue.Full:
            self.dropped += 1

    def _open(self, image: np.ndarray) -> None:
        h, w = image.shape[:2]
        self._size = (w, h)
        self._writer = cv2.VideoWriter(str(self.path), self.fourcc, self.fps, self._size)
        if not self._writer.isOpened():
            raise OSError(f"{self.path}: OpenCV cannot write this video (codec {VIDEO_CODECS[self.path.suffix.lower()]})")

    def _run(self) -> None:
        while True:
            image = self._queue.get()
            if image is None:
                return
            if self.error is not None:
                continue
            try:
                if self._writer is None:
                    self._open(image)
                if (image.shape[1], image.shape[0]) != self._size:
                    image = cv2.resize(image, self._size, interpolation=cv2.INTER_AREA)
                self._writer.write(np.ascontiguousarray(image))
                self.frames += 1
            except Exception as exc:  # noqa: BLE001 - raised again by close()
                self.error = exc

    def close(self) -> Path:
        self._queue.put(None)
        self._thread.join()
        if self._writer is not None:
            self._writer.release()
        if self.error is not None:
            raise self.error
        if self.frames == 0:
            raise ValueError(f"{self.path}: no frame was shown while recording; nothing was written")
        return self.path
