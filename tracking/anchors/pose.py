"""Camera pose from anchor observations: IPPE per planar anchor, hypothesis scoring, outlier rejection, LM.

All poses are 4x4. `camera_from_world` maps world points (metres) into the
OpenCV camera frame; image points are distorted pixels, and every projection
goes through camera.K and camera.dist.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from tracking.anchors.numeric import median, row_norms
from tracking.camera import Camera
from tracking.poses import from_rvec_tvec, invert, rotation_angle, to_rvec_tvec

if TYPE_CHECKING:  # annotations only: detect.py imports this module for `project`
    from tracking.anchors.detect import Observation

_LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-10)


def project(camera: Camera, camera_from_world: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pixels (N,2), depth (N,)) of world points under a camera_from_world pose (distortion applied)."""
    pc = world @ camera_from_world[:3, :3].T + camera_from_world[:3, 3]
    return project_pixels(camera, camera_from_world, world), pc[:, 2]


def project_pixels(camera: Camera, camera_from_world: np.ndarray, world: np.ndarray) -> np.ndarray:
    """project()'s pixels (N,2) alone (no depths)."""
    rvec, tvec = to_rvec_tvec(camera_from_world)
    px, _ = cv2.projectPoints(world.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
    return px.reshape(-1, 2)


def residuals(camera: Camera, camera_from_world: np.ndarray, world: np.ndarray, img: np.ndarray,
              behind: float = 1e6) -> np.ndarray:
    """Reprojection error in pixels per point; points behind the camera get `behind`."""
    px, z = project(camera, camera_from_world, world)
    r = row_norms(px - img)
    r[z <= 1e-6] = behind
    return r


def planar_solutions(obs: Observation, camera: Camera) -> list[np.ndarray]:
    """The (up to two) camera_from_anchor poses IPPE gives for one planar anchor, best first.

    A single square marker uses SOLVEPNP_IPPE_SQUARE (its corners in OpenCV's order); other planar
    point sets SOLVEPNP_IPPE. Both local minima are returned: choosing between them is the caller's job.
    """
    if len(obs.obj) < 4:
        return []
    flag = cv2.SOLVEPNP_IPPE_SQUARE if obs.square and len(obs.obj) == 4 else cv2.SOLVEPNP_IPPE
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obs.obj.astype(np.float64), obs.img.astype(np.float64),
                                                 camera.K, camera.dist, flags=flag)
    except cv2.error:
        return []
    return [from_rvec_tvec(r, t) for r, t in zip(rvecs[:n], tvecs[:n])]


