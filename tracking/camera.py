"""The one camera model: pinhole intrinsics with OpenCV's lens distortion.

Pixel centres are at integer coordinates (OpenCV's convention). Points are in
the camera frame (x right, y down, z forward), metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracking.calibration_file import read_calibration_file
from tracking.errors import CalibrationError


@dataclass
class Camera:
    """Intrinsics `K` (3x3), distortion `dist` (OpenCV order k1 k2 p1 p2 [k3 ...]), image size in pixels.

    `readout` (optional, seconds): a rolling shutter's readout time, top row to bottom row; a frame's
    timestamp is its centre row's time (row y is read at t + readout * ((y + 0.5) / height - 0.5)).
    0 = a global shutter or unknown.
    """

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    readout: float = 0.0
    _maps: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self.K = np.asarray(self.K, dtype=float).reshape(3, 3)
        d = np.zeros(5) if self.dist is None else np.asarray(self.dist, dtype=float).ravel()
        if d.size not in (4, 5, 8, 12, 14):
            raise CalibrationError(
                f"distortion has {d.size} coefficients; OpenCV takes 4, 5, 8, 12 or 14 (k1 k2 p1 p2 [k3 ...])"
            )
        self.dist = d
        self.width = int(self.width)
        self.height = int(self.height)
        if self.width <= 0 or self.height <= 0:
            raise CalibrationError(f"image size must be positive, got {self.width}x{self.height}")
        if not np.all(np.isfinite(self.K)) or self.K[0, 0] <= 0 or self.K[1, 1] <= 0:
            raise CalibrationError(f"camera matrix must have positive finite fx, fy; got {self.K.tolist()}")
        self.readout = float(self.readout or 0.0)
        if not (0.0 <= self.readout < 1.0):
            raise CalibrationError(f"rolling-shutter readout must be 0 <= readout < 1 seconds, got {self.readout}")

    # -- accessors -----------------------------------------------------------
    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0))

    # -- projection ----------------------------------------------------------
    def row_offsets(self, y: np.ndarray) -> np.ndarray:
        """Seconds from the frame's time (its centre row's) at which image rows y (N,) were read out (all 0
        with a global shutter)."""
        return self.readout * ((np.asarray(y, float) + 0.5) / self.height - 0.5)

    def project(self, points_camera: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of camera-frame points (..., 3), distortion applied (as cv2.projectPoints)."""
        p = np.asarray(points_camera, dtype=float)
        shape = p.shape[:-1]
        pts, _ = cv2.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.dist)
        return pts.reshape(*shape, 2)

    def project_world(self, points_world: np.ndarray, world_from_camera: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of world points seen from a `world_from_camera` pose."""
        cam_from_world = np.linalg.inv(world_from_camera)
        p = np.asarray(points_world, dtype=float)
        pc = p @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
        return self.project(pc)

    def unproject(self, pixels: np.ndarray, depth: float | np.ndarray = 1.0) -> np.ndarray:
        """Camera-frame points (..., 3) at the given z depth for distorted pixels (..., 2)."""
        px = np.asarray(pixels, dtype=float)
        shape = px.shape[:-1]
        n = cv2.undistortPoints(
            px.reshape(-1, 1, 2), self.K, self.dist, None, None,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12),
        ).reshape(-1, 2)
        rays = np.concatenate([n, np.ones((n.shape[0], 1))], axis=1).reshape(*shape, 3)
        return rays * np.asarray(depth, dtype=float)[..., None]

    def undistort_points(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted pixel coordinates (..., 2) in the same K (distortion removed)."""
        return (self.unproject(pixels) @ self.K.T)[..., :2]

    def undistort_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (map_x, map_y, float32) turning a distorted image into an undistorted one, same K. Cached."""
        if "undistort" not in self._maps:
            self._maps["undistort"] = cv2.initUndistortRectifyMap(
                self.K, self.dist, None, self.K, (self.width, self.height), cv2.CV_32FC1
            )
        return self._maps["undistort"]

    def distort_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps taking an undistorted image (same K) to the distorted camera image. Cached.

        For each distorted output pixel, the undistorted position it comes from.
        """
        if "distort" not in self._maps:
            xs, ys = np.meshgrid(np.arange(self.width, dtype=float), np.arange(self.height, dtype=float))
            und = self.undistort_points(np.stack([xs, ys], axis=-1))
            self._maps["distort"] = (und[..., 0].astype(np.float32), und[..., 1].astype(np.float32))
        return self._maps["distort"]

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        if not self.has_distortion:
            return image
        mx, my = self.undistort_maps()
        return cv2.remap(image, mx, my, cv2.INTER_LINEAR)

    # -- resizing --------------------------------------------------------------
    def scaled(self, width: int, height: int) -> "Camera":
        """The same lens at another resolution (pixel-centre convention kept: c' = (c + 0.5) s - 0.5)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 1] *= sx
        K[1, 1] *= sy
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return Camera(K, self.dist.copy(), width, height, self.readout)

    def turned(self, quarter_turns: int) -> "Camera":
        """The same camera for its images turned `quarter_turns` x 90 degrees clockwise (cv2.rotate's
        ROTATE_90_CLOCKWISE, repeated): a video a phone recorded upright, which the decoder turns by its
        rotation tag. One turn maps pixel (u, v) to (h - 1 - v, u) and the camera's x, y to -y, x: fx and fy
        swap, the principal point moves with the pixels, the radial terms stay and the tangential ones turn
        (p1, p2 -> p2, -p1). CalibrationError for a skewed matrix or thin-prism / tilt terms (no such turn)."""
        k = int(quarter_turns) % 4
        if k == 0:
            return self
        if self.K[0, 1] != 0.0 or self.dist.size > 8:
            raise CalibrationError("cannot turn a calibration with skew or thin-prism / tilt distortion terms; "
                                   "calibrate on the turned video itself")
        cam = self
        for _ in range(k):
            K, d = cam.K, cam.dist.copy()
            turned = np.array([[K[1, 1], 0.0, cam.height - 1 - K[1, 2]], [0.0, K[0, 0], K[0, 2]], [0.0, 0.0, 1.0]])
            d[2], d[3] = cam.dist[3], -cam.dist[2]
            # (readout 0: a turned image's rows are not read top to bottom, which the row model assumes)
            cam = Camera(turned, d, cam.height, cam.width, 0.0)
        return cam

    # -- files -----------------------------------------------------------------
    def to_dict(self) -> dict:
        """The `camera` block of session.json."""
        d = {"width": self.width, "height": self.height, "K": self.K.tolist(), "dist": self.dist.tolist()}
        if self.readout > 0:
            d["readout"] = self.readout
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera") -> "Camera":
        """From a session.json `camera` block; errors name the field (`camera.K`, ...)."""
        if not isinstance(d, dict):
            raise CalibrationError(f"{where}: must be an object with width, height, K and dist")
        for key in ("width", "height", "K"):
            if key not in d:
                raise CalibrationError(f"{where}.{key}: missing")
        try:
            K = np.asarray(d["K"], dtype=float)
        except (TypeError, ValueError):
            raise CalibrationError(f"{where}.K: must be a 3x3 array of numbers") from None
        if K.shape != (3, 3):
            raise CalibrationError(f"{where}.K: must be 3x3, got shape {K.shape}")
        try:
            dist = np.asarray(d.get("dist", [0, 0, 0, 0, 0]), dtype=float)
        except (TypeError, ValueError):
            raise CalibrationError(f"{where}.dist: must be a list of numbers") from None
        for key in ("width", "height"):
            if not isinstance(d[key], int) or isinstance(d[key], bool) or d[key] <= 0:
                raise CalibrationError(f"{where}.{key}: must be a positive integer, got {d[key]!r}")
        readout = d.get("readout", 0.0)
        if not isinstance(readout, (int, float)) or isinstance(readout, bool) or not 0 <= readout < 1:
            raise CalibrationError(f"{where}.readout: must be a rolling-shutter readout time in seconds "
                                   f"(0 <= readout < 1, e.g. 0.03), got {readout!r}")
        try:
            return cls(K, dist, d["width"], d["height"], float(readout))
        except CalibrationError as e:
            raise CalibrationError(f"{where}: {e}") from None

    def save_yaml(self, path: str | Path, extra: dict | None = None) -> None:
        """Write OpenCV FileStorage YAML (camera_matrix, distortion_coefficients, image_width, image_height)."""
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        try:
            fs.write("image_width", self.width)
            fs.write("image_height", self.height)
            fs.write("camera_matrix", self.K)
            fs.write("distortion_coefficients", self.dist.reshape(-1, 1))
            for k, v in (extra or {}).items():
                fs.write(k, v)
        finally:
            fs.release()

    @classmethod
    def load_yaml(cls, path: str | Path, image_size: tuple[int, int] | None = None) -> "Camera":
        """Read a calibration file (tracking.calibration_file: OpenCV FileStorage YAML/XML/JSON with
        camera_matrix / distortion_coefficients or K / D, or a ROS camera_info YAML). `image_size` (width,
        height in pixels) is used when the file states none; without it such a file is refused. No
        distortion coefficients = no distortion. Raises CalibrationError naming the file and the field."""
        return cls.load_file(path, image_size)[0]

    @classmethod
    def load_file(cls, path: str | Path, image_size: tuple[int, int] | None = None) -> tuple["Camera", list[str]]:
        """As load_yaml, with the notes a user should read: how the file was read when it is not arapp's own
        layout, and where the image size came from when the file has none."""
        f = read_calibration_file(path)
        notes = []
        if not f.layout.startswith("OpenCV FileStorage (camera_matrix"):
            notes.append(f"{f.path}: read as {f.layout}")
        if f.width is None:
            if image_size is None:
                raise CalibrationError(f"{f.path}: image_width, image_height: missing (the image size in pixels "
                                       "the calibration is for); add them, or use the file with a video or camera "
                                       "that gives the size")
            width, height = int(image_size[0]), int(image_size[1])
            notes.append(f"{f.path} gives no image size; taken as the frames' {width}x{height}")
        else:
            width, height = f.width, f.height
        dist = f.dist if f.dist.size else np.zeros(5)
        try:
            return cls(f.K, dist, width, height), notes
        except CalibrationError as e:
            raise CalibrationError(f"{f.path}: {e}") from None
