"""Is a detected square marker partly covered? Per-side contrast of its black border against the white margin.

A finger or a hand that reaches into a marker's white margin drags the edge
fit (and the detector's contour) of that side by pixels, and a lone marker's
four corners cannot reveal one wrong corner by their reprojection error (two
spare equations). What can be seen is the cover itself: along an uncovered
side the margin just outside the black border is as bright as everywhere else
around the marker, and the border just inside as dark. So each side is
sampled along its length, in a band outside (white margin) and a band inside
(black border), and a sample whose contrast (outside minus inside, grey
levels) falls well below the marker's typical contrast, or whose margin is
much darker than the marker's typical margin, counts as covered.

Quads are in distorted pixels (the detector's frame), corners in order around
the square; `cell_px` is one marker cell (bit) in pixels, the black border's
width and about the printed margin's.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.edges import refine_squares
from tracking.anchors.pose import project
from tracking.camera import Camera

OUTSIDE = (0.3, 0.5, 0.7)   # cells beyond the edge sampled in the white margin
INSIDE = (0.35, 0.6)        # cells inside the edge sampled in the black border
MIN_CELL_PX = 4.0           # below this the bands are within the blur: nothing can be judged


def covered_fraction(gray: np.ndarray, quad: np.ndarray, bits: int, margin_cells: float = 1.0, samples: int = 20,
                     contrast_drop: float = 0.6, margin_drop: float = 0.3) -> np.ndarray:
    """Fraction (0..1) of each of the 4 sides of `quad` (4,2) whose margin looks covered, per side (4,).

    `bits`: cells across the marker, black border included (6 for a 4x4 marker); `margin_cells`: the
    printed white margin around it in cells (a board's half separation); the bands are scaled to it.
    A sample along a side is covered when its contrast (darkest margin sample minus brightest border
    sample) is below `contrast_drop` times the side's reference contrast, or when its margin is darker
    than the reference margin by more than `margin_drop` of the reference contrast (a skin-coloured
    finger against a dark border keeps some contrast, but not the margin's brightness). A side's
    reference is the better of its own median and its opposite side's: a hand covering part or all of
    one side stands out, while motion blur or foreshortening, which lower two opposite sides alike, do
    not. Samples off the image count as not covered (an image border is not a hand). Zeros when the
    marker is too small to judge.
    """
    quad = np.asarray(quad, np.float64).reshape(4, 2)
    h, w = gray.shape[:2]
    a = quad
    b = np.roll(quad, -1, axis=0)
    d = b - a
    length = np.linalg.norm(d, axis=1)
    cell = length / float(bits)                                                   # (4,) local cell size
    if not cell.min() >= MIN_CELL_PX:
        return np.zeros(4)
    centre = quad.mean(axis=0)
    t = (np.arange(samples) + 0.5) / samples
    pts = a[:, None, :] + d[:, None, :] * t[None, :, None]                         # (4,S,2)
    nrm = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(length, 1e-9)[:, None]
    # outward normal: away from the marker's centre
    flip = np.sign(np.einsum("ij,ij->i", (a + b) / 2 - centre, nrm))
    nrm = nrm * np.where(flip == 0, 1.0, flip)[:, None]
    out_scale = min(1.0, float(margin_cells))
    offs = np.array([o * out_scale for o in OUTSIDE] + [-o for o in INSIDE])       # (K,) cells
    grid = pts[:, :, None, :] + nrm[:, None, None, :] * (offs[None, :] * cell[:, None])[:, None, :, None]
    flat = grid.reshape(-1, 2).astype(np.float32)
    vals = cv2.remap(gray if gray.dtype == np.float32 else gray.astype(np.float32), flat[:, 0:1], flat[:, 1:2],
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(grid.shape[:-1])
    in_img = ((flat[:, 0] >= 0) & (flat[:, 0] <= w - 1) & (flat[:, 1] >= 0) & (flat[:, 1] <= h - 1))
    in_img = in_img.reshape(grid.shape[:-1]).all(axis=-1)                          # (4,S)
    if not in_img.any():
        return np.zeros(4)
    k = len(OUTSIDE)
    margin = vals[..., :k].min(axis=-1)   # a finger anywhere across the margin band darkens it
    border = vals[..., k:].max(axis=-1)
    contrast = margin - border
    med_c = np.array([np.median(contrast[i][in_img[i]]) if in_img[i].any() else -np.inf for i in range(4)])
    med_m = np.array([np.median(margin[i][in_img[i]]) if in_img[i].any() else -np.inf for i in range(4)])
    ref_c = np.maximum(med_c, np.roll(med_c, 2))
    ref_m = np.maximum(med_m, np.roll(med_m, 2))
    if not np.isfinite(ref_c).all() or ref_c.min() < 20.0:
        return np.zeros(4)   # no usable contrast (a dark or washed-out frame): no verdict
    bad = (contrast < contrast_drop * ref_c[:, None]) | (margin < (ref_m - margin_drop * ref_c)[:, None])
    bad &= in_img
    return bad.mean(axis=1)


def is_covered(fractions: np.ndarray, min_fraction: float = 0.1) -> bool:
    """Whether the per-side covered fractions say the marker is partly covered (any side at least
    `min_fraction` covered: two of twenty samples, more than noise or a speck of dirt)."""
    return bool(np.max(fractions, initial=0.0) >= min_fraction)


def refit_covered(camera: Camera, gray, model, ids, quads, bits: int, pred_cfw: np.ndarray, end_margin: float):
    """Corners (M,4,2) of partly covered markers `ids` (their detected corners `quads`), found again on
    their edges where the predicted pose `pred_cfw` puts them (shifted onto the detection), or None.

    A fingertip on a marker's border drags the detector's contour, and the edge fit started from it,
    toward the finger; started from the prediction instead, the middle of each side (where the
    edge fit samples) is mostly uncovered and the corners come out where the sides' lines meet. The
    refit is kept only where at least three corners of each marker land within a pixel and a half (or
    0.15 cell) of the detected ones: the prediction and the uncovered part of the detection agree."""
    world = np.concatenate([model.to_world(model.markers[int(i)]) for i in ids])
    start, z = project(camera, pred_cfw, world)
    if np.any(z <= 0.01):
        return None
    start = start.reshape(-1, 4, 2)
    # a lagging prediction is mostly shifted: move it onto the detection by the median offset of the
    # four corners (one dragged corner cannot pull a median of four far)
    start = start + np.median(quads - start, axis=1)[:, None, :]
    cell = np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=2).min(axis=1) / bits
    refined, ok = refine_squares(gray, start, cell, camera, consensus_px=0.35, end_margin=end_margin)
    if not ok.all():
        return None
    near = np.linalg.norm(refined - quads, axis=2) <= np.maximum(1.5, 0.15 * cell)[:, None]
    if (near.sum(axis=1) < 3).any():
        return None
    return refined
