"""Subpixel corners of squares (marker borders, QR finder rings) by fitting lines to their edges.

Gradient corner refiners (cornerSubPix) are biased toward the inside of an
L-shaped corner as soon as the image is blurred (a few tenths of a pixel,
which on a 50-pixel marker is a percent of distance). Edges are not: the
gradient peak across a straight edge under a symmetric blur lies on the edge.
So each side is sampled away from its ends, the edge is located along the
normal (gradient peak, parabolic interpolation), the points are undistorted,
a line is fitted, and adjacent lines intersect at the corners.

Motion blur is not symmetric: it smears edges along the motion and biases
corners by pixels. `edge_sharpness` measures that smear, so the anchor filter
and the SLAM tracker can tell smeared markers from sharp ones.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.camera import Camera

# with consensus_px or strong_only: edge samples below this fraction of the marker's typical step are left out
STRONG_STEP = 0.75

_NS = 16                                # edge samples along each side
_ALONG = np.linspace(0.0, 1.0, _NS)     # their positions, as fractions of the sampled stretch
_ACROSS = np.linspace(-1.0, 1.0, 17)    # the window across the edge, as fractions of its reach
_NEXT = [1, 2, 3, 0]                    # corner k's side ends at corner k + 1
_PREV = [3, 0, 1, 2]


def _distort(camera: Camera, und: np.ndarray) -> np.ndarray:
    """Distorted pixels of undistorted pixels (same K)."""
    if not camera.has_distortion:
        return und
    K = camera.K
    n = np.empty((len(und), 1, 3))
    n[:, 0, :2] = (und - [K[0, 2], K[1, 2]]) / [K[0, 0], K[1, 1]]
    n[:, 0, 2] = 1.0
    # (Camera.project's own call, without its conversions)
    px, _ = cv2.projectPoints(n, np.zeros(3), np.zeros(3), K, camera.dist)
    return px.reshape(-1, 2)


def _per_quad(value, m: int, dtype) -> np.ndarray:
    """A scalar or (m,) argument as an (m,) array."""
    a = np.asarray(value, dtype=dtype)
    return a if a.shape == (m,) else np.broadcast_to(a, (m,))


_ARANGE = np.arange(4 * 64)


def _arange(n: int) -> np.ndarray:
    """np.arange(n), from a kept one when short."""
    return _ARANGE[:n] if n <= len(_ARANGE) else np.arange(n)


def _sum16(v: np.ndarray) -> np.ndarray:
    """v.sum(axis=0) of 16 rows added as numpy adds 16 contiguous values (eight running sums, then
    combined pairwise), so that a (16, ...) layout gives the numbers a (..., 16) one did."""
    p = v[:8] + v[8:]
    return ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7]))


def refine_squares(gray: np.ndarray, quads: np.ndarray, cell_px: np.ndarray, camera: Camera | None = None,
                   min_contrast: float = 8.0, consensus_px: float | None = None,
                   end_margin: float | np.ndarray = 0.2,
                   strong_only: bool | np.ndarray = False) -> tuple[np.ndarray, np.ndarray]:
    """Refine approximate square corners (M,4,2) (distorted pixels, consecutive corners along the sides).

    cell_px (M,): how far (pixels) each edge is from the next parallel edge inside/outside the square;
    the search reaches 0.45 of it. consensus_px: when set, each side's line is the one through two of its
    edge samples that the most samples lie within `consensus_px` of (then refitted to those): a finger
    over part of a side shifts a third of its samples by under a pixel, which the default median-based
    rejection keeps; samples whose step across the edge is under STRONG_STEP of the marker's median step
    are left out first. end_margin (scalar or (M,)): the fraction of each side left unsampled at either
    end (the samples run from end_margin to 1 - end_margin of the side); a longer sampled stretch pins the
    line's angle, and with it the corners the lines are extrapolated to, better, as long as no sample is
    within the blur of the corner. strong_only (scalar or (M,) bool): leave out samples under STRONG_STEP
    of the quad's typical step also without consensus_px (a fingertip on the black edge leaves a
    black-to-skin step, and a longer stretch reaches it more often).
    Returns (refined (M,4,2), ok (M,) bool); quads that cannot be refined
    (a side off the image or without contrast) are returned unchanged with ok False.
    """
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    cell_px = _per_quad(cell_px, len(quads), np.float64)
    out = quads.copy()
    ok = np.zeros(len(quads), bool)
    if len(quads) == 0:
        return out, ok
    h, w = gray.shape
    r = np.minimum(np.maximum(0.45 * cell_px, 1.5), 5.0)  # (M,) the search's reach across each edge
    crop = _crop(gray, quads, float(r.max()) + 3.0)
    if crop is None:
        return out, ok
    img, x0, y0 = crop
    edge, valid, contrast = _edge_samples(img, x0, y0, w, h, quads, r, end_margin, min_contrast)
    # Lines for all sides at once: undistort every edge point in one call, then a weighted total-least-
    # squares fit per side (weights 0/1 = valid), one pass of outlier rejection.
    M = len(quads)
    pts = edge.reshape(-1, 2)
    if camera is not None and camera.has_distortion:
        pts = camera.undistort_points(pts)
    pts = pts.reshape(M, 4, _NS, 2)
    wgt = valid.astype(np.float64)
    only = _per_quad(strong_only, M, bool)
    if consensus_px is not None or only.any():
        # a finger over the edge leaves a step from black to skin, well short of black to paper
        typical = np.array([np.median(np.abs(contrast[m][valid[m]])) if valid[m].any() else 0.0 for m in range(M)])
        strong = valid & (np.abs(contrast) >= STRONG_STEP * typical[:, None, None])
        if consensus_px is not None:
            wgt = wgt * _consensus(pts, strong, consensus_px)
        else:
            wgt = wgt * np.where(only[:, None, None], strong, True)
    nvec, c, cnt = _fit_side_lines(pts, wgt)
    corners, good = _side_intersections(nvec, c, cnt)
    if camera is not None and camera.has_distortion and good.any():
        corners[good] = _distort(camera, corners[good].reshape(-1, 2)).reshape(-1, 4, 2)
    # a refinement that moves a corner far is a failure (wrong edge), not an improvement
    moved = np.linalg.norm(corners - quads, axis=2).max(axis=1)
    good &= moved <= np.maximum(0.5 * cell_px, 1.5)
    out[good] = corners[good]
    ok[good] = True
    return out, ok


def _crop(gray: np.ndarray, quads: np.ndarray, reach: float):
    """(float32 crop, x0, y0) of the region the quads cover, `reach` px around them, or None when it is empty:
    the samples are taken from just that region (a 720p conversion per call is not free)."""
    h, w = gray.shape
    x0 = int(max(np.floor(quads[..., 0].min() - reach), 0))
    y0 = int(max(np.floor(quads[..., 1].min() - reach), 0))
    x1 = int(min(np.ceil(quads[..., 0].max() + reach) + 1, w))
    y1 = int(min(np.ceil(quads[..., 1].max() + reach) + 1, h))
    if x1 <= x0 or y1 <= y0:
        return None
    return gray[y0:y1, x0:x1].astype(np.float32), x0, y0


def _edge_samples(img, x0: int, y0: int, w: int, h: int, quads: np.ndarray, r: np.ndarray, end_margin,
                  min_contrast: float):
    """Edge points of every side of every quad (M,4,ns,2 distorted pixels), their validity (M,4,ns) and the
    step across the edge there (M,4,ns grey levels), from the float32 crop `img` at (x0, y0) of a w x h image;
    `r` (M,) the search's reach across each edge in pixels. A numeric kernel: one vectorised pass over all
    samples, kept in one piece so its floating-point order (and so its results) stays as measured."""
    # Sample geometry for every side of every quad at once.
    a = quads
    b = quads[:, _NEXT]
    length = np.linalg.norm(b - a, axis=2)  # (M,4)
    ns = _NS
    em = _per_quad(end_margin, len(quads), np.float64)
    t = em[:, None] + (1.0 - 2.0 * em[:, None]) * _ALONG[None, :]  # (M,ns)
    steps = _ACROSS  # fractions of r
    d = (b - a) / np.maximum(length[..., None], 1e-9)
    nrm = np.stack([-d[..., 1], d[..., 0]], axis=-1)  # (M,4,2)
    base = a[:, :, None, :] + (b - a)[:, :, None, :] * t[:, None, :, None]  # (M,4,ns,2)
    offs = steps[None, :] * r[:, None]  # (M,17)
    # The samples are laid out (17 across the edge, marker, side, sample along it), x and y apart: numpy's
    # loops then run over long contiguous rows (a trailing axis of 2 or 17 makes every operation slow).
    across = nrm[None, :, :, None, :] * offs.T[:, :, None, None, None]  # (17,M,4,1,2): window across each side
    ax = np.ascontiguousarray(np.broadcast_to(across[..., 0], (17, len(quads), 4, ns)))
    ay = np.ascontiguousarray(np.broadcast_to(across[..., 1], (17, len(quads), 4, ns)))
    rr = r[:, None, None]
    dx = steps[1] - steps[0]
    # remap's maps: any 2-D shape under 32767 on both sides (4 M columns: as many markers as before)
    map_shape = (17 * ns, 4 * len(quads))
    shift = np.zeros(base.shape[:-1])
    valid = np.ones(base.shape[:-1], bool)
    for _ in range(2):  # the second pass re-centres the window on the first estimate
        centre = base + nrm[:, :, None, :] * shift[..., None]
        gx = (centre[..., 0] + ax).astype(np.float32)  # (17,M,4,ns)
        gy = (centre[..., 1] + ay).astype(np.float32)
        vals = cv2.remap(img, (gx - np.float32(x0)).reshape(map_shape), (gy - np.float32(y0)).reshape(map_shape),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(gx.shape).astype(np.float64)
        # each window is a straight run of samples, monotonic in x and in y (rounding included): it lies
        # inside the image when both of its ends do
        inside = ((np.minimum(gx[0], gx[-1]) >= 0) & (np.maximum(gx[0], gx[-1]) <= w - 1)
                  & (np.minimum(gy[0], gy[-1]) >= 0) & (np.maximum(gy[0], gy[-1]) <= h - 1))  # (M,4,ns)
        # Edge position = centroid of |dI/ds|; by parts it is a ratio of areas under the profile, which
        # the trapezoid rule gets right on interpolated samples (a gradient peak would snap to pixels).
        lo, hi = vals[0], vals[-1]
        contrast = hi - lo
        # the trapezoid rule over s in [-r, r] (np.trapezoid's 16 terms, summed in its order)
        area = _sum16(dx * (vals[1:] + vals[:-1]) / 2.0) * rr
        with np.errstate(divide="ignore", invalid="ignore"):
            sc = (rr * (hi + lo) - area) / contrast
        mono = np.abs(np.diff(vals, axis=0)).max(axis=0) <= np.abs(contrast) * 0.6 + 2.0
        valid = inside & (np.abs(contrast) > min_contrast) & np.isfinite(sc) & (np.abs(sc) < rr) & mono
        shift = shift + np.where(valid, sc, 0.0)
    edge = base + nrm[:, :, None, :] * shift[..., None]  # (M,4,ns,2)
    return edge, valid, contrast


def _fit_side_lines(pts: np.ndarray, wgt: np.ndarray):
    """A weighted total-least-squares line per side (pts (M,4,ns,2) undistorted, wgt (M,4,ns) 0/1), with one
    pass of outlier rejection: its unit normal (M,4,2), a point on it (M,4,2) and the samples kept (M,4)."""
    ns = pts.shape[2]
    # the fit's arrays laid out (sample, marker, side), x and y apart (long rows for numpy again); sums over
    # the samples in numpy's own order for the (M,4,ns) layout: sequential where it summed over a middle
    # axis, pairwise (_sum16) where over the last one
    X = np.ascontiguousarray(np.moveaxis(pts[..., 0], -1, 0))
    Y = np.ascontiguousarray(np.moveaxis(pts[..., 1], -1, 0))
    W = np.ascontiguousarray(np.moveaxis(wgt, -1, 0))
    for _ in range(2):
        cnt = W.sum(axis=0)  # (M,4)
        cx = (X * W).sum(axis=0) / np.maximum(cnt, 1)
        cy = (Y * W).sum(axis=0) / np.maximum(cnt, 1)
        dx_ = (X - cx) * W
        dy_ = (Y - cy) * W
        sxx = _sum16(dx_ ** 2)
        syy = _sum16(dy_ ** 2)
        sxy = _sum16(dx_ * dy_)
        # normal = eigenvector of the scatter matrix with the smaller eigenvalue
        theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # direction of the line
        nx, ny = -np.sin(theta), np.cos(theta)
        res = np.abs((X - cx) * nx + (Y - cy) * ny)
        masked = np.sort(np.where(W > 0, res, np.inf), axis=0)
        mid = np.minimum(np.maximum((cnt.astype(int) - 1) // 2, 0), ns - 1)
        rmed = np.where(cnt > 0, masked.reshape(ns, -1)[mid.ravel(), _arange(mid.size)].reshape(mid.shape), 0.0)
        W = W * (res <= np.maximum(3.0 * 1.4826 * rmed, 0.1))
    cnt = W.sum(axis=0)
    nvec = np.stack([nx, ny], axis=-1)  # (M,4,2)
    c = np.stack([cx, cy], axis=-1)
    return nvec, c, cnt


def _side_intersections(nvec: np.ndarray, c: np.ndarray, cnt: np.ndarray):
    """Corner k = the intersection of side k-1 and side k (normals nvec, points c, (M,4,2)); ok where both
    sides kept 5+ samples and are not parallel. Returns (corners (M,4,2), ok (M,))."""
    side_ok = cnt >= 5
    # corner k = intersection of side k-1 and side k: n1.x = n1.c1, n2.x = n2.c2
    n1, n2 = nvec[:, _PREV], nvec
    c1, c2 = c[:, _PREV], c
    det = n1[..., 0] * n2[..., 1] - n1[..., 1] * n2[..., 0]
    b1 = (n1 * c1).sum(-1)
    b2 = (n2 * c2).sum(-1)
    safe = np.where(np.abs(det) > 1e-6, det, 1.0)
    corners = np.stack([(b1 * n2[..., 1] - b2 * n1[..., 1]) / safe, (n1[..., 0] * b2 - n2[..., 0] * b1) / safe], -1)
    good = side_ok.all(axis=1) & (np.abs(det) > 1e-6).all(axis=1)
    return corners, good


def _consensus(pts: np.ndarray, valid: np.ndarray, tol: float) -> np.ndarray:
    """(M,4,ns) mask of the samples within `tol` pixels of the line through the pair of valid samples of
    their side that the most valid samples lie within `tol` of (every pair tried)."""
    M, S, ns, _ = pts.shape
    i, j = np.triu_indices(ns, 1)
    a, b = pts[:, :, i, :], pts[:, :, j, :]                                   # (M,4,P,2)
    d = b - a
    n = np.stack([-d[..., 1], d[..., 0]], axis=-1) / np.maximum(np.linalg.norm(d, axis=-1), 1e-9)[..., None]
    dist = np.abs(np.einsum("mspk,msqk->mspq", n, pts) - (n * a).sum(-1)[..., None])   # (M,4,P,ns)
    close = (dist <= tol) & valid[:, :, None, :]
    pair_ok = valid[:, :, i] & valid[:, :, j] & (np.linalg.norm(d, axis=-1) > 2.0)
    score = np.where(pair_ok, close.sum(-1), -1)
    best = np.argmax(score, axis=-1)                                           # (M,4)
    return np.take_along_axis(close, best[..., None, None], axis=2)[:, :, 0, :]


def _fit_line(p: np.ndarray):
    """Total-least-squares line (point, unit normal) through points, one pass of outlier rejection."""
    for _ in range(2):
        c = p.mean(axis=0)
        u, s, vt = np.linalg.svd(p - c, full_matrices=False)
        n = vt[1]
        res = (p - c) @ n
        mad = np.median(np.abs(res - np.median(res)))
        keep = np.abs(res) <= max(3.0 * 1.4826 * mad, 0.1)
        if keep.all() or keep.sum() < 5:
            break
        p = p[keep]
    return c, n


def _intersect(l1, l2):
    (c1, n1), (c2, n2) = l1, l2
    A = np.array([n1, n2])
    if abs(np.linalg.det(A)) < 1e-6:
        return None
    return np.linalg.solve(A, [n1 @ c1, n2 @ c2])


def _linear_percentile(n: int, q: float, value_at) -> float:
    """np.percentile's default ('linear') q-th percentile of n values, computed as numpy does (its float64
    result: float64 values, or q given as a sequence), from
    `value_at(k)`: the k-th smallest value (k from 0). Lets a caller find just the order statistics
    needed (from a histogram, a partial partition) instead of numpy's partition with its end points."""
    virtual = (n - 1) * (q / 100)
    if virtual >= n - 1:
        return float(value_at(n - 1))
    if virtual < 0:
        return float(value_at(0))
    prev = np.floor(virtual)
    gamma = float(virtual - prev)
    a, b = value_at(int(prev)), value_at(int(prev) + 1)
    diff = float(b - a)   # (in the values' own type, as numpy; the rest in float64)
    # numpy's _lerp: from the nearer end
    return float(b) - diff * (1 - gamma) if gamma >= 0.5 else float(a) + diff * gamma


