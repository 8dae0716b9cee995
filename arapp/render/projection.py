"""Camera maths for the overlay: OpenCV intrinsics -> OpenGL matrices, depth range, pixel regions.

Conventions (docs/domain.md §2): OpenCV camera frame x right, y down, z forward; OpenGL
(pyrender) camera frame x right, y up, z backward; the two differ by diag(1, -1, -1).
Pixel centres are at integer coordinates (OpenCV), so pixel column i covers
[i - 0.5, i + 0.5). The projection matrix maps the undistorted pinhole pixel
`u = fx x/z + cx`, `v = fy y/z + cy` exactly as cv2.projectPoints does (which
ignores the skew entry K[0, 1], so this does too).

A render covers a crop of the (undistorted) image plane: pixel rectangle
`(x0, y0, w, h)` holding pixel centres x0..x0+w-1 and y0..y0+h-1; x0, y0 may be
negative or beyond the image (distortion pulls content in from outside it).
"""

from __future__ import annotations

import cv2
import numpy as np

#: OpenCV camera axes -> OpenGL camera axes.
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def gl_view(camera_from_model: np.ndarray) -> np.ndarray:
    """4x4 OpenGL model-view matrix (GL camera from model) for an OpenCV `camera_from_model`."""
    return CV_TO_GL @ np.asarray(camera_from_model, dtype=float)


def gl_projection(K: np.ndarray, crop: tuple[int, int, int, int], near: float, far: float) -> np.ndarray:
    """4x4 OpenGL projection for the pixel crop `(x0, y0, w, h)` of a camera with intrinsics K.

    Takes GL-camera points (x_gl, y_gl, z_gl) = (x, -y, -z). NDC x = -1..1 spans the crop's columns
    [x0 - 0.5, x0 + w - 0.5]. NDC y = -1..1 spans the crop's rows from the *top* (v = y0 - 0.5) down,
    so glReadPixels (which returns the bottom GL row first) yields the rows in image order without a
    flip; this mirrors y, so triangle winding is reversed (the renderer does not cull faces).
    """
    x0, y0, w, h = crop
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    P = np.zeros((4, 4))
    # clip_x / w_c = (2/w) (u - x0 + 0.5) - 1, with u = fx x/z + cx, z = -z_gl, w_c = -z_gl
    P[0, 0] = 2.0 * fx / w
    P[0, 2] = -2.0 * (cx - x0 + 0.5) / w + 1.0
    # clip_y / w_c = (2/h) (v - y0 + 0.5) - 1, with v = fy y/z + cy = fy y_gl / z_gl + cy
    P[1, 1] = -2.0 * fy / h
    P[1, 2] = -2.0 * (cy - y0 + 0.5) / h + 1.0
    P[2, 2] = -(far + near) / (far - near)
    P[2, 3] = -2.0 * far * near / (far - near)
    P[3, 2] = -1.0
    return P


def near_far(camera_from_model: np.ndarray, center: np.ndarray, radius: float, min_near: float) -> tuple[float, float]:
    """Depth range (OpenCV z, model->camera units) tightly enclosing a bounding sphere (model frame).

    `center`, `radius` bound everything drawn (mesh, lines, shadow). The near plane never goes
    below `min_near` (a model reaching behind the camera is clipped there) and keeps far/near
    bounded so the 24-bit depth buffer keeps its precision.
    """
    T = np.asarray(camera_from_model, dtype=float)
    c = T[:3, :3] @ center + T[:3, 3]
    scale = float(np.cbrt(abs(np.linalg.det(T[:3, :3])))) or 1.0
    r = radius * scale * 1.01 + 1e-9
    far = max(c[2] + r, 2.0 * min_near)
    near = max(c[2] - r, min_near, far * 1e-5)
    return float(near), float(far)


def pixel_bounds(points_camera: np.ndarray, K: np.ndarray, near: float) -> tuple[float, float, float, float] | None:
    """(u_min, v_min, u_max, v_max) of the undistorted pinhole projection of camera-frame points (OpenCV).

    Returns None when no point is in front of the camera, and the unbounded box (+-inf) when some
    point lies behind the near plane (its projection is not a bounded region of the image plane).
    """
    p = np.asarray(points_camera, dtype=float).reshape(-1, 3)
    z = p[:, 2]
    if not np.any(z > near):
        return None
    if np.any(z <= near):
        return (-np.inf, -np.inf, np.inf, np.inf)
    u = K[0, 0] * p[:, 0] / z + K[0, 2]
    v = K[1, 1] * p[:, 1] / z + K[1, 2]
    return float(u.min()), float(v.min()), float(u.max()), float(v.max())


