"""Frame sources: recordings, video files, V4L2 cameras and OAK (DepthAI) cameras.

Every source is an iterable of `Frame(index, t, image)` (t seconds, image BGR
uint8) carrying its `camera` (tracking.camera.Camera), with `close()` and
context-manager use. A source that ends because of damage or a vanished
camera sets `.error` (a message the caller can show) and warns with
`SourceWarning` instead of raising from inside the loop. Sources are opened
with `open_source(spec)`: `file:PATH` or a plain path (recording folder or
video file), `v4l2:0`, `v4l2:/dev/video2`, `depthai`, `depthai:<device id>`.
"""

from __future__ import annotations

import csv
import glob
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError, SourceError
from tracking.session import Session, load_session


class SourceWarning(RuntimeWarning):
    """A source ended early (truncated video, camera unplugged); the message says where and why."""


@dataclass(frozen=True)
class Frame:
    """One frame: `index` (0-based position in the source), `t` (seconds from the source's first
    frame; recording time for recordings, capture time for cameras), `image` (BGR uint8, HxWx3)."""

    index: int
    t: float
    image: np.ndarray


class Source:
    """Base of all sources. Subclasses implement `_frames()` and `_release()`."""

    kind = "file"

    def __init__(self):
        self.error: str | None = None  # set when the stream ended early because something failed
        self.info: dict = {"kind": self.kind}  # the session.json `source` block for recordings of this source
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


# -- video files -------------------------------------------------------------------------------------

def _open_capture(path: Path) -> cv2.VideoCapture:
    if not path.is_file():
        raise SourceError(f"{path}: video file does not exist")
    if path.stat().st_size == 0:
        raise SourceError(f"{path}: video file is empty")
    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    if not cap.isOpened():
        cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SourceError(f"{path}: OpenCV cannot open this video (corrupt file or unsupported container/codec)")
    return cap


def _probe_first_frame(cap: cv2.VideoCapture, path: Path) -> np.ndarray:
    ok, img = cap.read()
    if not ok or img is None:
        cap.release()
        raise SourceError(f"{path}: the video opens but no frame can be decoded (corrupt or truncated file)")
    return img


def _as_bgr(img: np.ndarray) -> np.ndarray:
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


class VideoFileSource(Source):
    """A plain video file; timestamps frame / fps. With `calibration` (OpenCV YAML) it has a camera
    (scaled to the video size if the calibration was made at another size of the same aspect)."""

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
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.frame_count = n if n > 0 else None
        if calibration is not None:
            cam = calibration if isinstance(calibration, Camera) else Camera.load_yaml(calibration)
            self._camera = _fit_camera(cam, self.width, self.height, str(calibration), str(self.path))
        self.info = {"kind": "file", "path": str(self.path)}

    def describe(self) -> str:
        return f"video {self.path}"

    def _frames(self) -> Iterator[Frame]:
        i = 0
        while not self.closed:
            ok, img = self._cap.read()
            if not ok or img is None:
                if self.frame_count and i < self.frame_count:
                    self._fail(f"{self.path}: decoding stopped at frame {i} of {self.frame_count} "
                               f"(truncated or corrupt file); frames 0..{i - 1} were delivered")
                return
            yield Frame(i, i / self.fps, _as_bgr(img))
            i += 1

    def _release(self) -> None:
        self._cap.release()


def _fit_camera(cam: Camera, width: int, height: int, calib_name: str, what: str) -> Camera:
    """The calibration at the stream's size: scaled when the aspect matches, else an error."""
    if (cam.width, cam.height) == (width, height):
        return cam
    if abs(cam.width / cam.height - width / height) > 1e-3:
        raise CalibrationError(
            f"{calib_name} is for {cam.width}x{cam.height} but {what} delivers {width}x{height} "
            "(another aspect ratio); calibrate at this size"
        )
    return cam.scaled(width, height)


# -- recordings --------------------------------------------------------------------------------------

