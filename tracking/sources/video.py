"""Plain video files (spec `file:VIDEO` or a path to a video): frames at the container's own timestamps (a
phone's variable frame rate kept), from 0 at the first frame."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator

import cv2

from tracking.camera import Camera

from .base import Frame, Source, _as_bgr, _calibrated, _open_capture, _probe_first_frame


class VideoFileSource(Source):
    """A plain video file (mp4, avi, mov, webm, mkv: whatever OpenCV's FFmpeg decodes); timestamps the
    container's (seconds from the first frame; frame / fps where it has none, or when `fps` is given: a rate
    the user sets). With `calibration` (a file tracking.calibration_file reads, or a Camera) it has a camera
    (scaled to the video size if the calibration was made at another size of the same aspect; a file
    without an image size is taken at the video's, noted in `notes`)."""

    kind = "file"

    def __init__(self, path: str | Path, calibration: str | Path | Camera | None = None, fps: float | None = None):
        super().__init__()
        self.path = Path(path)
        self._cap = _open_capture(self.path)
        first = _probe_first_frame(self._cap, self.path)
        self.height, self.width = first.shape[:2]
        self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
        probed = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps or (probed if probed and 0 < probed < 1000 else 30.0))
        self._own_times = fps is None   # the container's timestamps unless a rate is given
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count = n if n > 0 else None
        # quarter turns clockwise OpenCV gives the stored frames (a phone's rotation tag: 90 clockwise, 270 back)
        self.turns = int(round(self._cap.get(cv2.CAP_PROP_ORIENTATION_META) or 0) // 90) % 4
        if calibration is not None:
            self._camera, self.notes = _calibrated(calibration, self.width, self.height, str(self.path), self.turns)
        self.info = {"kind": "file", "path": str(self.path)}

    def describe(self) -> str:
        return f"video {self.path}"

    def _frames(self) -> Iterator[Frame]:
        i, first, t = 0, None, -1.0
        while not self.closed:
            ok, img = self._cap.read()
            if not ok or img is None:
                if self.frame_count and i < self.frame_count:
                    self._fail(f"{self.path}: decoding stopped at frame {i} of {self.frame_count} "
                               f"(truncated or corrupt file); {self._delivered(i)}")
                return
            if not self._own_times:
                t = i / self.fps
            else:
                stamp = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
                if first is None and math.isfinite(stamp):   # (an edit list may start it below 0)
                    first = stamp
                own = stamp - first if first is not None else float("nan")
                # the container's time when it has one that goes forward, else one frame period on
                t = own if own > t else (0.0 if i == 0 else t + 1.0 / self.fps)
            yield Frame(i, t, _as_bgr(img))
            i += 1

    def _release(self) -> None:
        self._cap.release()

