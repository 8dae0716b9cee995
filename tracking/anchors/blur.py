"""Motion blur stretches every marker along the motion: fit that stretch together with the pose.

While the camera moves, each marker is smeared over the exposure; the edge fit
and the detector then find it a little longer along the motion than it is (the
leading corners ahead, the trailing ones behind, by about the same amount, up
to a pixel or two at a few hundred pixels per second). A pose solved from such
corners reads the stretch as tilt or depth and is off by millimetres to
centimetres. The stretch is the same kind for every marker of a frame (one
motion, one exposure): each marker's corners move by S (corner - marker
centre), with S a symmetric 2x2 image-space tensor. Perspective cannot mimic
that on several markers at once (it also changes the spacing between
markers), so with five or more whole markers, spread over the image, S and the pose can be fitted
together: six pose parameters plus three of S, by Gauss-Newton on the
reprojection error.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.numeric import median
from tracking.camera import Camera

MIN_MARKERS = 5   # whole markers (4 inlier corners each) needed: with 3-4 at an image edge the fit went wrong
MIN_SPREAD = 0.4  # marker sizes: see spread_enough
PRIOR = 0.03      # standard deviation of the stretch's prior (a 2 px stretch of a 60 px marker is 0.03)


def marker_groups(img: np.ndarray, groups: np.ndarray):
    """Per point (of `img` (N,2) pixels, labelled `groups` (N,)): the index of its group and whether that
    group has exactly 4 points (a whole marker); per group: its point count and the mean of its points.
    Pass it as `markers` to marker_offsets / spread_enough of the same points to group them once."""
    img = np.asarray(img, float).reshape(-1, 2)
    uniq, inv, counts = np.unique(groups, return_inverse=True, return_counts=True)
    # (bincount adds in the points' order, as np.add.at did)
    sums = np.stack([np.bincount(inv, weights=img[:, 0], minlength=len(uniq)),
                     np.bincount(inv, weights=img[:, 1], minlength=len(uniq))], axis=1)
    return inv, counts[inv] == 4, counts, sums / counts[:, None]


def marker_offsets(img: np.ndarray, groups: np.ndarray, markers=None) -> tuple[np.ndarray, int]:
    """Each point's offset (N,2) pixels from the centre of its marker's corners (zeros for points not in a
    group of exactly 4: QR or chessboard points, or markers with a corner dropped), and the number of
    whole markers. `markers`: marker_groups(img, groups), when the caller has it."""
    img = np.asarray(img, float).reshape(-1, 2)
    inv, whole, counts, centres = marker_groups(img, groups) if markers is None else markers
    return np.where(whole[:, None], img - centres[inv], 0.0), int((counts == 4).sum())


def spread_enough(img: np.ndarray, groups: np.ndarray, min_spread: float = MIN_SPREAD, markers=None) -> bool:
    """Whether at least MIN_MARKERS whole markers (groups of 4 points) lie spread in two directions: the
    smaller principal standard deviation of their centres is at least `min_spread` marker sizes. A row
    or column of markers (a board half out of view) cannot tell a stretch across it from the pose's tilt.
    `markers`: marker_groups(img, groups), when the caller has it."""
    img = np.asarray(img, float).reshape(-1, 2)
    inv, whole, counts, centres = marker_groups(img, groups) if markers is None else markers
    if (counts == 4).sum() < MIN_MARKERS:
        return False
    # a square's corners lie side / sqrt(2) from its centre
    r2 = np.bincount(inv, weights=((img - centres[inv]) ** 2).sum(axis=1), minlength=len(counts))
    sizes = np.sqrt(2.0 * r2[counts == 4] / 4.0)
    minor = np.sqrt(max(np.linalg.eigvalsh(np.cov(centres[counts == 4].T))[0], 0.0))
    return bool(minor >= min_spread * float(median(sizes)))


def fit_pose_and_stretch(camera: Camera, camera_from_world: np.ndarray, world: np.ndarray, img: np.ndarray,
                         offsets: np.ndarray, iterations: int = 6, prior: float = PRIOR,
                         pixel_sigma: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Jointly refine camera_from_world (4x4) and the stretch S (2x2, symmetric, unitless) so that the
    points `world` (N,3, metres) project to `img` - S offsets (N,2 distorted pixels; `offsets` from
    `marker_offsets`). Starts from the given pose and S = 0; S has a zero-mean prior of standard
    deviation `prior` against corners of `pixel_sigma` pixels, so that where a few markers cannot tell
    the stretch from the pose, it stays small. Returns (camera_from_world, S)."""
    world = np.asarray(world, np.float64).reshape(-1, 3)
    img = np.asarray(img, np.float64).reshape(-1, 2)
    d = np.asarray(offsets, np.float64).reshape(-1, 2)
    rvec = cv2.Rodrigues(np.ascontiguousarray(camera_from_world[:3, :3]))[0].ravel()
    tvec = camera_from_world[:3, 3].astype(np.float64).copy()
    s = np.zeros(3)
    n = len(world)
    Js = np.zeros((2 * n, 3))       # d(residual)/d(s): residual = projected - (img - S d)
    Js[0::2, 0], Js[0::2, 1] = d[:, 0], d[:, 1]
    Js[1::2, 1], Js[1::2, 2] = d[:, 0], d[:, 1]
    dist = camera.dist.reshape(-1)
    lam = pixel_sigma / prior
    # the system [J_pose J_s; 0 lam I] step = -[r; lam s], built once; each iteration fills in its parts
    J = np.zeros((2 * n + 3, 9))
    J[:2 * n, 6:] = Js
    J[2 * n:, 6:] = lam * np.eye(3)
    rhs = np.empty(2 * n + 3)
    for _ in range(iterations):
        proj, jac = cv2.projectPoints(world, rvec, tvec, camera.K, dist)
        S = np.array([[s[0], s[1]], [s[1], s[2]]])
        r = (proj.reshape(-1, 2) - (img - d @ S.T)).reshape(-1)
        J[:2 * n, :6] = jac[:, :6]
        rhs[:2 * n] = -r
        rhs[2 * n:] = -(lam * s)
        step = np.linalg.lstsq(J, rhs, rcond=None)[0]
        rvec, tvec, s = rvec + step[:3], tvec + step[3:6], s + step[6:]
        if np.abs(step).max() < 1e-9:
            break
    pose = np.eye(4)
    pose[:3, :3] = cv2.Rodrigues(rvec)[0]
    pose[:3, 3] = tvec
    return pose, np.array([[s[0], s[1]], [s[1], s[2]]])
