"""Pose refinement for the chosen views: SIFT features matched across views and a bundle adjustment
that keeps the markers' scale.

SIFT keypoints (OpenCV) are matched between each view and its nearest views
by viewing direction (Lowe's ratio test, then an epipolar check against the
tracker's poses), chained into tracks, triangulated, and refined together
with the camera poses by robust least squares (scipy, Huber loss, sparse
Jacobian). The board's marker corners seen in each view enter as
observations of fixed world points, so the solution stays in the markers'
frame and at their scale (metres). Images are undistorted (pinhole K).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from tracking.anchors.detect import ArucoDetection
from tracking.anchors.model import build_models
from tracking.camera import Camera

MARKER_WEIGHT = 2.0   # marker corners are measured to ~0.5 px: twice the weight of a 1 px SIFT keypoint


@dataclass
class Refinement:
    """What the bundle adjustment did: poses (world_from_camera per view), sparse points (N,3) world,
    RMS reprojection error before/after (px), mean pose change (m, deg), counts."""

    poses: list[np.ndarray]
    points: np.ndarray
    rms_before: float
    rms_after: float
    moved_m: float
    turned_deg: float
    tracks: int
    marker_corners: int


def _marker_observations(views, K, anchors):
    """Per view: (world corners (M,3), pixels (M,2)) of the anchors' markers found in the undistorted image."""
    h, w = views[0].image.shape[:2]
    models = build_models(list(anchors))
    det = ArucoDetection(models, Camera(K, np.zeros(5), w, h))
    out = []
    for v in views:
        gray = cv2.cvtColor(v.image, cv2.COLOR_BGR2GRAY)
        xyz, uv = [], []
        for ob in det.detect(gray):
            xyz.append(models[ob.anchor].to_world(ob.obj))
            uv.append(ob.img)
        out.append((np.concatenate(xyz), np.concatenate(uv)) if xyz else (np.zeros((0, 3)), np.zeros((0, 2))))
    return out


