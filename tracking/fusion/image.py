"""A frame's image made ready for tracking: at the camera's size, as BGR (for the anchors) and grey."""

from __future__ import annotations

import cv2
import numpy as np

MIN_SIDE = 48  # pixels: smaller frames carry nothing trackable


def prepare(image, size: tuple[int, int]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(image for the anchors, grey image) at the camera's `size` (width, height), or (None, None) if
    unusable. Any dtype (floats in 0..1 or 0..255), grey, BGR or BGRA; another resolution of the same
    aspect ratio is resized."""
    if image is None:
        return None, None
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.shape[0] < MIN_SIDE or img.shape[1] < MIN_SIDE:
        return None, None
    if img.dtype != np.uint8:
        if np.issubdtype(img.dtype, np.floating):
            img = np.clip(np.nan_to_num(img) * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
        else:
            img = np.clip(img, 0, 255).astype(np.uint8)
    if img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] != 3:
        return None, None
    h, w = img.shape[:2]
    if (w, h) != tuple(size):
        # another resolution of the same lens only if the aspect ratio agrees
        if abs(w / h - size[0] / size[1]) > 0.02:
            return None, None
        img = cv2.resize(img, tuple(size), interpolation=cv2.INTER_LINEAR)
    gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    bgr = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    return bgr, gray


def has_content(gray) -> bool:
    """False for a frame that is black, blown out or blank (nothing to track in it)."""
    if gray is None:
        return False
    mean, std = cv2.meanStdDev(gray[::8, ::8])   # a seventh of numpy's mean + std here
    m, s = float(mean[0, 0]), float(std[0, 0])
    return 6.0 < m < 250.0 and s > 2.0
