"""numpy's median and vector norms without their per-call overhead: the same numbers, computed the way
numpy computes them (the tracker calls them a few dozen times a frame on a few dozen values, where
numpy's argument handling costs more than the arithmetic)."""

from __future__ import annotations

import numpy as np


def row_norms(v: np.ndarray) -> np.ndarray:
    """np.linalg.norm(v, axis=1) of a real (N,k) array: sqrt of the row sums of squares, as numpy does."""
    return np.sqrt(np.add.reduce(v * v, axis=1))


def median(v: np.ndarray):
    """np.median(v, axis=0) of a real float array with at least one row: the middle order statistic, or
    the mean of the two middle ones (their sum over 2, numpy's mean of two); NaN where numpy gives NaN
    (a NaN in the column)."""
    n = v.shape[0]
    h = n // 2
    kth = [h, n - 1] if n % 2 else [h - 1, h, n - 1]
    part = np.partition(v, kth, axis=0)
    mid = part[h] if n % 2 else (part[h - 1] + part[h]) / 2.0
    last = part[n - 1]
    if np.ndim(mid) == 0:
        return np.float64(np.nan) if np.isnan(last) else mid
    return np.where(np.isnan(last), np.nan, mid)
