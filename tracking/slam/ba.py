"""Local bundle adjustment: keyframe poses and map points of a window, minimising robust
reprojection error with scipy.optimize.least_squares (sparse Jacobian, Huber loss).

The anchors' corners seen by a keyframe enter as observations of fixed world
points, so the map cannot drift away from the markers' frame or scale.
Units: metres, undistorted pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from tracking.poses import invert
from tracking.slam.map import Map

ANCHOR_WEIGHT = 2.0  # marker corners are measured to ~0.5 px: twice the weight of a 1 px keypoint


@dataclass
class BAProblem:
    """A snapshot of the window: what is optimised, what is held fixed, and the observations."""

    kf_ids: list[int]                 # optimised keyframes
    fixed_poses: dict[int, np.ndarray]  # keyframe id -> cam_from_world held fixed
    poses: dict[int, np.ndarray]        # optimised keyframe id -> cam_from_world (initial)
    point_ids: np.ndarray               # (P,)
    points: np.ndarray                  # (P,3) initial
    obs_kf: np.ndarray                  # (O,) keyframe id per observation
    obs_pt: np.ndarray                  # (O,) index into points
    obs_uv: np.ndarray                  # (O,2)
    obs_w: np.ndarray                   # (O,) sqrt information
    anc_kf: np.ndarray                  # (A,) keyframe id per anchor corner
    anc_xyz: np.ndarray                 # (A,3) fixed world corners
    anc_uv: np.ndarray                  # (A,2)


def build_problem(m: Map, newest: int, window: int = 6, scale: float = 1.2) -> BAProblem | None:
    """Collect the newest `window` keyframes, the points they see, and the other keyframes seeing those."""
    with m.lock:
        ids = sorted(m.keyframes)[-window:]
        if not ids:
            return None
        local = set(ids)
        pids = set()
        for k in ids:
            pids.update(int(p) for p in m.keyframes[k].point_ids if p >= 0 and int(p) in m.points)
        pids = sorted(pids)
        pindex = {p: i for i, p in enumerate(pids)}
        obs_kf, obs_pt, obs_uv, obs_w = [], [], [], []
        fixed = {}
        for p in pids:
            mp = m.points[p]
            for kid, fi in mp.obs.items():
                kf = m.keyframes.get(kid)
                if kf is None:
                    continue
                if kid not in local:
                    fixed[kid] = invert(kf.pose)
                obs_kf.append(kid)
                obs_pt.append(pindex[p])
                obs_uv.append(kf.feats.und[fi])
                obs_w.append(scale ** -float(kf.feats.octave[fi]))
        poses = {k: invert(m.keyframes[k].pose) for k in ids}
        anc_kf, anc_xyz, anc_uv = [], [], []
        for k in ids:
            kf = m.keyframes[k]
            if kf.from_anchors:
                anc_kf += [k] * kf.anchor_world.shape[0]
                anc_xyz.append(kf.anchor_world)
                anc_uv.append(kf.anchor_uv)
        points = np.array([m.points[p].xyz for p in pids]) if pids else np.zeros((0, 3))
    if not anc_kf and not fixed:
        # nothing ties the gauge: hold the oldest keyframe of the window
        k0 = ids[0]
        fixed[k0] = poses.pop(k0)
        ids = ids[1:]
    if not ids or not pids:
        return None
    return BAProblem(ids, fixed, poses, np.array(pids), points, np.array(obs_kf), np.array(obs_pt),
                     np.array(obs_uv).reshape(-1, 2), np.array(obs_w), np.array(anc_kf, int),
                     np.concatenate(anc_xyz) if anc_xyz else np.zeros((0, 3)),
                     np.concatenate(anc_uv) if anc_uv else np.zeros((0, 2)))


def solve(problem: BAProblem, K: np.ndarray, max_nfev: int = 20, huber_px: float = 2.0) -> tuple[dict, np.ndarray, np.ndarray]:
    """Optimise; returns ({kf id: world_from_camera}, point positions (P,3), inlier mask of observations).

    Parameters: per optimised keyframe a rotation increment w (R = exp(w) R0) and the
    translation of camera_from_world; per point its world position. The Jacobian is
    analytic and sparse (2 rows per observation: 6 pose + 3 point columns).
    """
    pr = problem
    nk, npnt = len(pr.kf_ids), pr.points.shape[0]
    kidx = {k: i for i, k in enumerate(pr.kf_ids)}
    R0 = np.array([pr.poses[k][:3, :3] for k in pr.kf_ids])
    x0 = np.zeros(6 * nk + 3 * npnt)
    for k, i in kidx.items():
        x0[6 * i + 3:6 * i + 6] = pr.poses[k][:3, 3]
    x0[6 * nk:] = pr.points.ravel()

    # every observation's camera: optimised slot i >= 0, or fixed (-1) with its pose
    o_slot = np.array([kidx.get(int(k), -1) for k in pr.obs_kf], int)
    opt = o_slot >= 0
    a_slot = np.array([kidx[int(k)] for k in pr.anc_kf], int)
    fixed_R = np.zeros((pr.obs_kf.size, 3, 3))
    fixed_t = np.zeros((pr.obs_kf.size, 3))
    for j, k in enumerate(pr.obs_kf):
        if o_slot[j] < 0:
            fixed_R[j] = pr.fixed_poses[int(k)][:3, :3]
            fixed_t[j] = pr.fixed_poses[int(k)][:3, 3]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    m_obs, m_anc = pr.obs_kf.size, a_slot.size
    slot = np.maximum(o_slot, 0)

    def unpack(x):
        rv = x[:6 * nk].reshape(nk, 6)
        Rs = Rotation.from_rotvec(rv[:, :3]).as_matrix() @ R0
        return Rs, rv[:, 3:], x[6 * nk:].reshape(npnt, 3)

    def cams(x):
        Rs, ts, P = unpack(x)
        R = np.where(opt[:, None, None], Rs[slot], fixed_R)
        t = np.where(opt[:, None], ts[slot], fixed_t)
        return Rs, ts, P, R, t

    def proj(Xc):
        z = np.maximum(Xc[:, 2], 1e-6)
        return np.stack([fx * Xc[:, 0] / z + cx, fy * Xc[:, 1] / z + cy], axis=1)

    def residuals(x):
        Rs, ts, P, R, t = cams(x)
        Xc = np.einsum("nij,nj->ni", R, P[pr.obs_pt]) + t
        r1 = (proj(Xc) - pr.obs_uv) * pr.obs_w[:, None]
        if m_anc:
            Xa = np.einsum("nij,nj->ni", Rs[a_slot], pr.anc_xyz) + ts[a_slot]
            r2 = (proj(Xa) - pr.anc_uv) * ANCHOR_WEIGHT
            return np.concatenate([r1.ravel(), r2.ravel()])
        return r1.ravel()

    def dproj(Xc, w):
        """(n,2,3) derivative of the weighted projection by the camera-frame point."""
        z = np.maximum(Xc[:, 2], 1e-6)
        J = np.zeros((Xc.shape[0], 2, 3))
        J[:, 0, 0] = fx / z
        J[:, 0, 2] = -fx * Xc[:, 0] / z**2
        J[:, 1, 1] = fy / z
        J[:, 1, 2] = -fy * Xc[:, 1] / z**2
        return J * w[:, None, None]

    def dpose(Jp, Xc, t):
        """(n,2,6) by the rotation increment (left, d(exp(w) R0 X) = -[R X]x dw) and translation."""
        RX = Xc - t
        S = np.zeros((Xc.shape[0], 3, 3))
        S[:, 0, 1], S[:, 0, 2] = RX[:, 2], -RX[:, 1]
        S[:, 1, 0], S[:, 1, 2] = -RX[:, 2], RX[:, 0]
        S[:, 2, 0], S[:, 2, 1] = RX[:, 1], -RX[:, 0]
        return np.concatenate([Jp @ S, Jp], axis=2)

    n_rows = 2 * (m_obs + m_anc)
    r_obs = np.repeat(np.arange(2 * m_obs).reshape(m_obs, 2), 3, axis=1).reshape(m_obs, 2, 3)
    c_pt = (6 * nk + 3 * pr.obs_pt[:, None, None] + np.arange(3)[None, None, :]).repeat(2, axis=1)
    oi = np.nonzero(opt)[0]
    r_po = np.repeat(np.arange(2 * m_obs).reshape(m_obs, 2)[oi], 6, axis=1).reshape(oi.size, 2, 6)
    c_po = (6 * o_slot[oi][:, None, None] + np.arange(6)[None, None, :]).repeat(2, axis=1)
    r_an = np.repeat((2 * m_obs + np.arange(2 * m_anc)).reshape(m_anc, 2), 6, axis=1).reshape(m_anc, 2, 6)
    c_an = (6 * a_slot[:, None, None] + np.arange(6)[None, None, :]).repeat(2, axis=1)
    rows = np.concatenate([r_obs.ravel(), r_po.ravel(), r_an.ravel()])
    cols = np.concatenate([c_pt.ravel(), c_po.ravel(), c_an.ravel()])

    def jacobian(x):
        Rs, ts, P, R, t = cams(x)
        Xc = np.einsum("nij,nj->ni", R, P[pr.obs_pt]) + t
        Jp = dproj(Xc, pr.obs_w)
        J_pt = Jp @ R
        J_po = dpose(Jp[oi], Xc[oi], t[oi])
        parts = [J_pt.ravel(), J_po.ravel()]
        if m_anc:
            Xa = np.einsum("nij,nj->ni", Rs[a_slot], pr.anc_xyz) + ts[a_slot]
            Ja = dproj(Xa, np.full(m_anc, ANCHOR_WEIGHT))
            parts.append(dpose(Ja, Xa, ts[a_slot]).ravel())
        return coo_matrix((np.concatenate(parts), (rows, cols)), shape=(n_rows, x0.size)).tocsr()

    # Two stages: plain least squares pulls a perturbed window into the basin (scipy's robust
    # losses stall from far away), then the Huber loss from there discounts outlier observations.
    res = least_squares(residuals, x0, jac=jacobian, loss="linear", method="trf", x_scale="jac",
                        max_nfev=max(2, max_nfev // 2), tr_solver="lsmr", tr_options={"maxiter": 40})
    res = least_squares(residuals, res.x, jac=jacobian, loss="huber", f_scale=huber_px, method="trf",
                        x_scale="jac", max_nfev=max(2, max_nfev - res.nfev), tr_solver="lsmr",
                        tr_options={"maxiter": 40})
    x = res.x
    Rs, ts, P = unpack(x)
    poses = {}
    for k, i in kidx.items():
        T = np.eye(4)
        T[:3, :3] = Rs[i]
        T[:3, 3] = ts[i]
        poses[k] = invert(T)
    r = residuals(x)[:2 * m_obs].reshape(-1, 2) / pr.obs_w[:, None]
    inl = (r**2).sum(1) < 5.991 * 2.0
    return poses, P, inl


def local_bundle_adjustment(m: Map, newest: int, K: np.ndarray, window: int = 5, max_nfev: int = 10) -> bool:
    """Run local BA on the map (snapshot, solve without the lock, write back). True if applied."""
    pr = build_problem(m, newest, window)
    if pr is None:
        return False
    poses, P, inl = solve(pr, K, max_nfev)
    bad_obs = {}
    for j in np.nonzero(~inl)[0]:
        bad_obs.setdefault(int(pr.point_ids[pr.obs_pt[j]]), []).append(int(pr.obs_kf[j]))
    with m.lock:
        for k, T in poses.items():
            kf = m.keyframes.get(k)
            if kf is not None:
                kf.pose = T
        for i, pid in enumerate(pr.point_ids):
            p = m.points.get(int(pid))
            if p is not None:
                p.xyz = P[i]
                p.ready = True
        m.version += 1
    # observations BA could not explain are dropped; points left with < 2 views go
    for pid, kids in bad_obs.items():
        with m.lock:
            p = m.points.get(pid)
            if p is None:
                continue
            for k in kids:
                fi = p.obs.pop(k, None)
                kf = m.keyframes.get(k)
                if fi is not None and kf is not None and kf.point_ids[fi] == pid:
                    kf.point_ids[fi] = -1
            few = len(p.obs) < 2
        if few:
            m.remove_point(pid)
    return True
