"""The source interface: `Source` (an iterable of `Frame`s with a camera), `SourceWarning`, and the
OpenCV capture helpers the file-based sources share.

A source class says what it is with class attributes: `scheme` (the spec prefix that opens it, see
tracking.sources.registry), `kind` (the session.json `source.kind`), `live` (frames arrive in real
time from a device: the GUI shows the newest, never paces or seeks) and `seekable` (`seek()` works).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SourceError


class SourceWarning(RuntimeWarning):
    """A source ended early (truncated video, camera unplugged); the message says where and why."""


@dataclass(frozen=True)
class Frame:
    """One frame: `index` (0-based position in the source), `t` (seconds from the source's first
    frame; recording time for recordings, capture time for cameras), `image` (BGR uint8, HxWx3), and
    `depth` when the source gives depth (depth cameras, recordings with a depth stream): float32 HxW,
    metres along the camera's z, aligned to `image` pixel for pixel (same camera), 0 where unknown;
    else None."""

    index: int
    t: float
    image: np.ndarray
    depth: np.ndarray | None = None


class Source:
    """Base of all sources. Subclasses implement `_frames()` and `_release()`, set `kind`, `live` and
    `seekable`, and are opened through a scheme registered in tracking.sources.registry."""

    kind = "file"
    live = False      # frames come from a device as they happen: show the newest, never pace or seek
    seekable = False  # seek(frame=) / seek(t=) work

    def __init__(self):
        self.error: str | None = None  # set when the stream ended early because something failed
        self.info: dict = {"kind": self.kind}  # the session.json `source` block for recordings of this source
        self.notes: list[str] = []  # what a user should read about how the source was opened (one line each)
        self._camera: Camera | None = None
        self.fps: float = 30.0
        self.closed = False

    @property
    def camera(self) -> Camera:
        if self._camera is None:
            raise SourceError(self._no_camera_message())
        return self._camera

    @property
    def has_camera(self) -> bool:
        return self._camera is not None

    def _no_camera_message(self) -> str:
        return f"{self.describe()} has no calibration; pass --calibration cam.yaml (OpenCV FileStorage YAML)"

    def describe(self) -> str:
        return self.kind

    def _fail(self, message: str) -> None:
        """End the stream with an error the caller can show (no exception from inside iteration)."""
        self.error = message
        warnings.warn(message, SourceWarning, stacklevel=3)

    @staticmethod
    def _delivered(i: int) -> str:
        """What a stream that ended early at frame `i` had given: for the end of a `_fail` message."""
        return f"frames 0..{i - 1} were delivered" if i > 0 else "no frame was delivered"

    def __iter__(self) -> Iterator[Frame]:
        if self.closed:
            raise SourceError(f"{self.describe()}: source is closed")
        return self._frames()

    def _frames(self) -> Iterator[Frame]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _release(self) -> None:
        pass

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - never raise from a finaliser
            pass


# FFmpeg's own stderr lines ("moov atom not found") would stand beside the one-line error a file that is
# no video gets; read once, when OpenCV first loads FFmpeg (OPENCV_FFMPEG_LOGLEVEL set by the user wins).
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def _looks_like_text(path: Path) -> bool:
    """Whether the file starts as UTF-8 text (a video container starts with binary boxes or headers)."""
    with open(path, "rb") as f:
        head = f.read(512)
    try:
        head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return b"\0" not in head


def _open_capture(path: Path) -> cv2.VideoCapture:
    if not path.is_file():
        raise SourceError(f"{path}: {'a folder, not a video' if path.is_dir() else 'video file does not exist'}")
    if path.stat().st_size == 0:
        raise SourceError(f"{path}: video file is empty")
    if _looks_like_text(path):
        raise SourceError(f"{path}: a text file, not a video; give a video (mp4, avi, mov, webm, mkv), a recording "
                          "folder or a folder of images")
    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)  # the backend-fallback warnings: the error below says it all
    try:
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        if not cap.isOpened():
            cap = cv2.VideoCapture(str(path))
    finally:
        log.setLogLevel(level)
    if not cap.isOpened():
        raise SourceError(f"{path}: OpenCV cannot open this video (corrupt file or unsupported container/codec); "
                          "convert it, e.g. `ffmpeg -i FILE out.mp4`")
    return cap


# codec tags as containers write them, by the name people know them by
CODEC_NAMES = {"av01": "AV1", "hvc1": "HEVC", "hev1": "HEVC", "hevc": "HEVC", "vp09": "VP9", "vp80": "VP8",
               "avc1": "H.264", "h264": "H.264", "mp4v": "MPEG-4", "mjpg": "Motion JPEG", "ffv1": "FFV1"}


def codec_name(cap: cv2.VideoCapture) -> str:
    """The video's codec as its four-character tag says (and its common name when known), or "unknown"."""
    tag = int(cap.get(cv2.CAP_PROP_FOURCC) or 0)
    text = "".join(chr((tag >> (8 * k)) & 0xFF) for k in range(4)).strip("\x00 ")
    if not text.isprintable() or not text:
        return "unknown"
    name = CODEC_NAMES.get(text.lower())
    return f"{name}, '{text}'" if name else f"'{text}'"


