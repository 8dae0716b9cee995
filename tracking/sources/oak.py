"""OAK cameras through depthai v3 (spec `depthai` or `depthai:<device id>`); depthai is optional.

On a device with a stereo pair (OAK-D: CAM_B, CAM_C) the source also gives
depth: depthai's StereoDepth node computes it on the device, aligned to the
colour camera (RVC2: the colour output linked to `StereoDepth.inputAlignTo`;
RVC4: an `ImageAlign` node), and a `Sync` node pairs each colour frame with
its depth frame. Depth arrives in millimetres (uint16) and is handed on as
`Frame.depth` in metres. With depth on, the colour output is undistorted on
the device, so colour and depth share one pinhole camera (distortion zero).

Tested only against a stand-in depthai module (tests/test_sources.py): the
call sequence follows depthai 3.x's documented API and examples, not a run on
a real OAK device.
"""

from __future__ import annotations

from datetime import timedelta
from typing import Iterator

import cv2
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


# stereo pair resolution: the OV9282 pair of an OAK-D at 640x400 gives depth at 30 fps with room to spare
STEREO_SIZE = (640, 400)
DEPTH_SCALE = 0.001  # StereoDepth's default depth unit: millimetres


class DepthAISource(Source):
    """The colour camera (CAM_A) of an OAK device through the depthai v3 API, with stereo depth.

    Intrinsics and distortion come from the device's own calibration at the
    delivered size, so no separate calibration is needed. `device_id` picks a
    device when several are attached (ids as `arapp sources` lists them).
    depth: None (default) gives depth when the device has a stereo pair (CAM_B
    and CAM_C), True requires it, False turns it off; `has_depth` says which.
    """

    kind = "depthai"
    live = True

    def __init__(self, device_id: str | None = None, width: int = 1280, height: int = 720, fps: float = 30.0,
                 read_timeout_s: float = 5.0, depth: bool | None = None):
        super().__init__()
        dai = _import_depthai()

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
        stereo_pair = self._has_stereo_pair(dai)
        if depth and not stereo_pair:
            self._device.close()
            raise SourceError(f"DepthAI device {self.device_id} has no stereo pair (CAM_B and CAM_C), so no "
                              "depth; use an OAK-D, or record without depth")
        self.has_depth = stereo_pair if depth is None else bool(depth)
        self._pipeline = dai.Pipeline(self._device)
        cam = self._pipeline.create(dai.node.Camera).build(socket)
        size = (int(width), int(height))
        if self.has_depth:
            # undistorted on the device: the depth aligned to it is then exact on a pinhole camera
            out = cam.requestOutput(size, dai.ImgFrame.Type.BGR888i, fps=float(fps), enableUndistortion=True)
            self._queue = self._depth_pipeline(dai, out, float(fps))
        else:
            out = cam.requestOutput(size, dai.ImgFrame.Type.BGR888i, fps=float(fps))
            self._queue = out.createOutputQueue(maxSize=4, blocking=False)
        self._pipeline.start()
        self.fps = float(fps)
        calib = self._device.readCalibration()
        K = np.asarray(calib.getCameraIntrinsics(socket, int(width), int(height)), float)
        dist = np.asarray(calib.getDistortionCoefficients(socket), float)
        if self.has_depth:
            dist = np.zeros(5)
        self._camera = Camera(K, dist[:14] if dist.size >= 14 else dist[:5], int(width), int(height))
        self._calib_from_frames = True
        self.info = {"kind": "depthai", "device_id": self.device_id, "name": info.name,
                     "width": int(width), "height": int(height), "fps": self.fps}
        if self.has_depth:
            self.info["depth"] = {"node": "StereoDepth", "stereo_size": list(STEREO_SIZE), "aligned_to": "CAM_A",
                                  "colour_undistorted_on_device": True}

    def _has_stereo_pair(self, dai) -> bool:
        cams = set(self._device.getConnectedCameras())
        return dai.CameraBoardSocket.CAM_B in cams and dai.CameraBoardSocket.CAM_C in cams

    def _depth_pipeline(self, dai, colour_out, fps: float):
        """StereoDepth from the CAM_B/CAM_C pair, aligned to `colour_out`, paired with it by a Sync node;
        returns the queue of message groups {"rgb", "depth"}."""
        p = self._pipeline
        left = p.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_B)
        right = p.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_C)
        stereo = p.create(dai.node.StereoDepth).build(left.requestOutput(STEREO_SIZE, fps=fps),
                                                      right.requestOutput(STEREO_SIZE, fps=fps),
                                                      presetMode=dai.node.StereoDepth.PresetMode.DEFAULT)
        stereo.setLeftRightCheck(True)       # drops occluded and mismatched pixels (no depth there)
        stereo.setSubpixel(True)             # finer depth steps at the scanning distance
        stereo.setExtendedDisparity(True)    # the OAK-D sees down to ~20 cm only with it (objects at 25-35 cm)
        sync = p.create(dai.node.Sync)
        sync.setSyncThreshold(timedelta(seconds=0.5 / fps))
        colour_out.link(sync.inputs["rgb"])
        if self._device.getPlatform() == dai.Platform.RVC4:
            align = p.create(dai.node.ImageAlign)
            stereo.depth.link(align.input)
            colour_out.link(align.inputAlignTo)
            align.outputAligned.link(sync.inputs["depth"])
        else:
            colour_out.link(stereo.inputAlignTo)
            stereo.depth.link(sync.inputs["depth"])
        return sync.out.createOutputQueue(maxSize=4, blocking=False)

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
            depth = None
            if self.has_depth:  # a message group: the colour frame and its depth
                msg, depth = msg["rgb"], self._depth_metres(msg["depth"])
            if self._calib_from_frames:
                self._camera = self._camera_from_frame(msg) or self._camera
                self._calib_from_frames = False
            stamp = msg.getTimestamp().total_seconds()
            seq = msg.getSequenceNum()
            if t0 is None:
                t0, seq0 = stamp, seq
            image = msg.getCvFrame()
            if depth is not None and depth.shape != image.shape[:2]:
                # aligned, but delivered at another size: same field of view, so a resize keeps alignment
                depth = cv2.resize(depth, (image.shape[1], image.shape[0]), interpolation=cv2.INTER_NEAREST)
            yield Frame(int(seq - seq0), stamp - t0, image, depth)
            i += 1

    @staticmethod
    def _depth_metres(msg) -> np.ndarray:
        """StereoDepth's uint16 millimetres (0 = no depth) as float32 metres."""
        return msg.getFrame().astype(np.float32) * np.float32(DEPTH_SCALE)

    def _camera_from_frame(self, msg) -> Camera | None:
        """Intrinsics of the delivered image (crop/scale included) from the frame's transformation."""
        try:
            tr = msg.getTransformation()
            K = np.asarray(tr.getIntrinsicMatrix(), float)
            dist = np.asarray(tr.getDistortionCoefficients(), float)
            w, h = tr.getSize()
            if self.has_depth:
                dist = np.zeros(5)  # undistorted on the device (requestOutput(enableUndistortion=True))
            return Camera(K, dist[:14] if dist.size >= 14 else dist[:5], w, h)
        except (AttributeError, RuntimeError, CalibrationError, ValueError):
            return None

    def _release(self) -> None:
        for step in (lambda: self._pipeline.stop(), lambda: self._device.close()):
            try:
                step()
            except (AttributeError, RuntimeError):
                pass

