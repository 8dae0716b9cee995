"""What a webcam does to the light reaching it, as small pure functions (images are float32 BGR, 8-bit levels).

The renderer (tracking.synth.renderer) applies them in a camera's order:
optics (vignetting, defocus) -> exposure gain (auto-exposure) -> sensor noise
(shot + read, in electrons) -> white balance -> 8-bit quantisation -> chroma
subsampling (a YUYV 4:2:2 link) -> JPEG (an MJPEG webcam). Motion blur and
rolling shutter happen earlier, while the scene is rendered (the renderer
integrates sub-frame poses and gives every sensor row its own time,
`row_times`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


# -- rolling shutter ----------------------------------------------------------------------------------
def row_times(t: float, rows: int, readout_s: float) -> np.ndarray:
    """Exposure-centre time (seconds) of each of `rows` image rows of a frame stamped t.

    Rows are read top to bottom over `readout_s` seconds; the frame's timestamp is the time of the
    middle of the image (row centre (rows / 2) in pixel-edge coordinates), so the ground-truth pose of
    a frame is the pose of its centre row: row y (centre y + 0.5) is exposed at
    t + readout_s * ((y + 0.5) / rows - 0.5).
    """
    y = np.arange(rows, dtype=np.float64)
    return t + readout_s * ((y + 0.5) / rows - 0.5)


# -- optics ---------------------------------------------------------------------------------------------
def vignette_factor(width: int, height: int, cx: float, cy: float, strength: float) -> np.ndarray:
    """Brightness factor (H, W) float32: 1 - strength * r^2, r the distance to the principal point
    divided by the distance from the principal point to the image corner (pixel centres)."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx ** 2 + cy ** 2)
    return (1.0 - strength * r2).astype(np.float32)


def defocus_kernel(radius_px: float) -> np.ndarray:
    """Normalised pillbox (uniform disc) point-spread function of radius `radius_px` output pixels.

    Pixel weights are the disc's area inside each pixel, estimated on a 16 x 16 sub-pixel grid,
    so fractional radii are exact to the sub-grid; a radius under 0.05 px is the identity (1x1).
    """
    if radius_px < 0.05:
        return np.ones((1, 1), np.float32)
    half = int(math.ceil(radius_px + 0.5))
    n = 2 * half + 1
    sub = 16
    c = (np.arange(n * sub) + 0.5) / sub - half - 0.5
    xx, yy = np.meshgrid(c, c)
    inside = (xx ** 2 + yy ** 2 <= radius_px ** 2).astype(np.float64)
    k = inside.reshape(n, sub, n, sub).sum(axis=(1, 3))
    return (k / k.sum()).astype(np.float32)


def defocus(img: np.ndarray, radius_px: float) -> np.ndarray:
    """The image through a pillbox PSF of `radius_px` pixels (edges replicated)."""
    k = defocus_kernel(radius_px)
    if k.shape == (1, 1):
        return img
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REPLICATE)


# -- exposure ---------------------------------------------------------------------------------------------
def luminance(img: np.ndarray) -> float:
    """Mean Rec.601 luma of a BGR image (8-bit levels), what a webcam's auto-exposure meters."""
    m = img.reshape(-1, 3).mean(axis=0)
    return float(0.114 * m[0] + 0.587 * m[1] + 0.299 * m[2])


class AutoExposure:
    """A webcam's auto-exposure: a gain that walks toward `target` mean luma one frame late.

    Frame n is taken with gain g_n; after it, the camera meters the frame's mean luma L_n (before
    noise and clipping) and sets g_{n+1} = clip(g_n * (target / L_n) ** speed, min_gain, max_gain).
    speed 1 would settle in one frame; webcams use ~0.1-0.3 (a visible drift after a scene change).
    """

    def __init__(self, target: float = 110.0, speed: float = 0.2, initial_gain: float = 1.0,
                 min_gain: float = 0.25, max_gain: float = 4.0):
        self.target, self.speed = float(target), float(speed)
        self.initial_gain = float(initial_gain)
        self.min_gain, self.max_gain = float(min_gain), float(max_gain)
        self.gain = self.initial_gain

    def reset(self) -> None:
        self.gain = self.initial_gain

    def update(self, metered_luma: float) -> float:
        """Meter a frame taken at the current gain; returns the gain for the next frame."""
        ratio = self.target / max(float(metered_luma), 1e-3)
        self.gain = float(np.clip(self.gain * ratio ** self.speed, self.min_gain, self.max_gain))
        return self.gain


def white_balance_gains(t: float, amplitude: float, period: float, phase: float = 0.0) -> np.ndarray:
    """Per-channel (B, G, R) gains of a drifting auto white balance at time t (seconds).

    The colour temperature estimate wanders: blue gain 1 + a sin(2 pi t / period + phase), red gain
    1 - a sin(...), green fixed at 1.
    """
    s = amplitude * math.sin(2 * math.pi * t / period + phase)
    return np.array([1.0 + s, 1.0, 1.0 - s], np.float32)


# -- sensor ----------------------------------------------------------------------------------------------
def sensor_noise(img: np.ndarray, rng: np.random.Generator, full_well: float, read_noise: float,
                 gain: float = 1.0) -> np.ndarray:
    """Shot and read noise of a sensor whose full well (`full_well` electrons) maps to level 255 at gain 1.

    `img` is the image after the gain (8-bit levels). A pixel at level L collected L / gain * full_well
    / 255 electrons (Poisson: variance = mean, approximated as Gaussian), read noise `read_noise` is in
    levels at gain 1; both are amplified by the gain, so the variance in output levels is
    gain * L * 255 / full_well + (gain * read_noise)^2.
    """
    level = np.clip(img, 0.0, None)
    var = gain * level * (255.0 / full_well) + (gain * read_noise) ** 2
    return img + rng.standard_normal(img.shape).astype(np.float32) * np.sqrt(var).astype(np.float32)


# -- link and codec ---------------------------------------------------------------------------------------
def chroma_subsample_422(img: np.ndarray) -> np.ndarray:
    """uint8 BGR through YUYV 4:2:2: each horizontal pixel pair shares the mean of its Cr and Cb."""
    ycc = cv2.cvtColor(img, cv2.COLOR_BGR2YCrCb).astype(np.float32)
    w2 = ycc.shape[1] // 2 * 2
    pair = ycc[:, :w2, 1:].reshape(ycc.shape[0], w2 // 2, 2, 2).mean(axis=2, keepdims=True)
    ycc[:, :w2, 1:] = np.repeat(pair, 2, axis=2).reshape(ycc.shape[0], w2, 2)
    return cv2.cvtColor(np.clip(np.rint(ycc), 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2BGR)


def jpeg_roundtrip(img: np.ndarray, quality: int) -> np.ndarray:
    """uint8 BGR encoded as JPEG at `quality` and decoded again (block and ringing artefacts)."""
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not JPEG-encode a synthetic frame")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


def frame_jpeg_quality(spec, rng: np.random.Generator) -> int | None:
    """This frame's JPEG quality: a number, or [low, high] drawn per frame (a webcam's MJPEG rate control)."""
    if not spec:
        return None
    if isinstance(spec, (list, tuple)):
        return int(rng.integers(int(spec[0]), int(spec[1]) + 1))
    return int(spec)