def crop_from_bounds(bounds, limits: tuple[int, int, int, int], pad: int) -> tuple[int, int, int, int] | None:
    """Integer pixel crop (x0, y0, w, h) covering `bounds` (u_min, v_min, u_max, v_max) plus `pad` pixels,
    clipped to `limits` (x0, y0, w, h). None when the two do not overlap."""
    u0, v0, u1, v1 = bounds
    lx0, ly0, lw, lh = limits
    x0 = max(int(np.floor(max(u0, -1e9))) - pad, lx0)
    y0 = max(int(np.floor(max(v0, -1e9))) - pad, ly0)
    x1 = min(int(np.ceil(min(u1, 1e9))) + pad, lx0 + lw - 1)
    y1 = min(int(np.ceil(min(v1, 1e9))) + pad, ly0 + lh - 1)
    if x1 < x0 or y1 < y0:
        return None
    return x0, y0, x1 - x0 + 1, y1 - y0 + 1


def distort_pixels(pixels: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Distorted pixel positions (n, 2) of undistorted pinhole pixels (n, 2) of the same K (cv2.projectPoints)."""
    px = np.asarray(pixels, dtype=float).reshape(-1, 2)
    x = (px[:, 0] - K[0, 2]) / K[0, 0]
    y = (px[:, 1] - K[1, 2]) / K[1, 1]
    pts = np.stack([x, y, np.ones_like(x)], axis=1).reshape(-1, 1, 3)
    out, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, dist)
    return out.reshape(-1, 2)


def distorted_bounds(crop: tuple[int, int, int, int], K: np.ndarray, dist: np.ndarray, samples: int = 32):
    """(u_min, v_min, u_max, v_max) in the distorted image of the undistorted pixel crop's rectangle.

    The rectangle's border is sampled and distorted; inside the region where the distortion is
    monotonic (the renderer keeps crops inside it) the border's image encloses the interior's.
    """
    x0, y0, w, h = crop
    xa, xb, ya, yb = x0 - 0.5, x0 + w - 0.5, y0 - 0.5, y0 + h - 0.5
    t = np.linspace(0.0, 1.0, samples)
    border = np.concatenate([
        np.stack([xa + t * (xb - xa), np.full_like(t, ya)], 1),
        np.stack([xa + t * (xb - xa), np.full_like(t, yb)], 1),
        np.stack([np.full_like(t, xa), ya + t * (yb - ya)], 1),
        np.stack([np.full_like(t, xb), ya + t * (yb - ya)], 1),
    ])
    d = distort_pixels(border, K, dist)
    return float(d[:, 0].min()), float(d[:, 1].min()), float(d[:, 0].max()), float(d[:, 1].max())


def _cubic_weights(n_out: int, step: int, n_in: int) -> np.ndarray:
    """(n_out, n_in) Catmull-Rom interpolation matrix from samples at (k - 1) * step to pixels 0..n_out-1."""
    t = np.arange(n_out, dtype=float) / step + 1.0
    i = np.floor(t).astype(int)
    f = t - i
    taps = [  # Catmull-Rom: exact on quadratics, C1
        (-1, 0.5 * (-f ** 3 + 2 * f ** 2 - f)),
        (0, 0.5 * (3 * f ** 3 - 5 * f ** 2 + 2)),
        (1, 0.5 * (-3 * f ** 3 + 4 * f ** 2 + f)),
        (2, 0.5 * (f ** 3 - f ** 2)),
    ]
    M = np.zeros((n_out, n_in))
    rows = np.arange(n_out)
    for off, wgt in taps:
        np.add.at(M, (rows, np.clip(i + off, 0, n_in - 1)), wgt)
    return M


def distort_maps_fast(camera, step: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 (H, W) like Camera.distort_maps(): for each distorted pixel, the undistorted
    pixel (same K) it shows. Solved exactly (cv2.undistortPoints) on a grid every `step` pixels, with one
    ring beyond the image, and interpolated (Catmull-Rom, separable) in between: the map is smooth, so
    this agrees with the dense solve to a few thousandths of a pixel at a fraction of its cost (a dense
    1280x720 solve takes seconds on a small CPU)."""
    w, h = camera.width, camera.height
    nx, ny = -(-(w - 1) // step) + 1, -(-(h - 1) // step) + 1
    gx, gy = np.meshgrid((np.arange(nx + 2) - 1.0) * step, (np.arange(ny + 2) - 1.0) * step)
    und = camera.undistort_points(np.stack([gx, gy], axis=-1))  # (ny + 2, nx + 2, 2)
    My = _cubic_weights(h, step, ny + 2)
    Mx = _cubic_weights(w, step, nx + 2)
    mx = (My @ und[..., 0] @ Mx.T).astype(np.float32)
    my = (My @ und[..., 1] @ Mx.T).astype(np.float32)
    return mx, my