def _fundamental(K, Ta, Tb):
    """F with x_b^T F x_a = 0 for world_from_camera poses Ta, Tb."""
    T = np.linalg.inv(Tb) @ Ta          # b_from_a
    R, t = T[:3, :3], T[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Ki = np.linalg.inv(K)
    return Ki.T @ tx @ R @ Ki


def _neighbours(views, k: int) -> list[list[int]]:
    dirs = np.array([v.axis for v in views])
    sim = dirs @ dirs.T
    np.fill_diagonal(sim, -2)
    return [list(np.argsort(-sim[i])[:k]) for i in range(len(views))]


def match_tracks(views, K, n_features: int = 2500, neighbours: int = 3, epi_px: float = 1.5):
    """SIFT tracks: list of {view: keypoint index} plus per-view keypoint pixel arrays."""
    sift = cv2.SIFT_create(nfeatures=n_features)
    kps, descs = [], []
    for v in views:
        kp, d = sift.detectAndCompute(cv2.cvtColor(v.image, cv2.COLOR_BGR2GRAY), None)
        kps.append(np.array([p.pt for p in kp], float).reshape(-1, 2))
        descs.append(d if d is not None else np.zeros((0, 128), np.float32))
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    offsets = np.cumsum([0] + [len(k) for k in kps])
    parent = np.arange(offsets[-1])

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    done = set()
    for i, nbrs in enumerate(_neighbours(views, neighbours)):
        for j in nbrs:
            if (min(i, j), max(i, j)) in done or len(descs[i]) < 2 or len(descs[j]) < 2:
                continue
            done.add((min(i, j), max(i, j)))
            pairs = [m for m in matcher.knnMatch(descs[i], descs[j], k=2)
                     if len(m) == 2 and m[0].distance < 0.75 * m[1].distance]
            if not pairs:
                continue
            qa = np.array([m[0].queryIdx for m in pairs])
            qb = np.array([m[0].trainIdx for m in pairs])
            F = _fundamental(K, views[i].pose, views[j].pose)
            xa = np.c_[kps[i][qa], np.ones(len(qa))]
            xb = np.c_[kps[j][qb], np.ones(len(qb))]
            lines = xa @ F.T   # epipolar lines in b
            dist = np.abs(np.sum(lines * xb, axis=1)) / np.linalg.norm(lines[:, :2], axis=1)
            for a, b in zip(qa[dist < epi_px], qb[dist < epi_px]):
                ra, rb = find(offsets[i] + a), find(offsets[j] + b)
                if ra != rb:
                    parent[ra] = rb
    roots = np.array([find(a) for a in range(offsets[-1])])
    view_of = np.searchsorted(offsets, np.arange(offsets[-1]), side="right") - 1
    order = np.argsort(roots, kind="stable")
    tracks = []
    start = 0
    for end in list(np.nonzero(np.diff(roots[order]))[0] + 1) + [len(order)]:
        members = order[start:end]
        start = end
        if len(members) < 2:
            continue
        vs = view_of[members]
        if len(set(vs.tolist())) != len(vs):
            continue   # two keypoints of one view in a track: an ambiguous chain, dropped
        tracks.append({int(v): int(m - offsets[v]) for v, m in zip(vs, members)})
    return tracks, kps


def _triangulate(Ps, obs):
    """Linear multi-view triangulation of one track: Ps per-view 3x4 projections, obs [(view, (u, v))]."""
    rows = []
    for vi, (u, v) in obs:
        P = Ps[vi]
        rows += [u * P[2] - P[0], v * P[2] - P[1]]
    _, _, vt = np.linalg.svd(np.array(rows))
    X = vt[-1]
    return X[:3] / X[3] if abs(X[3]) > 1e-12 else None


def _project(K, rvecs, tvecs, X):
    R = Rotation.from_rotvec(rvecs).as_matrix()
    pc = np.einsum("nij,nj->ni", R, X) + tvecs
    z = np.maximum(pc[:, 2], 1e-6)
    return np.c_[K[0, 0] * pc[:, 0] / z + K[0, 2], K[1, 1] * pc[:, 1] / z + K[1, 2]]


def refine_poses(views, K, anchors, max_reproj_px: float = 2.0, max_nfev: int = 15, min_track: int = 3) -> Refinement:
    """Bundle-adjust the views' poses with SIFT tracks and the anchors' marker corners (fixed world points)."""
    poses = [v.pose.copy() for v in views]
    tracks, kps = match_tracks(views, K)
    Ps = [K @ np.linalg.inv(T)[:3] for T in poses]
    pts, obs_v, obs_p, obs_uv = _track_points(tracks, kps, Ps, max_reproj_px, min_track)
    marks = _marker_observations(views, K, anchors)
    m_v = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(marks)]).astype(int)
    m_xyz = np.concatenate([m[0] for m in marks]) if len(m_v) else np.zeros((0, 3))
    m_uv = np.concatenate([m[1] for m in marks]) if len(m_v) else np.zeros((0, 2))
    nv, npnt = len(views), len(pts)
    cfw = [np.linalg.inv(T) for T in poses]
    x0 = np.concatenate([np.concatenate([Rotation.from_matrix(c[:3, :3]).as_rotvec(), c[:3, 3]]) for c in cfw]
                        + [pts.ravel()])

    def residuals(x):
        cam = x[:6 * nv].reshape(nv, 6)
        X = x[6 * nv:].reshape(npnt, 3)
        r1 = (_project(K, cam[obs_v, :3], cam[obs_v, 3:], X[obs_p]) - obs_uv).ravel()
        r2 = (_project(K, cam[m_v, :3], cam[m_v, 3:], m_xyz) - m_uv).ravel() * MARKER_WEIGHT
        return np.concatenate([r1, r2])

    r0 = residuals(x0)
    rms0 = float(np.sqrt(np.mean(r0[:2 * len(obs_v)] ** 2))) if len(obs_v) else 0.0
    if len(obs_v) + len(m_v) < 6 * nv:
        return Refinement(poses, pts, rms0, rms0, 0.0, 0.0, npnt, len(m_v))
    S = _jacobian_sparsity(nv, x0.size, obs_v, obs_p, m_v)
    sol = least_squares(residuals, x0, jac_sparsity=S.tocsr(), method="trf", loss="huber", f_scale=1.0,
                        x_scale="jac", max_nfev=max_nfev)
    r1 = residuals(sol.x)
    rms1 = float(np.sqrt(np.mean(r1[:2 * len(obs_v)] ** 2))) if len(obs_v) else 0.0
    new, moved, turned = _poses_from_params(sol.x[:6 * nv].reshape(nv, 6), poses)
    return Refinement(new, sol.x[6 * nv:].reshape(-1, 3), rms0, rms1, float(np.mean(moved)),
                      float(np.mean(turned)), npnt, len(m_v))


