"""Soft contact shadow of a model on its anchor plane (z = 0 of the model frame, +z out of the plane).

The shadow is the model's footprint seen from straight above, darker where the model is close to
the plane, blurred: an alpha texture on a quad lying on z = 0. Built once per mesh on the CPU.
"""

from __future__ import annotations

import cv2
import numpy as np

TEXTURE_SIZE = 128


def footprint(vertices: np.ndarray, faces: np.ndarray, size: int = TEXTURE_SIZE):
    """Shadow alpha texture (size, size) float32 in 0..1 and its quad corners (4, 3) on z = 0 (model frame).

    Texture row 0 lies at the quad's y minimum, column 0 at its x minimum (texture coordinates u = x, v = y).
    """
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    extent = float(np.max(hi - lo)) or 1.0
    margin = 0.25 * extent
    x0, y0 = lo[0] - margin, lo[1] - margin
    x1, y1 = hi[0] + margin, hi[1] + margin
    sx = (size - 1) / max(x1 - x0, 1e-12)
    sy = (size - 1) / max(y1 - y0, 1e-12)
    tri = v[f]  # (n, 3, 3)
    # darkness falls off with height above the plane: touching -> 1, half the model size up -> 0
    zmin = tri[:, :, 2].min(axis=1)
    weight = np.clip(1.0 - np.maximum(zmin, 0.0) / (0.5 * extent), 0.0, 1.0)
    levels = np.round(weight * 8).astype(int)
    img = np.zeros((size, size), np.uint8)
    px = np.stack([(tri[:, :, 0] - x0) * sx, (tri[:, :, 1] - y0) * sy], axis=-1)
    px = np.round(px * 16).astype(np.int32)  # 4 fractional bits
    order = np.argsort(levels, kind="stable")  # darker drawn last wins
    for i in order:
        if levels[i] == 0:
            continue
        # one triangle at a time: cv2.fillPoly with many overlapping polygons fills them even-odd
        cv2.fillConvexPoly(img, px[i], int(levels[i] * 255 // 8), lineType=cv2.LINE_AA, shift=4)
    sigma = max(1.0, 0.08 * size)
    tex = cv2.GaussianBlur(img.astype(np.float32) / 255.0, (0, 0), sigma)
    corners = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
    return tex, corners
