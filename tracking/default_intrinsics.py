"""An approximate camera for a source that has no calibration: pinhole, no distortion.

A webcam or a plain video opened without a calibration file still needs
intrinsics for the tracker to draw anything. This guess is a pinhole camera
with square pixels, the principal point at the image centre and the focal
length from a typical webcam's horizontal field of view, taken across the
image's long side: a portrait video (a phone held upright, which OpenCV turns
by the file's rotation tag) is the same sensor turned, its field of view
across the width the narrower one. Sizes and distances
measured with it are approximate (a 10 degree error in the field of view is
~15 % in scale); calibrating the camera (`arapp calibrate`, or the GUI's
calibration wizard) replaces it.

Why 65 degrees: spec sheets of common webcams give 45-70 degrees across the
width (Logitech C270: 55 deg diagonal = ~45 deg horizontal at 4:3; C920:
78 deg diagonal = ~70 deg horizontal at 16:9; laptop cameras mostly 60-70).
65 sits in the range most users have; no recording was used to choose it.

Pixel centres are at integer coordinates (tracking.camera's convention), so
the centre of a W x H image is ((W - 1) / 2, (H - 1) / 2).
"""

from __future__ import annotations

import math

import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError

DEFAULT_HFOV_DEG = 65.0
"""Field of view across the long side (horizontal, landscape) assumed for an uncalibrated camera, degrees."""

ESTIMATED_NOTE = "uncalibrated (estimated): sizes approximate, calibrate for accuracy"


def estimated_camera(width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG) -> Camera:
    """A pinhole Camera for a `width` x `height` image (pixels) whose field of view across its long side is
    `hfov_deg` degrees: fx = fy = (max(width, height) / 2) / tan(hfov / 2), principal point at the image
    centre, zero distortion."""
    integers = isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))
    if not integers or width <= 0 or height <= 0:
        raise CalibrationError(f"an estimated camera needs a positive integer image size, got {width}x{height}")
    if not 1.0 <= float(hfov_deg) <= 170.0:
        raise CalibrationError(f"horizontal field of view {hfov_deg} deg: use a value between 1 and 170 degrees")
    f = (max(width, height) / 2.0) / math.tan(math.radians(float(hfov_deg)) / 2.0)
    K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return Camera(K, np.zeros(5), int(width), int(height))


def is_estimated(camera: Camera | None, hfov_deg: float = DEFAULT_HFOV_DEG) -> bool:
    """True when `camera` is exactly the estimate for its own image size (so the UI can say so
    without the source having to carry a flag across processes)."""
    if camera is None:
        return False
    guess = estimated_camera(camera.width, camera.height, hfov_deg)
    return bool(np.allclose(camera.K, guess.K, rtol=0, atol=1e-9) and not camera.has_distortion)


def source_size(source) -> tuple[int, int] | None:
    """(width, height) of the frames a tracking.sources source delivers, when it knows them before
    the first frame (video files: .width/.height; V4L2: .granted); else None."""
    w, h = getattr(source, "width", None), getattr(source, "height", None)
    if isinstance(w, int) and isinstance(h, int):
        return w, h
    granted = getattr(source, "granted", None)
    if isinstance(granted, dict) and granted.get("width") and granted.get("height"):
        return int(granted["width"]), int(granted["height"])
    return None


def attach_estimated_camera(source, hfov_deg: float = DEFAULT_HFOV_DEG) -> bool:
    """Give a source without calibration the estimated camera; returns True when it did.

    Sets `source.camera_estimated = True` so callers can show "uncalibrated (estimated)".
    A source with a camera (a calibration file, a recording, a DepthAI device) is left alone.
    This is the hook `tracking.sources.open_source` (or its caller) calls on a just-opened source.
    """
    if source.has_camera:
        return False
    size = source_size(source)
    if size is None:
        return False
    source._camera = estimated_camera(size[0], size[1], hfov_deg)
    source.camera_estimated = True
    return True
