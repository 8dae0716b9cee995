"""Robust pose fitting from known 3D points: the camera pose that puts points X (world, metres) on their image
points (undistorted pixels, intrinsics K), refined by a Huber-weighted Gauss-Newton on SE(3), and how far a
pose so fitted can be off in position (`position_spread`). Used by the map's frame pose (tracking.slam) and by
the anchors' own fits (tracking.anchors.card), which sit beside each other in the layers.

Poses: `world_from_camera` 4x4 (OpenCV camera axes); internally the optimiser works on `camera_from_world`.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.poses import invert

CHI2_2D = 5.991  # 95 % of a 2-dof chi-square: the inlier bound on squared reprojection error (px^2, sigma 1 px)


def exp_se3(xi: np.ndarray) -> np.ndarray:
    """4x4 rigid transform of a twist (omega (3), v (3)); first-order coupling is enough for small steps."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.ascontiguousarray(xi[:3], dtype=float))[0]
    T[:3, 3] = xi[3:]
    return T


def project(K: np.ndarray, cam_from_world: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted pixels (N,2) and depths (N,) of world points X (N,3)."""
    Xc = X @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    z = Xc[:, 2]
    zs = np.where(np.abs(z) < 1e-9, 1e-9, z)
    u = K[0, 0] * Xc[:, 0] / zs + K[0, 2]
    v = K[1, 1] * Xc[:, 1] / zs + K[1, 2]
    return np.stack([u, v], axis=1), z


def _pose_jacobian(fx: float, fy: float, x: np.ndarray, y: np.ndarray, iz: np.ndarray) -> np.ndarray:
    """d pixels / d xi (2N, 6) of points at normalised image coordinates x, y (N,) and inverse depths iz
    (N,), for a left perturbation xi = (omega, v) of camera_from_world: the projection's derivative times
    d Xc / d xi = [-[Xc]x | I], written out per row (no per-point matrix products)."""
    J = np.empty((x.size, 2, 6))
    J[:, 0, 0] = -fx * x * y
    J[:, 0, 1] = fx * (1.0 + x * x)
    J[:, 0, 2] = -fx * y
    J[:, 0, 3] = fx * iz
    J[:, 0, 4] = 0.0
    J[:, 0, 5] = -fx * x * iz
    J[:, 1, 0] = -fy * (1.0 + y * y)
    J[:, 1, 1] = fy * x * y
    J[:, 1, 2] = fy * x
    J[:, 1, 3] = 0.0
    J[:, 1, 4] = fy * iz
    J[:, 1, 5] = -fy * y * iz
    return J.reshape(-1, 6)


def position_spread(K: np.ndarray, world_from_camera: np.ndarray, X: np.ndarray, pixel_sigma: float) -> float:
    """The spread (metres: the root of the summed variances along the three axes) of the camera position a
    pose fitted to world points X (N,3) would have, their pixels measured to `pixel_sigma` px each axis:
    the translation part of the fit's covariance, pixel_sigma^2 (J^T J)^-1. Large when the points hold the position poorly (a few
    markers in a row at the image edge: their tilt and the camera's shift trade off); inf below 3 points."""
    X = np.asarray(X, float).reshape(-1, 3)
    if len(X) < 3:
        return float("inf")
    T = invert(world_from_camera)
    Xc = X @ T[:3, :3].T + T[:3, 3]
    if np.any(Xc[:, 2] <= 1e-6):
        return float("inf")
    iz = 1.0 / Xc[:, 2]
    J = _pose_jacobian(K[0, 0], K[1, 1], Xc[:, 0] * iz, Xc[:, 1] * iz, iz)
    try:
        cov = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return float("inf")
    # the camera position is -R^T t; a left perturbation moves it by -R^T v: the same spread as v
    return float(pixel_sigma * np.sqrt(max(np.trace(cov[3:, 3:]), 0.0)))


def _huber_step(K: np.ndarray, Xc: np.ndarray, u: np.ndarray, v: np.ndarray, s2: np.ndarray, w: np.ndarray,
                huber: float, damp: np.ndarray) -> np.ndarray | None:
    """One Huber-weighted Gauss-Newton step (6,) of `refine_pose` for camera-frame points Xc (N,3, in front)
    seen at undistorted pixels (u, v) (N,) each, with expected squared errors s2 (N,) and weights w (N,); None
    when the normal equations are singular."""
    fx, fy = K[0, 0], K[1, 1]
    iz = 1.0 / Xc[:, 2]
    x, y = Xc[:, 0] * iz, Xc[:, 1] * iz   # normalised image coordinates
    r = np.empty((iz.size, 2))
    r[:, 0] = fx * x + K[0, 2] - u
    r[:, 1] = fy * y + K[1, 2] - v
    e = np.sqrt((r * r).sum(1) / s2)
    hw = w * np.where(e <= huber, 1.0, huber / np.maximum(e, 1e-12))
    J = _pose_jacobian(fx, fy, x, y, iz)
    JW = J * np.repeat(hw, 2)[:, None]
    H = JW.T @ J
    g = JW.T @ r.reshape(-1)
    try:
        return -np.linalg.solve(H + damp, g)
    except np.linalg.LinAlgError:
        return None


def refine_pose(K: np.ndarray, world_from_camera: np.ndarray, X: np.ndarray, uv: np.ndarray,
                weights: np.ndarray | None = None, rounds: int = 2, iterations: int = 6,
                huber: float = np.sqrt(CHI2_2D), sigma2: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Pose-only Gauss-Newton with Huber robust weights (IRLS); outliers are dropped between rounds.

    X: world points (N,3); uv: undistorted pixels (N,2); weights: information
    per point (1 = one-pixel noise; a marker corner measured to 0.5 px gets 4).
    sigma2: expected squared error per point (px^2) for the inlier test
    e^2 < 5.991 sigma2 (default 1/weights).
    Returns (world_from_camera, inlier mask (N,), RMS inlier error in px).
    """
    n = X.shape[0]
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    s2 = 1.0 / np.maximum(w, 1e-12) if sigma2 is None else np.asarray(sigma2, dtype=float)
    T = invert(world_from_camera)
    damp = 1e-9 * np.eye(6)
    active = np.ones(n, bool)
    for rnd in range(rounds):
        a = None
        for _ in range(iterations):
            if a is None:
                # the active points' rows, taken once while the set stays the same
                a = np.nonzero(active)[0]
                Xa, ua, va, s2a, wa = X[a], uv[a, 0], uv[a, 1], s2[a], w[a]
            if a.size < 4:
                break
            Xc = Xa @ T[:3, :3].T + T[:3, 3]
            z = Xc[:, 2]
            if np.any(z <= 1e-6):
                good = z > 1e-6
                active[a[~good]] = False
                a = None
                continue
            dx = _huber_step(K, Xc, ua, va, s2a, wa, huber, damp)
            if dx is None:
                break
            T = exp_se3(dx) @ T
            # converged: 1e-5 of a twist moves a point at 500 px focal length by 0.005 px (1e-7 cost a
            # third more iterations for changes under a micrometre)
            if np.linalg.norm(dx) < 1e-5:
                break
        # classify with the current pose; the last round's set is the result
        proj, z = project(K, T, X)
        e2 = ((proj - uv) ** 2).sum(1) / s2
        active = (e2 < CHI2_2D) & (z > 0)
        if rnd < rounds - 1 and active.sum() < 4:
            break
    proj, z = project(K, T, X)
    e2 = ((proj - uv) ** 2).sum(1)
    inl = (e2 / s2 < CHI2_2D) & (z > 0)
    rms = float(np.sqrt(e2[inl].mean())) if inl.any() else float("inf")
    return invert(T), inl, rms
