"""Reading camera calibration files in the conventions people have (no Camera here: tracking.camera
builds one from what this returns).

Read through cv2.FileStorage (YAML, XML or JSON):

- OpenCV's own layout (what `arapp calibrate` and OpenCV's samples write): `camera_matrix` and
  `distortion_coefficients` as `!!opencv-matrix`, `image_width`, `image_height`;
- the same with the short names `K` / `D` (or `dist_coeffs`, `cameraMatrix` / `distCoeffs`), as
  `!!opencv-matrix` or as plain lists (9 numbers, or 3 rows of 3);
- a ROS `camera_info` YAML (camera_calibration's output): `camera_matrix` and
  `distortion_coefficients` as `{rows, cols, data}` maps, `distortion_model` (plumb_bob or
  rational_polynomial), `image_width` / `image_height`; a `camera_info` message dumped as YAML
  (`K`/`D` or `k`/`d` lists with `width` / `height`) reads too.

The image size may be missing (many hand-written files have none): `width`/`height` are then None
and the caller takes the size of the frames the calibration is used on (and says so).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracking.errors import CalibrationError

# key spellings, most common first
MATRIX_KEYS = ("camera_matrix", "K", "k", "cameraMatrix")
DIST_KEYS = ("distortion_coefficients", "D", "d", "dist_coeffs", "distCoeffs")
SIZE_KEYS = (("image_width", "image_height"), ("width", "height"))
# ROS distortion models that are OpenCV's pinhole distortion (k1 k2 p1 p2 k3 [k4 k5 k6])
ROS_PINHOLE_MODELS = ("plumb_bob", "rational_polynomial")

EXPECTED = ("expected camera_matrix (or K) and distortion_coefficients (or D, dist_coeffs), with image_width "
            "and image_height: OpenCV FileStorage as `arapp calibrate` writes, or a ROS camera_info YAML")


@dataclass
class CalibrationFile:
    """What a calibration file holds: K (3x3), dist (OpenCV order, may be empty), the image size in pixels
    (None when the file gives none), and `layout`, the convention it was read as (for messages)."""

    path: Path
    K: np.ndarray
    dist: np.ndarray
    width: int | None
    height: int | None
    layout: str


def read_calibration_file(path: str | Path) -> CalibrationFile:
    """Read `path` (see the module doc). Raises CalibrationError naming the file, and the field or the
    keys it expected."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"calibration file {path} does not exist")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as e:
        # OpenCV's parser reports a syntax error as cv2.error, or (through the Python binding of the
        # constructor) as a SystemError whose cause is that cv2.error.
        raise CalibrationError(f"{path}: not a calibration file OpenCV can read ({cv_message(e)}); "
                               f"{EXPECTED}") from None
    try:
        if not fs.isOpened():
            raise CalibrationError(f"{path}: cannot be read as a calibration file; {EXPECTED}")
        root = fs.root()
        keys = list(root.keys()) if root.isMap() else []
        mkey = next((k for k in MATRIX_KEYS if k in keys), None)
        if mkey is None:
            found = ", ".join(keys[:12]) if keys else "none"
            raise CalibrationError(f"{path}: no camera matrix; {EXPECTED} (the file has keys: {found})")
        K, kind = _matrix(fs.getNode(mkey), mkey, path)
        if K.size != 9:
            raise CalibrationError(f"{path}: {mkey}: must be 3x3 (9 numbers), got {_shape(K)}")
        K = K.reshape(3, 3)
        dkey = next((k for k in DIST_KEYS if k in keys), None)
        dist = np.zeros(0) if dkey is None else _matrix(fs.getNode(dkey), dkey, path)[0].ravel()
        model = fs.getNode("distortion_model")
        ros = kind == "ros" or not model.empty()
        if not model.empty():
            name = model.string() if model.isString() else ""
            if name not in ROS_PINHOLE_MODELS:
                raise CalibrationError(f"{path}: distortion_model {name or '(not a name)'!r} is not supported; "
                                       f"arapp's camera takes {' or '.join(ROS_PINHOLE_MODELS)} (OpenCV's pinhole "
                                       "distortion); a fisheye lens needs a pinhole calibration")
        width, height = _size(fs, keys, path)
        layout = ("ROS camera_info" if ros else "OpenCV FileStorage") + f" ({mkey}" + (f", {dkey})" if dkey else ")")
        return CalibrationFile(path, K, dist, width, height, layout)
    finally:
        fs.release()


