"""How well a set of board views determines a camera: which image corners they reach, the intrinsics'
covariance, and how far that uncertainty moves a ray's pixel across the image, set against the
estimated camera's error. Functions over numpy arrays; pixels with centres at integers.

The coverage rule (which distortion terms a calibration may free): k3 (the r^6 term) acts mostly far
from the image centre, where only board corners near the image corners constrain it. Unless the views
put board corners in each of the four corner regions (the outer CORNER_FRACTION of the width times the
outer CORNER_FRACTION of the height at each image corner), k3 is fixed at 0; freed, a set of views in
the middle of the image lets it grow to any value (k3 = 54.6 from 9 views covering 21 % of the image
was seen) that fits the middle and ruins the edges. The tangential terms p1, p2 stay free: they trade
off against the principal point, and zeroing them on tests/test_calibration.py's views (true p1 5e-4,
p2 -8e-4, two corners missing) moved cx by 2 px where leaving them free kept it within 0.9 px.

The refusal rule: the calibration's 95 % (2 sigma) projection spread at the image corners, where
extrapolation is worst, must stay under what the estimated camera (tracking.default_intrinsics) is off
by there: ESTIMATE_SCALE_ERROR of the distance from the image centre. A calibration worse than that
is refused with the corners that need views.
"""

from __future__ import annotations

import cv2
import numpy as np

CORNER_FRACTION = 0.25
CORNERS = ("top-left", "top-right", "bottom-left", "bottom-right")
# A 10 degree error in the estimated camera's 65 degree field of view is ~15 % in scale (the doc of
# tracking.default_intrinsics): a pixel at distance r from the centre is off by about 0.15 r.
ESTIMATE_SCALE_ERROR = 0.15
SPREAD_SIGMAS = 2.0
# parameter order of the covariance: cv2.projectPoints' Jacobian columns after rvec and tvec
PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def corner_regions(points: np.ndarray, width: int, height: int) -> set[str]:
    """The image corner regions (CORNERS names) that hold at least one of `points` (N,2 pixels)."""
    p = np.asarray(points, float).reshape(-1, 2)
    left, right = p[:, 0] < CORNER_FRACTION * width, p[:, 0] >= (1 - CORNER_FRACTION) * width
    top, bottom = p[:, 1] < CORNER_FRACTION * height, p[:, 1] >= (1 - CORNER_FRACTION) * height
    hits = {"top-left": left & top, "top-right": right & top, "bottom-left": left & bottom,
            "bottom-right": right & bottom}
    return {name for name, m in hits.items() if m.any()}


def missing_corners(point_sets, width: int, height: int) -> list[str]:
    """The corner regions (in CORNERS order) no point of any of `point_sets` (each N,2 pixels) reaches."""
    reached: set[str] = set()
    for pts in point_sets:
        reached |= corner_regions(pts, width, height)
    return [c for c in CORNERS if c not in reached]


def free_params(flags: int) -> list[int]:
    """Indices into PARAMS that a cv2.calibrateCamera run with `flags` estimates (the 5-term model)."""
    fixed = set()
    if flags & cv2.CALIB_FIX_PRINCIPAL_POINT:
        fixed |= {2, 3}
    if flags & cv2.CALIB_FIX_K1:
        fixed.add(4)
    if flags & cv2.CALIB_FIX_K2:
        fixed.add(5)
    if flags & cv2.CALIB_ZERO_TANGENT_DIST:
        fixed |= {6, 7}
    if flags & cv2.CALIB_FIX_K3:
        fixed.add(8)
    if flags & ~(cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_ZERO_TANGENT_DIST
                 | cv2.CALIB_FIX_K3 | cv2.CALIB_USE_INTRINSIC_GUESS):
        raise ValueError("the covariance handles only the FIX_PRINCIPAL_POINT, FIX_K1..K3, ZERO_TANGENT_DIST and "
                         "USE_INTRINSIC_GUESS flags")
    return [i for i in range(len(PARAMS)) if i not in fixed]


def intrinsic_covariance(obj: list[np.ndarray], img: list[np.ndarray], rvecs, tvecs, K: np.ndarray,
                         dist: np.ndarray, flags: int = 0) -> tuple[np.ndarray, list[int]]:
    """(covariance of the free intrinsics (P,P), their indices into PARAMS) of a solved calibration: the
    Gauss-Newton normal matrix of all views (intrinsics and each view's pose), the poses eliminated
    (Schur complement), scaled by the residual variance; what cv2.calibrateCameraExtended's standard
    deviations are the square roots of the diagonal of. obj: per view (N,3) metres, img: (N,2) pixels."""
    free = free_params(flags)
    cols = [6 + i for i in free]
    P = len(free)
    U = np.zeros((P, P))
    reduced = np.zeros((P, P))
    sq, n_obs = 0.0, 0
    d5 = np.asarray(dist, float).ravel()[:5]
    for o, p, r, t in zip(obj, img, rvecs, tvecs):
        o = np.asarray(o, float).reshape(-1, 3)
        proj, jac = cv2.projectPoints(o, np.asarray(r, float), np.asarray(t, float), K, d5)
        res = np.asarray(p, float).reshape(-1, 2) - proj.reshape(-1, 2)
        sq += float(np.sum(res ** 2))
        n_obs += res.size
        A, B = jac[:, cols], jac[:, :6]
        U += A.T @ A
        W = A.T @ B
        reduced += W @ np.linalg.solve(B.T @ B, W.T)
    dof = n_obs - P - 6 * len(obj)
    sigma2 = sq / max(dof, 1)
    S = U - reduced
    return sigma2 * np.linalg.pinv(S), free


def projection_spread(K: np.ndarray, dist: np.ndarray, cov: np.ndarray, free: list[int],
                      pixels: np.ndarray) -> np.ndarray:
    """1 sigma spread (px, the RMS radius) of where the ray seen at each pixel (N,2) lands, given the
    intrinsics' covariance; inf where the distortion cannot be inverted at that pixel (the model folds
    back before reaching it)."""
    px = np.asarray(pixels, float).reshape(-1, 1, 2)
    d5 = np.asarray(dist, float).ravel()[:5]
    n = cv2.undistortPoints(px, K, d5, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
    rays = np.concatenate([n.reshape(-1, 2), np.ones((len(px), 1))], axis=1)
    back, jac = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, d5)
    out = np.empty(len(px))
    for i in range(len(px)):
        if np.linalg.norm(back[i, 0] - px[i, 0]) > 0.5:
            out[i] = np.inf
            continue
        J = jac[2 * i:2 * i + 2, [6 + k for k in free]]
        out[i] = float(np.sqrt(max(np.trace(J @ cov @ J.T), 0.0)))
    return out


def image_corner_pixels(width: int, height: int) -> np.ndarray:
    """The four image corners in CORNERS order (pixel centres)."""
    return np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], float)


def estimate_error(width: int, height: int, pixels: np.ndarray) -> np.ndarray:
    """What the estimated camera is typically off by at each pixel (N,2): ESTIMATE_SCALE_ERROR of its distance
    from the image centre, pixels."""
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    return ESTIMATE_SCALE_ERROR * np.linalg.norm(np.asarray(pixels, float).reshape(-1, 2) - c, axis=1)