def read_frames_csv(path: Path) -> np.ndarray:
    """Timestamps (seconds) from a recording's frames.csv (`frame,t`, one row per frame, in order)."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise SessionError(f"{path}: cannot be read ({e.strerror})") from None
    if not rows or [c.strip() for c in rows[0]] != ["frame", "t"]:
        raise SessionError(f"{path}: first line must be the header 'frame,t'")
    times = []
    for lineno, row in enumerate(rows[1:], 2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != 2:
            raise SessionError(f"{path}:{lineno}: expected 'frame,t', got {','.join(row)!r}")
        try:
            frame, t = int(row[0]), float(row[1])
        except ValueError:
            raise SessionError(f"{path}:{lineno}: frame must be an integer and t a number, got {row!r}") from None
        if frame != len(times):
            raise SessionError(f"{path}:{lineno}: frame {frame} out of order; expected {len(times)}")
        if not np.isfinite(t) or (times and t < times[-1]):
            raise SessionError(f"{path}:{lineno}: t must be finite and not decrease, got {t}")
        times.append(t)
    return np.asarray(times, float)


class RecordingSource(Source):
    """A recording folder (`arapp-recording/1`): frames at their recorded timestamps.

    realtime: pace frames to their timestamps (sleeping, no busy wait) from the
    moment the first one is taken, scaled by `speed`; else as fast as possible.
    loop: start over after the last frame (`index` and `t` restart; `.loops`
    counts the restarts). `seek(frame=)` / `seek(t=)` sets the next frame.
    """

    kind = "recording"

    def __init__(self, folder: str | Path, realtime: bool = False, loop: bool = False, speed: float = 1.0):
        super().__init__()
        self.folder = Path(folder)
        self.session: Session = load_session(self.folder)
        self._camera = self.session.camera
        self.fps = self.session.fps
        self.realtime, self.loop, self.speed = bool(realtime), bool(loop), float(speed)
        if self.speed <= 0:
            raise SourceError(f"replay speed must be positive, got {speed}")
        self.video_path = self.session.video_path
        if not self.video_path.is_file():
            raise SourceError(f"{self.video_path}: missing; {self.folder / 'session.json'} names video "
                              f"{self.session.video!r} but the folder has no such file")
        self._cap = _open_capture(self.video_path)
        first = _probe_first_frame(self._cap, self.video_path)
        h, w = first.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            self._cap.release()
            raise SessionError(f"{self.folder / 'session.json'}: camera is {self.camera.width}x{self.camera.height} "
                               f"but {self.video_path.name} has {w}x{h} frames")
        self._pos = 1  # the capture's next frame
        csv_path = self.folder / "frames.csv"
        if csv_path.is_file():
            self.times = read_frames_csv(csv_path)
        else:
            n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
            if n <= 0:
                raise SourceError(f"{self.video_path}: frame count unknown and no frames.csv; add frames.csv")
            self.times = np.arange(n) / self.fps
        self.frame_count = len(self.times)
        self._next = 0
        self._pace_origin: float | None = None
        self._first_img = first
        self.loops = 0
        self.info = {"kind": "file", "recording": str(self.folder), **{k: v for k, v in self.session.source.items()
                                                                      if k != "kind"}}

    def describe(self) -> str:
        return f"recording {self.folder}"

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if self.frame_count else 0.0

    def seek(self, frame: int | None = None, t: float | None = None) -> int:
        """Make `frame` (or the first frame at or after time `t`, seconds) the next one; returns its index."""
        if (frame is None) == (t is None):
            raise ValueError("seek: give exactly one of frame= or t=")
        if t is not None:
            frame = int(np.searchsorted(self.times, t - 1e-9, side="left"))
        if not 0 <= frame < self.frame_count:
            raise SourceError(f"{self.describe()}: cannot seek to frame {frame}; it has frames 0..{self.frame_count - 1}")
        self._next = int(frame)
        self._pace_origin = None
        return self._next

    def _read(self, i: int) -> np.ndarray | None:
        """Frame i of the video (sequential reads; seeks by position, checked, else by decoding forward)."""
        if i == 0 and self._first_img is not None and self._pos == 1:
            img, self._first_img = self._first_img, None
            return img
        self._first_img = None
        if i != self._pos:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, i)
            if int(self._cap.get(cv2.CAP_PROP_POS_FRAMES)) != i:  # inexact seek: reopen, decode forward
                self._cap.release()
                self._cap = _open_capture(self.video_path)
                for _ in range(i):
                    if not self._cap.grab():
                        return None
            self._pos = i
        ok, img = self._cap.read()
        if not ok or img is None:
            return None
        self._pos = i + 1
        return _as_bgr(img)

    def _frames(self) -> Iterator[Frame]:
        self._pace_origin = None
        while not self.closed:
            if self._next >= self.frame_count:
                if not self.loop:
                    return
                self._next = 0
                self.loops += 1
                self._pace_origin = None
            i = self._next
            img = self._read(i)
            if img is None:
                self._fail(f"{self.video_path}: decoding stopped at frame {i} of {self.frame_count} "
                           f"(truncated or corrupt video); frames before it were replayed")
                return
            t = float(self.times[i])
            if self.realtime:
                now = time.monotonic()
                if self._pace_origin is None:
                    self._pace_origin = now - t / self.speed
                wait = self._pace_origin + t / self.speed - now
                if wait > 0:
                    time.sleep(wait)
            self._next = i + 1
            yield Frame(i, t, img)

    def _release(self) -> None:
        self._cap.release()


# -- V4L2 cameras ------------------------------------------------------------------------------------

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
        if calibration is not None:
            cam = calibration if isinstance(calibration, Camera) else Camera.load_yaml(calibration)
            self._camera = _fit_camera(cam, w, h, str(calibration), self.path)
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


# -- DepthAI (OAK) cameras ---------------------------------------------------------------------------

def _import_depthai():
    try:
        import depthai as dai  # noqa: PLC0415 - heavy, optional
    except ImportError as e:
        raise SourceError(f"depthai is not installed ({e}); pip install depthai to use OAK cameras") from None
    return dai


def list_depthai() -> list[dict]:
    """Attached OAK devices: [{"spec": "depthai:<id>", "id", "name", "state"}]. Empty if none or no depthai."""
    try:
        dai = _import_depthai()
    except SourceError:
        return []
    return [{"spec": f"depthai:{d.getDeviceId()}", "id": d.getDeviceId(), "name": d.name, "state": str(d.state)}
            for d in dai.Device.getAllAvailableDevices()]


class DepthAISource(Source):
    """The colour camera (CAM_A) of an OAK device through the depthai v3 API.

    Intrinsics and distortion come from the device's own calibration at the
    delivered size, so no separate calibration is needed. `device_id` picks a
    device when several are attached (ids as `arapp sources` lists them).
    """

    kind = "depthai"

    def __init__(self, device_id: str | None = None, width: int = 1280, height: int = 720, fps: float = 30.0,
                 read_timeout_s: float = 5.0):
        super().__init__()
        dai = _import_depthai()
        from datetime import timedelta

        self._timeout = timedelta(seconds=read_timeout_s)
        available = dai.Device.getAllAvailableDevices()
        if not available:
            raise SourceError("no DepthAI (OAK) device found; check the USB cable (and udev rules), "
                              "then run 'arapp sources'")
        if device_id:
            match = [d for d in available if d.getDeviceId() == device_id or d.name == device_id]
            if not match:
                ids = ", ".join(d.getDeviceId() for d in available)
                raise SourceError(f"no DepthAI device {device_id!r}; attached: {ids}")
            info = match[0]
        else:
            info = available[0]
        try:
            self._device = dai.Device(info)
        except RuntimeError as e:
            raise SourceError(f"DepthAI device {info.getDeviceId()} cannot be opened (in use by another "
                              f"program?): {e}") from None
        self.device_id = info.getDeviceId()
        socket = dai.CameraBoardSocket.CAM_A
        self._pipeline = dai.Pipeline(self._device)
        cam = self._pipeline.create(dai.node.Camera).build(socket)
        out = cam.requestOutput((int(width), int(height)), dai.ImgFrame.Type.BGR888i, fps=float(fps))
        self._queue = out.createOutputQueue(maxSize=4, blocking=False)
        self._pipeline.start()
        self.fps = float(fps)
        calib = self._device.readCalibration()
        K = np.asarray(calib.getCameraIntrinsics(socket, int(width), int(height)), float)
        dist = np.asarray(calib.getDistortionCoefficients(socket), float)
        self._camera = Camera(K, dist[:14] if dist.size >= 14 else dist[:5], int(width), int(height))
        self._calib_from_frames = True
        self.info = {"kind": "depthai", "device_id": self.device_id, "name": info.name,
                     "width": int(width), "height": int(height), "fps": self.fps}

    def describe(self) -> str:
        return f"DepthAI device {self.device_id}"

    def _frames(self) -> Iterator[Frame]:
        i, t0, seq0 = 0, None, None
        while not self.closed:
            try:
                msg = self._queue.get(self._timeout)
            except RuntimeError as e:  # QueueException: pipeline stopped / device gone
                self._fail(f"DepthAI device {self.device_id} stopped delivering frames after {i} frames: {e}")
                return
            if msg is None:
                self._fail(f"DepthAI device {self.device_id}: no frame for {self._timeout.total_seconds():.0f} s "
                           f"after {i} frames (unplugged?)")
                return
            if self._calib_from_frames:
                self._camera = self._camera_from_frame(msg) or self._camera
                self._calib_from_frames = False
            stamp = msg.getTimestamp().total_seconds()
            seq = msg.getSequenceNum()
            if t0 is None:
                t0, seq0 = stamp, seq
            yield Frame(int(seq - seq0), stamp - t0, msg.getCvFrame())
            i += 1

    def _camera_from_frame(self, msg) -> Camera | None:
        """Intrinsics of the delivered image (crop/scale included) from the frame's transformation."""
        try:
            tr = msg.getTransformation()
            K = np.asarray(tr.getIntrinsicMatrix(), float)
            dist = np.asarray(tr.getDistortionCoefficients(), float)
            w, h = tr.getSize()
            return Camera(K, dist[:14] if dist.size >= 14 else dist[:5], w, h)
        except (AttributeError, RuntimeError, CalibrationError, ValueError):
            return None

    def _release(self) -> None:
        for step in (lambda: self._pipeline.stop(), lambda: self._device.close()):
            try:
                step()
            except (AttributeError, RuntimeError):
                pass


