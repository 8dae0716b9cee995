"""Plain video files (spec `file:VIDEO` or a path to a video): frames at the container's own timestamps (a
phone's variable frame rate kept), from 0 at the first frame; seekable by frame (or by time, at the mean rate)
when the container gives its frame count."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator

import cv2

from tracking.camera import Camera
from tracking.errors import SourceError

from .base import Frame, Source, _as_bgr, _calibrated, _open_capture, _probe_first_frame, _seek_capture


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
        # the first frame's container time: the origin of every frame's (an edit list may start it below 0)
        stamp = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
        self._origin = stamp if math.isfinite(stamp) else None
        self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
        self._pos, self._next = 0, 0   # the capture's next frame; the next frame to give (`seek`)
        probed = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps or (probed if probed and 0 < probed < 1000 else 30.0))
        self._own_times = fps is None   # the container's timestamps unless a rate is given
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count = n if n > 0 else None
        self.seekable = self.frame_count is not None   # (a stream that does not say its length plays through)
        # quarter turns clockwise OpenCV gives the stored frames (a phone's rotation tag: 90 clockwise, 270 back)
        self.turns = int(round(self._cap.get(cv2.CAP_PROP_ORIENTATION_META) or 0) // 90) % 4
        if calibration is not None:
            self._camera, self.notes = _calibrated(calibration, self.width, self.height, str(self.path), self.turns)
        self.info = {"kind": "file", "path": str(self.path)}

    def describe(self) -> str:
        return f"video {self.path}"

    def seek(self, frame: int | None = None, t: float | None = None) -> int:
        """Make `frame` (or the frame at time `t`, seconds, at the mean rate) the next one; returns its index."""
        if (frame is None) == (t is None):
            raise ValueError("seek: give exactly one of frame= or t=")
        if not self.seekable:
            raise SourceError(f"{self.describe()}: the file does not say how many frames it has; it can only play "
                              "through")
        if t is not None:
            frame = int(round(t * self.fps))
        if not 0 <= frame < self.frame_count:
            raise SourceError(f"{self.describe()}: cannot seek to frame {frame}; "
                              f"it has frames 0..{self.frame_count - 1}")
        self._next = int(frame)
        return self._next

    def _move_to(self, i: int) -> bool:
        """Put the capture before frame i: by position, checked, else reopened and decoded forward."""
        if i == self._pos:
            return True
        self._cap, ok = _seek_capture(self._cap, self.path, i)
        if ok:
            self._pos = i
        return ok

    def _frames(self) -> Iterator[Frame]:
        i, t = self._next, -1.0
        while not self.closed:
            ok = self._move_to(i)
            ok, img = self._cap.read() if ok else (False, None)
            if not ok or img is None:
                if self.frame_count and i < self.frame_count:
                    self._fail(f"{self.path}: decoding stopped at frame {i} of {self.frame_count} "
                               f"(truncated or corrupt file); {self._delivered(i)}")
                return
            self._pos = self._next = i + 1
            if not self._own_times:
                t = i / self.fps
            else:
                stamp = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
                own = stamp - self._origin if self._origin is not None else float("nan")
                # the container's time when it has one that goes forward, else one frame period on (from the
                # mean rate after a seek)
                t = own if own > t else (i / self.fps if t < 0 else t + 1.0 / self.fps)
            yield Frame(i, t, _as_bgr(img))
            i += 1

    def _release(self) -> None:
        self._cap.release()

