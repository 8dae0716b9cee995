"""OAK cameras through depthai v3 (spec `depthai` or `depthai:<device id>`); depthai is optional."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SourceError

from .base import Frame, Source


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
    live = True

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