def _matrix(node, key: str, path: Path) -> tuple[np.ndarray, str]:
    """(finite float array, layout) of an `!!opencv-matrix` ('opencv'), a ROS {rows, cols, data} map ('ros') or
    a list of numbers / of rows ('list')."""
    if node.isMap():
        if not node.getNode("dt").empty():
            try:
                mat, kind = node.mat(), "opencv"
            except cv2.error:
                mat = None
            if mat is None:
                raise CalibrationError(f"{path}: {key}: not a readable !!opencv-matrix (rows, cols, dt, data)")
        else:
            data = node.getNode("data")
            if data.empty() or not data.isSeq():
                raise CalibrationError(f"{path}: {key}: a map needs rows, cols and data (ROS camera_info) "
                                       "or dt too (!!opencv-matrix)")
            mat, kind = _numbers(data, key, path), "ros"
            rows, cols = node.getNode("rows"), node.getNode("cols")
            if not rows.empty() and not cols.empty() and int(rows.real()) * int(cols.real()) != mat.size:
                raise CalibrationError(f"{path}: {key}: rows x cols is {int(rows.real())} x {int(cols.real())} "
                                       f"but data holds {mat.size} numbers")
    elif node.isSeq():
        mat, kind = _numbers(node, key, path), "list"
    else:
        raise CalibrationError(f"{path}: {key}: must be a matrix (!!opencv-matrix, a ROS rows/cols/data map, "
                               "or a list of numbers)")
    mat = np.asarray(mat, dtype=float)
    if not np.all(np.isfinite(mat)):
        raise CalibrationError(f"{path}: {key}: holds a value that is not a finite number")
    return mat, kind


def _numbers(seq, key: str, path: Path) -> np.ndarray:
    """The numbers of a FileStorage sequence, flattened (rows of a nested list one after another)."""
    out: list[float] = []
    for i in range(seq.size()):
        item = seq.at(i)
        if item.isSeq():
            out.extend(_numbers(item, key, path).tolist())
        elif item.isReal() or item.isInt():
            out.append(item.real())
        else:
            raise CalibrationError(f"{path}: {key}: item {i} is not a number")
    return np.asarray(out, dtype=float)


def _shape(a: np.ndarray) -> str:
    return f"{a.shape[0]}x{a.shape[1]}" if a.ndim == 2 else f"{a.size} numbers"


def _size(fs, keys: list[str], path: Path) -> tuple[int | None, int | None]:
    """The image size the file states (pixels), or (None, None) when it states none."""
    for wkey, hkey in SIZE_KEYS:
        have = [k for k in (wkey, hkey) if k in keys]
        if not have:
            continue
        if len(have) == 1:
            other = hkey if have[0] == wkey else wkey
            raise CalibrationError(f"{path}: {other}: missing (the file gives {have[0]}; the image size in "
                                   "pixels the calibration is for needs both, or neither to take the video's)")
        size = []
        for key in (wkey, hkey):
            node = fs.getNode(key)
            value = node.real() if node.isReal() or node.isInt() else float("nan")
            if not (np.isfinite(value) and value == int(value) and 0 < value <= 100_000):
                raise CalibrationError(f"{path}: {key}: must be a positive whole number of pixels")
            size.append(int(value))
        return size[0], size[1]
    return None, None


def cv_message(exc: BaseException) -> str:
    """The short text of an OpenCV error (the cv2.error behind a SystemError when there is one)."""
    cause = exc.__cause__ or exc.__context__
    err = cause if isinstance(cause, cv2.error) else exc
    # Parsing errors read "FILE(LINE): what"; OpenCV versions put it in `err` or in `func`.
    parts = [str(getattr(err, name, "") or "") for name in ("err", "func")]
    located = [p for p in parts if re.search(r"\(\d+\): ", p)]
    text = located[0] if located else max(parts, key=len) or str(err)
    text = re.sub(r"^.*\((\d+)\): ", r"line \1: ", text.strip())
    return " ".join(text.split())[:200]