def _level_percentiles(image: np.ndarray, qs) -> list[float]:
    """np.percentile(image, q) for each q of a uint8 image, from its histogram (no sort of the pixels)."""
    counts = cv2.calcHist([image], [0], None, [256], [0, 256]).ravel().astype(np.int64)
    cum = np.cumsum(counts)
    level = lambda k: np.float32(np.searchsorted(cum, k, side="right"))   # the k-th smallest pixel value
    return [_linear_percentile(image.size, q, level) for q in qs]


def _top_percentile(values: np.ndarray, q: float) -> float:
    """np.percentile(values, q) of a 1-D float array, partitioning at just the two order statistics used,
    and for a high q over many values only among those at or above a bound taken from a sample."""
    n = len(values)
    virtual = (n - 1) * (q / 100)
    k = int(min(max(np.floor(virtual), 0), n - 1))
    k1 = min(k + 1, n - 1)
    if n >= 2048 and q >= 50:
        # every value left out is below every value kept, so the k-th smallest is the (k - below)-th
        # smallest kept one, as long as no more than k are left out (else: the whole array)
        sample = values[::16]
        j = int((len(sample) - 1) * (q - 2) / 100)
        bound = np.partition(sample, j)[j]
        kept = values[values >= bound]
        below = n - len(kept)
        if below <= k:
            part = np.partition(kept, [k - below, k1 - below])
            return _linear_percentile(n, q, lambda i: part[i - below])
    part = np.partition(values, [k, k1])
    return _linear_percentile(n, q, lambda i: part[i])


