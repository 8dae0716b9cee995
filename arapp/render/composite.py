"""Alpha compositing and lens-distortion warping of overlay crops (numpy/OpenCV, no per-pixel Python).

Overlay crops are premultiplied RGBA uint8 (colour already multiplied by alpha), which is what the
GPU produces with premultiplied blending and MSAA resolve, and what interpolates correctly when
warped. The public `render()` result is straight (non-premultiplied) RGBA.
"""

from __future__ import annotations

import cv2
import numpy as np


def over_bgr(frame_bgr: np.ndarray, premul_rgba: np.ndarray, x0: int, y0: int) -> None:
    """Composite a premultiplied RGBA crop over `frame_bgr` in place, with its top-left at (x0, y0).

    out = fg + round(bg * (255 - alpha) / 255), saturated at 255, only inside the crop; pixels with
    alpha 0 are left bit-exact. The crop must lie inside the frame.

    Integer maths through OpenCV's vectorised uint8 kernels: cv2.multiply rounds bg * (255 - alpha) / 255
    to the nearest integer (never a tie: the quotient is at least 1/510 from any .5) and cv2.add
    saturates, which is exactly the float formula `clip(bg * (1 - alpha / 255) + fg + 0.5)` truncated,
    at a fraction of the cost (no float32 copies of the crop).
    """
    h, w = premul_rgba.shape[:2]
    roi = frame_bgr[y0:y0 + h, x0:x0 + w]  # a view: the kernels below write into the frame
    inv = cv2.bitwise_not(premul_rgba[..., 3])  # 255 - alpha
    bg = cv2.multiply(roi, cv2.merge((inv, inv, inv)), scale=1.0 / 255.0)
    fg = cv2.cvtColor(premul_rgba, cv2.COLOR_RGBA2BGR)
    if roi.strides[1:] == (3, 1):
        cv2.add(fg, bg, dst=roi)
    else:  # a frame OpenCV cannot write into (e.g. a channel view of BGRA): add, then copy in
        roi[...] = cv2.add(fg, bg)


def over_scaled(picture: np.ndarray, premul_rgba: np.ndarray, x0: int, y0: int, scale: tuple[float, float]) -> None:
    """Composite a premultiplied RGBA crop of a frame, its top-left at frame pixel (x0, y0), in place over
    `picture`: that frame scaled by `scale` (sx, sy) as cv2.resize scales (pixel centres: display x + 0.5 =
    (frame x + 0.5) * sx), in the screen's 32-bit B, G, R, 255 order (arapp.engine.processor.to_bgra, on a
    little-endian machine). The crop is resampled bilinearly onto the picture's pixels (transparent beyond its
    edges) and laid over them as `over_bgr` does; the picture's fourth byte stays 255.

    The same picture as scaling the frame with the crop composited on it, up to the resampling's rounding
    (premultiplied colours interpolate linearly), for scales of 1/2 and up (below, cv2.resize averages areas)."""
    sx, sy = scale
    h, w = premul_rgba.shape[:2]
    ph, pw = picture.shape[:2]
    # the picture's pixels whose centres fall within the crop's pixel area, one more each side for the
    # bilinear blend into transparency
    bx0, by0 = max(int(np.floor((x0 - 1) * sx)), 0), max(int(np.floor((y0 - 1) * sy)), 0)
    bx1, by1 = min(int(np.ceil((x0 + w + 1) * sx)), pw), min(int(np.ceil((y0 + h + 1) * sy)), ph)
    if bx1 <= bx0 or by1 <= by0:
        return
    # picture pixel (u, v) of the box shows crop pixel ((u + bx0 + 0.5) / sx - 0.5 - x0, ...)
    to_crop = np.array([[1.0 / sx, 0.0, (bx0 + 0.5) / sx - 0.5 - x0], [0.0, 1.0 / sy, (by0 + 0.5) / sy - 0.5 - y0]])
    box = cv2.warpAffine(premul_rgba, to_crop, (bx1 - bx0, by1 - by0), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
    fg = cv2.cvtColor(box, cv2.COLOR_RGBA2BGRA)   # premultiplied: its alpha + the rest of 255 makes 255 again
    inv = cv2.bitwise_not(box[..., 3])
    roi = picture[by0:by1, bx0:bx1]   # a view: the kernels below write into the picture
    bg = cv2.multiply(roi, cv2.merge((inv, inv, inv, inv)), scale=1.0 / 255.0)
    cv2.add(fg, bg, dst=roi)


def unpremultiply(premul_rgba: np.ndarray) -> np.ndarray:
    """Straight-alpha RGBA uint8 from premultiplied RGBA uint8 (colour undefined -> 0 where alpha is 0)."""
    a = premul_rgba[..., 3:4].astype(np.float32)
    rgb = premul_rgba[..., :3].astype(np.float32) * (255.0 / np.maximum(a, 1.0))
    out = np.empty_like(premul_rgba)
    out[..., :3] = np.clip(rgb + 0.5, 0, 255).astype(np.uint8)
    out[..., 3] = premul_rgba[..., 3]
    out[..., :3][premul_rgba[..., 3] == 0] = 0
    return out


def warp_crop(premul_rgba: np.ndarray, src_xy: tuple[np.ndarray, np.ndarray], src_origin: tuple[int, int]) -> np.ndarray:
    """Resample an undistorted crop into distorted pixels.

    `src_xy` = (map_x, map_y) float32 (h, w): for each output (distorted) pixel, its position in the
    undistorted image (Camera.distort_maps() sliced to the output region); `src_origin` = (x0, y0) of
    the undistorted crop. Bilinear, transparent outside the crop.
    """
    mx = src_xy[0] - np.float32(src_origin[0])
    my = src_xy[1] - np.float32(src_origin[1])
    return cv2.remap(premul_rgba, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))