def _track_points(tracks, kps, Ps, max_reproj_px: float, min_track: int):
    """The tracks seen in at least `min_track` views, triangulated from the views' projections `Ps` and kept
    when in front of every camera within `max_reproj_px`: (points (n, 3), observation view indices, point
    indices, pixels (m, 2))."""
    pts, obs_v, obs_p, obs_uv = [], [], [], []
    for tr in tracks:
        if len(tr) < min_track:   # two-view tracks add many unknowns and little constraint
            continue
        ob = [(vi, kps[vi][ki]) for vi, ki in tr.items()]
        X = _triangulate(Ps, ob)
        if X is None:
            continue
        proj = np.array([Ps[vi] @ np.r_[X, 1.0] for vi, _ in ob])
        if np.any(proj[:, 2] <= 0):
            continue
        err = np.linalg.norm(proj[:, :2] / proj[:, 2:] - np.array([uv for _, uv in ob]), axis=1)
        if np.any(err > max_reproj_px):
            continue
        for vi, uv in ob:
            obs_v.append(vi)
            obs_p.append(len(pts))
            obs_uv.append(uv)
        pts.append(X)
    return (np.array(pts).reshape(-1, 3), np.array(obs_v, int), np.array(obs_p, int),
            np.array(obs_uv).reshape(-1, 2))


def _jacobian_sparsity(nv: int, n_params: int, obs_v, obs_p, m_v):
    """Which parameters each residual depends on (lil_matrix): a track pixel on its view's 6 pose
    parameters and its point's 3, a marker corner pixel on its view's pose only."""
    n_res = 2 * (len(obs_v) + len(m_v))
    S = lil_matrix((n_res, n_params), dtype=np.uint8)
    rows = np.arange(len(obs_v))
    for k in range(2):
        for c in range(6):
            S[2 * rows + k, 6 * obs_v + c] = 1
        for c in range(3):
            S[2 * rows + k, 6 * nv + 3 * obs_p + c] = 1
    rows = 2 * len(obs_v) + 2 * np.arange(len(m_v))
    for k in range(2):
        for c in range(6):
            S[rows + k, 6 * m_v + c] = 1
    return S


def _poses_from_params(cam, poses):
    """(world_from_camera 4x4s from the (nv, 6) rotation-vector + translation camera_from_world
    parameters, metres each moved from `poses`, degrees each turned)."""
    new, moved, turned = [], [], []
    for i in range(len(cam)):
        c = np.eye(4)
        c[:3, :3] = Rotation.from_rotvec(cam[i, :3]).as_matrix()
        c[:3, 3] = cam[i, 3:]
        T = np.linalg.inv(c)
        moved.append(np.linalg.norm(T[:3, 3] - poses[i][:3, 3]))
        turned.append(np.degrees(Rotation.from_matrix(T[:3, :3] @ poses[i][:3, :3].T).magnitude()))
        new.append(T)
    return new, moved, turned