def edge_sharpness(gray: np.ndarray, pixels: np.ndarray, direction: np.ndarray) -> float:
    """How sharp the edges are across `direction` (2,) in the box around `pixels` (N,2) of a grey
    image: the 99th percentile of the intensity gradient along `direction`, per pixel, over the
    box's intensity range (2nd to 98th percentile). An edge smeared over L pixels by motion blur
    scores about 1/L; a sharp one 0.3 to 0.5 (a soft lens about 0.25). NaN when the box is too small
    or flat."""
    h, w = gray.shape[:2]
    lo = np.maximum(np.floor(pixels.min(axis=0)).astype(int) - 4, 0)
    hi = np.minimum(np.ceil(pixels.max(axis=0)).astype(int) + 5, [w, h])
    if (hi - lo).min() < 8 or not np.linalg.norm(direction) > 0:
        return float("nan")
    roi = gray[lo[1]:hi[1], lo[0]:hi[0]]
    if roi.dtype != np.uint8 or roi.ndim != 2:
        roi = roi.astype(np.float32)
        lo_i, hi_i = np.percentile(roi, [2, 98])
    else:
        # the same percentiles from the 256 levels' histogram
        lo_i, hi_i = _level_percentiles(roi, (2, 98))
    if hi_i - lo_i < 10:
        return float("nan")
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    # (the 1/8 as Sobel's scale: a power of two, so the same numbers; a uint8 roi gives the same sums)
    gx = cv2.Sobel(roi, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(roi, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    return float(_top_percentile(np.abs(gx * d[0] + gy * d[1]).ravel(), 99) / (hi_i - lo_i))