def _seek_capture(cap: cv2.VideoCapture, path: Path, i: int) -> tuple[cv2.VideoCapture, bool]:
    """(`cap` placed before frame i, whether it got there): by position, checked, else a capture of `path`
    reopened and decoded forward (OpenCV's seek in some files lands elsewhere); False when the file ends first."""
    cap.set(cv2.CAP_PROP_POS_FRAMES, i)
    if int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == i:
        return cap, True
    cap.release()
    cap = _open_capture(path)
    for _ in range(i):
        if not cap.grab():
            return cap, False
    return cap, True


def _probe_first_frame(cap: cv2.VideoCapture, path: Path) -> np.ndarray:
    ok, img = cap.read()
    if not ok or img is None:
        codec = codec_name(cap)
        cap.release()
        # a file OpenCV opens but cannot decode is as often a codec its FFmpeg build lacks (AV1 in the pip wheels)
        # as a damaged file: both are said, with the conversion that fixes either
        raise SourceError(f"{path}: the video opens but no frame can be decoded: OpenCV's FFmpeg may have no decoder "
                          f"for its codec ({codec}), or the file is corrupt or truncated; convert it, e.g. "
                          "`ffmpeg -i FILE -c:v libx264 out.mp4`")
    return img


def _as_bgr(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


def _calibrated(calibration, width: int, height: int, what: str, turns: int = 0) -> tuple[Camera, list[str]]:
    """(the camera of `calibration` (a Camera, or a file tracking.calibration_file reads) at the stream's size
    (_fit_camera), the notes a user should read about the file). A file without an image size is taken at
    width x height, which a note says. `turns`: quarter turns clockwise the decoder gave the stored frames (a
    video's rotation tag)."""
    if isinstance(calibration, Camera):
        cam, notes = calibration, []
    else:
        cam, notes = Camera.load_file(calibration, (width, height))
    if turns % 2 and not _same_aspect(cam.width, cam.height, width, height) and \
            _same_aspect(cam.height, cam.width, width, height):
        # calibrated as the sensor lies, filmed upright: the frames come turned by the file's rotation tag
        cam = cam.turned(turns)
        way = "90 degrees counter-clockwise" if turns % 4 == 3 else "90 degrees clockwise"
        notes = notes + [f"{calibration}: turned {way} with {what}'s rotation tag (the video was filmed upright)"]
    return _fit_camera(cam, width, height, str(calibration), what), notes


def _same_aspect(w1: int, h1: int, w2: int, h2: int) -> bool:
    """Whether two image sizes have one aspect ratio (to 1e-3: 1280x720 and 1920x1080 do)."""
    return abs(w1 / h1 - w2 / h2) <= 1e-3


def _fit_camera(cam: Camera, width: int, height: int, calib_name: str, what: str) -> Camera:
    """The calibration at the stream's size: scaled when the aspect matches, else an error."""
    if (cam.width, cam.height) == (width, height):
        return cam
    if not _same_aspect(cam.width, cam.height, width, height):
        raise CalibrationError(
            f"{calib_name} is for {cam.width}x{cam.height} but {what} delivers {width}x{height} "
            "(another aspect ratio); calibrate at this size"
        )
    return cam.scaled(width, height)