def refine_lm(camera: Camera, camera_from_world: np.ndarray, world: np.ndarray, img: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt refinement of a camera_from_world pose on the given correspondences."""
    rvec, tvec = to_rvec_tvec(camera_from_world)
    rvec, tvec = cv2.solvePnPRefineLM(world.reshape(-1, 1, 3).astype(np.float64), img.reshape(-1, 1, 2).astype(np.float64),
                                      camera.K, camera.dist, rvec, tvec, criteria=_LM_CRITERIA)
    return from_rvec_tvec(rvec, tvec)


@dataclass
class PoseSolution:
    """A fused pose and what went into it (world points, inlier mask, errors in pixels)."""

    camera_from_world: np.ndarray
    world: np.ndarray
    img: np.ndarray
    inliers: np.ndarray
    rms: float
    markers: int
    anchors: list[int] = field(default_factory=list)
    # with a single observation: its IPPE branches as camera_from_world poses (best first), each with its
    # reprojection errors (pixels) on all of the observation's points; else empty
    branches: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)

    @property
    def world_from_camera(self) -> np.ndarray:
        return invert(self.camera_from_world)


def _robust_cost(r: np.ndarray, tau: float) -> float:
    return float(np.minimum(r, tau) ** 2 @ np.ones(len(r)))


def solve_pose(observations: list[Observation], world_from_anchor: list[np.ndarray], camera: Camera,
               predicted_camera_from_world: np.ndarray | None = None, outlier_px: float = 3.0,
               pixel_sigma: float = 0.5, motion_sigma_deg: float = 1.0) -> PoseSolution | None:
    """One camera_from_world pose from all anchors' points together.

    Hypotheses: both IPPE solutions of every observed anchor (the prediction when there are none). Each
    is scored on *all* points (robust truncated squared error, `outlier_px`), so other anchors decide
    between a marker's two minima. With a prediction, the score is a negative log-likelihood: the
    reprojection cost over `pixel_sigma`^2 plus the squared rotation away from the prediction over
    `motion_sigma_deg`^2. A flip (a jump of twice the tilt in one frame) is then only taken when the image
    really says so: this is what keeps a nearly frontal marker from flipping. Then: inliers (whole markers dropped when most of their corners are outliers), LM,
    a second tighter inlier pass, LM again. None when fewer than 4 points survive.
    """
    if not observations:
        return None
    world, img, group, groups, hyps = _stack(observations, world_from_anchor, camera)
    n_planar = len(hyps)
    if len(world) < 4:
        return None
    if not hyps and predicted_camera_from_world is not None:
        # no anchor gives its own solution (too few points each): start from the prediction.
        # Otherwise the prediction only chooses: LM started from it could slide into either IPPE minimum.
        hyps.append(predicted_camera_from_world)
    if not hyps:
        return None
    errors = [residuals(camera, h, world, img) for h in hyps]
    costs = np.array([_robust_cost(r, outlier_px) for r in errors])
    branches = list(zip(hyps[:n_planar], errors[:n_planar])) if len(observations) == 1 else []
    best = int(np.argmin(costs))
    if predicted_camera_from_world is not None:
        Rp = predicted_camera_from_world[:3, :3]
        ang = np.degrees([rotation_angle(h[:3, :3] @ Rp.T) for h in hyps])
        best = int(np.argmin(costs / pixel_sigma ** 2 + (ang / motion_sigma_deg) ** 2))
    fitted = _fit_inliers(camera, hyps[best], errors[best], world, img, group, outlier_px,
                          keep_branch=predicted_camera_from_world is not None)
    if fitted is None:
        return None
    pose, inl = fitted
    r = residuals(camera, pose, world[inl], img[inl])
    rms = float(np.sqrt(np.mean(r ** 2)))
    markers, anchors = _count_used(observations, groups, set(group[inl].tolist()))
    return PoseSolution(pose, world[inl], img[inl], inl, rms, markers, anchors, branches)


def _stack(observations: list[Observation], world_from_anchor: list[np.ndarray], camera: Camera):
    """All observations' points stacked: world points (N,3, metres), image points (N,2, px), each point's group
    (marker id made unique across anchors), the groups per observation, and both IPPE hypotheses
    (camera_from_world) of every observation that has its own."""
    worlds, imgs, groups = [], [], []
    hyps = []
    for ob in observations:
        wfa = world_from_anchor[ob.anchor]
        worlds.append(ob.obj @ wfa[:3, :3].T + wfa[:3, 3])
        imgs.append(ob.img)
        groups.append(ob.groups + 1_000_000 * (ob.anchor + 1))
        afw = invert(wfa)
        hyps += [cfa @ afw for cfa in planar_solutions(ob, camera)]
    return np.concatenate(worlds), np.concatenate(imgs), np.concatenate(groups), groups, hyps


def _fit_inliers(camera: Camera, pose: np.ndarray, first_errors: np.ndarray, world: np.ndarray, img: np.ndarray,
                 group: np.ndarray, outlier_px: float, keep_branch: bool):
    """Two passes of inlier selection (`outlier_px`, then 4 robust sigmas within [1 px, outlier_px]; whole
    markers dropped when most of their corners are out) and LM refinement from the chosen hypothesis `pose`
    (`first_errors` its residuals). `keep_branch`: refuse a refinement that turns 4 degrees or more (LM
    sliding into the other IPPE minimum). Returns (pose, inlier mask) or None when fewer than 4 points stay."""
    inl = np.ones(len(world), bool)
    # per point: its group; per group: its size (whole markers are dropped when most of their corners are out)
    _, group_of, group_size = np.unique(group, return_inverse=True, return_counts=True)
    small = group_size <= 4
    for thresh in (outlier_px, None):
        # (the first pass's errors are the chosen hypothesis's, already at hand)
        r = first_errors if thresh is not None else residuals(camera, pose, world, img)
        if thresh is None:
            # second pass: a data-driven threshold (4 robust sigmas), never below 1 px nor above outlier_px
            sigma = 1.4826 * median(r[inl]) if inl.any() else outlier_px
            thresh = float(min(max(4.0 * sigma, 1.0), outlier_px))
        new = r < thresh
        kept = np.bincount(group_of, weights=new, minlength=len(group_size))
        new &= ~(small & (kept * 2 < group_size))[group_of]
        if new.sum() < 4:
            return None
        inl = new
        refined = refine_lm(camera, pose, world[inl], img[inl])
        # A near-degenerate view (a small frontal marker) may have no second minimum: LM would then slide
        # from the chosen branch into the other one, i.e. flip after all. Keep the chosen solution then.
        if not keep_branch or np.degrees(rotation_angle(refined[:3, :3] @ pose[:3, :3].T)) < 4.0:
            pose = refined
    return pose, inl


def _count_used(observations: list[Observation], groups: list[np.ndarray], used: set) -> tuple[int, list[int]]:
    """Markers and anchors (sorted indices) with inlier points: boards count their markers; ChArUco corners
    count as the markers that located them."""
    markers = 0
    anchors = set()
    for ob, g in zip(observations, groups):
        hit = {x for x in g.tolist() if x in used}
        if hit:
            anchors.add(ob.anchor)
            markers += ob.markers if (ob.groups < 0).all() else len(hit)
    return markers, sorted(anchors)
