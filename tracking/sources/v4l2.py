"""V4L2 cameras through OpenCV (spec `v4l2:N` or `v4l2:/dev/videoN`)."""

from __future__ import annotations

import glob
import os
import time
from pathlib import Path
from typing import Iterator

import cv2

from tracking.camera import Camera
from tracking.errors import SourceError

from .base import Frame, Source, _as_bgr, _calibrated


def _v4l2_path(device: int | str) -> str:
    if isinstance(device, int) or (isinstance(device, str) and device.isdigit()):
        return f"/dev/video{int(device)}"
    return str(device)


def _fourcc_str(value: float) -> str:
    v = int(value)
    return "".join(chr((v >> (8 * k)) & 0xFF) for k in range(4)) if v > 0 else "?"


class V4L2Source(Source):
    """A V4L2 camera through OpenCV (`/dev/videoN` or its index). Requests size, fps and FOURCC
    (MJPG by default, which most UVC webcams need for full rate); `.granted` reports what the
    camera actually gave. Capture timestamps come from the driver (CAP_PROP_POS_MSEC) when it
    provides them, else from the host monotonic clock; `t` is relative to the first frame."""

    kind = "v4l2"
    live = True

    def __init__(self, device: int | str = 0, width: int | None = None, height: int | None = None,
                 fps: float | None = None, fourcc: str | None = "MJPG", calibration: str | Path | Camera | None = None,
                 read_timeout_s: float = 5.0):
        super().__init__()
        self.path = _v4l2_path(device)
        if not os.path.exists(self.path):
            attached = ", ".join(sorted(glob.glob("/dev/video*"))) or "none"
            raise SourceError(f"no camera at {self.path} (attached V4L2 devices: {attached}); "
                              "run 'arapp sources' to list cameras")
        if not os.access(self.path, os.R_OK | os.W_OK):
            raise SourceError(f"{self.path}: permission denied; add yourself to the 'video' group")
        os.environ.setdefault("OPENCV_VIDEOIO_V4L_SELECT_TIMEOUT", str(int(read_timeout_s * 1000)))
        self._cap = cv2.VideoCapture(self.path, cv2.CAP_V4L2)
        if not self._cap.isOpened():
            raise SourceError(f"{self.path}: cannot be opened as a camera (busy in another program, "
                              "or not a video capture device)")
        if fourcc:
            self._cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*fourcc))
        if width:
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        if height:
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        if fps:
            self._cap.set(cv2.CAP_PROP_FPS, fps)
        ok, first = self._cap.read()
        if not ok or first is None:
            self._cap.release()
            raise SourceError(f"{self.path}: opened but delivered no frame within {read_timeout_s:.0f} s "
                              "(camera busy in another program, or not a capture device)")
        self._first = first
        h, w = first.shape[:2]
        got_fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(got_fps) if got_fps and got_fps > 0 else float(fps or 30.0)
        self.granted = {"width": w, "height": h, "fps": self.fps, "fourcc": _fourcc_str(self._cap.get(cv2.CAP_PROP_FOURCC))}
        self.requested = {"width": width, "height": height, "fps": fps, "fourcc": fourcc}
        if calibration is not None:   # a file without an image size is for the granted size (the note says so)
            self._camera, self.notes = _calibrated(calibration, w, h, self.path)
        self.info = {"kind": "v4l2", "device": self.path, "name": _v4l2_name(self.path), **self.granted}

    def describe(self) -> str:
        return f"camera {self.path}"

    def _frames(self) -> Iterator[Frame]:
        i, t0 = 0, None
        img = self._first
        while not self.closed:
            if img is None:
                ok, img = self._cap.read()
                if not ok or img is None:
                    self._fail(f"{self.path}: camera stopped delivering frames after {i} frames (unplugged or "
                               "taken by another program)")
                    return
            ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
            stamp = ms / 1000.0 if ms and ms > 0 else time.monotonic()
            if t0 is None:
                t0 = stamp
            yield Frame(i, stamp - t0, _as_bgr(img))
            img = None
            i += 1

    def _release(self) -> None:
        self._cap.release()


def _v4l2_name(path: str) -> str:
    try:
        return Path(f"/sys/class/video4linux/{Path(path).name}/name").read_text().strip()
    except OSError:
        return "?"


def list_v4l2() -> list[dict]:
    """V4L2 device nodes with their driver names: [{"spec": "v4l2:/dev/video0", "device", "name"}]."""
    out = []
    for p in sorted(glob.glob("/dev/video*"), key=lambda s: (len(s), s)):
        out.append({"spec": f"v4l2:{p}", "device": p, "name": _v4l2_name(p)})
    return out