# -- specs -------------------------------------------------------------------------------------------

SPEC_HELP = ("a recording folder or video file (optionally 'file:PATH'), 'v4l2:0', 'v4l2:/dev/video2', "
             "'depthai' or 'depthai:<device id>'")


def open_source(spec: str, realtime: bool = False, loop: bool = False, calibration: str | Path | None = None,
                width: int | None = None, height: int | None = None, fps: float | None = None,
                fourcc: str | None = "MJPG") -> Source:
    """Open a source from its spec (see SPEC_HELP). Options apply where they make sense:
    realtime/loop to recordings, calibration to video files and V4L2, size/fps to cameras."""
    spec = str(spec).strip()
    if not spec:
        raise SourceError(f"empty source; give {SPEC_HELP}")
    scheme, colon, rest = spec.partition(":")
    if scheme == "v4l2":
        if not rest:
            raise SourceError("v4l2 needs a device: 'v4l2:0' or 'v4l2:/dev/video0'")
        return V4L2Source(rest, width, height, fps, fourcc, calibration)
    if scheme == "depthai":
        return DepthAISource(rest or None, width or 1280, height or 720, fps or 30.0)
    path = Path(rest if scheme == "file" else spec)
    looks_like_scheme = colon and scheme != "file" and len(scheme) > 1 and scheme.isalnum()
    if looks_like_scheme and not path.exists():
        raise SourceError(f"unknown source kind {scheme!r} in {spec!r}; give {SPEC_HELP}")
    if path.is_dir():
        if calibration is not None:
            raise SourceError(f"{path}: a recording carries its own camera in session.json; drop --calibration")
        return RecordingSource(path, realtime=realtime, loop=loop)
    if path.is_file():
        return VideoFileSource(path, calibration, fps)
    raise SourceError(f"{path}: no such recording folder or video file")
