"""The anchors' filtered pose held to the corners it rests on (`AnchorTracker._hold_to_corners`).

Poses are 4x4: world_from_camera for the filtered and raw poses, camera_from_world inside; pixels are
distorted image pixels as `camera` says.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.numeric import median, row_norms
from tracking.anchors.pose import project_pixels
from tracking.camera import Camera
from tracking.poses import invert


def hold_to_corners(camera: Camera, filt: np.ndarray, raw: np.ndarray, world: np.ndarray, tau: float,
                    rank_ratio: float) -> np.ndarray:
    """`filt` (world_from_camera) corrected just enough that the points `world` (N,3) project within `tau`
    pixels of where `raw` projects them: the least-squares pose change for the part of the offset beyond
    `tau`, in the pose directions whose singular values are at least `rank_ratio` of the largest (see
    AnchorTracker._hold_to_corners for why)."""
    target = project_pixels(camera, invert(raw), world)
    cfw = invert(filt)
    for _ in range(2):
        now = project_pixels(camera, cfw, world)
        r = target - now
        dev = float(row_norms(r).max())
        if not dev > 1.02 * tau:
            break
        depth = max(float(median((world @ cfw[:3, :3].T + cfw[:3, 3])[:, 2])), 1e-3)
        J = _pose_jacobian(camera, cfw, world, now, depth)
        U, S, Vt = np.linalg.svd(J, full_matrices=False)
        keep = S >= rank_ratio * S[0]
        delta = Vt[keep].T @ ((U[:, keep].T @ ((1.0 - tau / dev) * r.ravel())) / S[keep])
        cfw = _perturb(cfw, delta, depth)
    return invert(cfw)


def _perturb(cfw: np.ndarray, delta: np.ndarray, depth: float) -> np.ndarray:
    """camera_from_world moved by delta = (rotation vector, translation / depth) in the camera frame."""
    out = cfw.copy()
    dR = cv2.Rodrigues(np.asarray(delta[:3], np.float64).reshape(3, 1))[0]
    out[:3, :3] = dR @ cfw[:3, :3]
    out[:3, 3] = dR @ cfw[:3, 3] + np.asarray(delta[3:]) * depth
    return out


def _pose_jacobian(camera: Camera, cfw: np.ndarray, world: np.ndarray, px: np.ndarray, depth: float) -> np.ndarray:
    """(2N, 6) pixels per unit of `_perturb`'s delta, by forward differences (1e-6)."""
    J = np.empty((2 * len(world), 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        J[:, k] = ((project_pixels(camera, _perturb(cfw, d, depth), world) - px) / 1e-6).ravel()
    return J
