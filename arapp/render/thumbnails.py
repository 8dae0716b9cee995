"""Small shaded pictures of meshes for the model library, drawn on the CPU (no GL context needed)."""

from __future__ import annotations

import cv2
import numpy as np


def view_rotation(azimuth_deg: float = 35.0, elevation_deg: float = 25.0) -> np.ndarray:
    """3x3 rotation from model axes (z up) to view axes (x right, y down, z into the screen)."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    # look along +y of the turned model, tilted down by the elevation
    look = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
    rx = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    return rx @ look @ rz


def render_thumbnail(vertices: np.ndarray, faces: np.ndarray, size: int = 96,
                     color=(0.75, 0.55, 0.3), background=(40, 40, 46), supersample: int = 2) -> np.ndarray:
    """(size, size, 3) uint8 BGR picture of a triangle mesh: orthographic, painter's order, Lambert shading.

    vertices (N, 3) in model units with z up; faces (M, 3) vertex indices;
    color RGB in 0..1. Both sides of the surface are lit (open patches too).
    """
    s = size * supersample
    img = np.empty((s, s, 3), np.uint8)
    img[:] = background
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    if len(v) == 0 or len(f) == 0:
        return cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
    p = v @ view_rotation().T
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    scale = 0.86 * s / max(float((hi - lo).max()), 1e-12)
    xy = (p[:, :2] - (lo + hi) / 2) * scale + s / 2
    tri = p[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    keep = norm > 1e-15
    n, f, tri = n[keep] / norm[keep, None], f[keep], tri[keep]
    light = np.array([-0.35, -0.5, -0.8])
    light /= np.linalg.norm(light)
    shade = 0.25 + 0.75 * np.abs(n @ light)
    order = np.argsort(-tri[:, :, 2].mean(axis=1))  # far to near
    bgr = np.array(color[::-1], dtype=float) * 255
    pts = np.round(xy[f] * 16).astype(np.int32)  # 4 fractional bits for sub-pixel edges
    cols = (shade[:, None] * bgr).clip(0, 255).astype(np.uint8)
    for k in order:
        cv2.fillConvexPoly(img, pts[k], cols[k].tolist(), lineType=cv2.LINE_8, shift=4)
    return cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA)
