"""The one camera model: pinhole intrinsics with OpenCV's lens distortion.

Pixel centres are at integer coordinates (OpenCV's convention). Points are in
the camera frame (x right, y down, z forward), metres.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

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
    def load_yaml(cls, path: str | Path) -> "Camera":
        """Read an OpenCV calibration file (YAML/XML/JSON FileStorage), as written by OpenCV's own tools.

        Needs camera_matrix (3x3 !!opencv-matrix), image_width and image_height (pixels); distortion_coefficients
        is optional (none = no distortion). Raises CalibrationError naming the file and the field.
        """
        path = Path(path)
        if not path.is_file():
            raise CalibrationError(f"calibration file {path} does not exist")
        try:
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        except (cv2.error, SystemError) as e:
            # OpenCV's parser reports a syntax error as cv2.error, or (through the Python binding of the
            # constructor) as a SystemError whose cause is that cv2.error.
            raise CalibrationError(f"{path}: not a valid OpenCV calibration file ({_cv_message(e)}); "
                                   "write it with 'arapp calibrate' or cv2.FileStorage") from None
        try:
            if not fs.isOpened():
                raise CalibrationError(f"{path}: cannot be read as OpenCV FileStorage YAML")
            K = _read_matrix(fs, "camera_matrix", path)
            dist = _read_matrix(fs, "distortion_coefficients", path, required=False)
            size = {}
            for key in ("image_width", "image_height"):
                node = fs.getNode(key)
                if node.empty():
                    raise CalibrationError(f"{path}: {key}: missing (the image size in pixels the calibration is for)")
                value = node.real() if node.isReal() or node.isInt() else float("nan")
                if not (np.isfinite(value) and value == int(value) and 0 < value <= 100_000):
                    raise CalibrationError(f"{path}: {key}: must be a positive whole number of pixels")
                size[key] = int(value)
            if K.shape != (3, 3):
                raise CalibrationError(f"{path}: camera_matrix: must be 3x3, got {K.shape[0]}x{K.shape[1]}")
            try:
                return cls(K, np.zeros(5) if dist is None else dist.ravel(), size["image_width"], size["image_height"])
            except CalibrationError as e:
                raise CalibrationError(f"{path}: {e}") from None
        finally:
            fs.release()


def _cv_message(exc: BaseException) -> str:
    """The short text of an OpenCV error (the cv2.error behind a SystemError when there is one)."""
    cause = exc.__cause__ or exc.__context__
    err = cause if isinstance(cause, cv2.error) else exc
    # Parsing errors read "FILE(LINE): what"; OpenCV versions put it in `err` or in `func`.
    parts = [str(getattr(err, name, "") or "") for name in ("err", "func")]
    located = [p for p in parts if re.search(r"\(\d+\): ", p)]
    text = located[0] if located else max(parts, key=len) or str(err)
    text = re.sub(r"^.*\((\d+)\): ", r"line \1: ", text.strip())
    return " ".join(text.split())[:200]


def _read_matrix(fs, key: str, path: Path, required: bool = True) -> np.ndarray | None:
    """A finite matrix stored as an !!opencv-matrix under `key` (None when absent and not required)."""
    node = fs.getNode(key)
    if node.empty():
        if required:
            raise CalibrationError(f"{path}: {key}: missing")
        return None
    try:
        mat = node.mat()
    except cv2.error:  # a plain list or a scalar, not a matrix map
        mat = None
    if mat is None:
        raise CalibrationError(f"{path}: {key}: must be an !!opencv-matrix (rows, cols, dt, data)")
    mat = np.asarray(mat, dtype=float)
    if not np.all(np.isfinite(mat)):
        raise CalibrationError(f"{path}: {key}: holds a value that is not a finite number")
    return mat
