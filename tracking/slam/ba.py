"""Local bundle adjustment: keyframe poses and map points of a window, minimising robust
reprojection error (Huber loss) by Levenberg-Marquardt on the Schur complement (tracking.slam.schur_lm).

The anchors' corners seen by a keyframe enter as observations of fixed world
points, so the map cannot drift away from the markers' frame or scale.
Units: metres, undistorted pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from tracking.poses import invert
from tracking.slam.map import Map
from tracking.slam.schur_lm import minimise

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


def _project(Xc: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """(n,2) pixels of camera-frame points (n,3) (depth clamped to 1 um in front of the camera)."""
    z = np.maximum(Xc[:, 2], 1e-6)
    return np.stack([fx * Xc[:, 0] / z + cx, fy * Xc[:, 1] / z + cy], axis=1)


def _dproject(Xc: np.ndarray, w: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """(n,2,3) derivative of the weighted projection by the camera-frame point."""
    z = np.maximum(Xc[:, 2], 1e-6)
    J = np.zeros((Xc.shape[0], 2, 3))
    J[:, 0, 0] = fx / z
    J[:, 0, 2] = -fx * Xc[:, 0] / z**2
    J[:, 1, 1] = fy / z
    J[:, 1, 2] = -fy * Xc[:, 1] / z**2
    return J * w[:, None, None]


def _dpose(Jp: np.ndarray, Xc: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n,2,6) by the rotation increment (left, d(exp(w) R0 X) = -[R X]x dw) and translation."""
    RX = Xc - t
    S = np.zeros((Xc.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2] = RX[:, 2], -RX[:, 1]
    S[:, 1, 0], S[:, 1, 2] = -RX[:, 2], RX[:, 0]
    S[:, 2, 0], S[:, 2, 1] = RX[:, 1], -RX[:, 0]
    return np.concatenate([Jp @ S, Jp], axis=2)


class _WindowModel:
    """The window's least-squares model: the parameter vector's layout (per optimised keyframe a rotation
    increment w, R = exp(w) R0, and the translation of camera_from_world; per point its world position),
    the residuals in weighted pixels and their analytic Jacobian by blocks (per observation 2 x 6 by its
    keyframe's pose, 2 x 3 by its point)."""

    def __init__(self, problem: BAProblem, K: np.ndarray):
        pr = self.pr = problem
        self.nk, self.npnt = len(pr.kf_ids), pr.points.shape[0]
        self.kidx = {k: i for i, k in enumerate(pr.kf_ids)}
        self.R0 = np.array([pr.poses[k][:3, :3] for k in pr.kf_ids])
        self.x0 = self._initial_vector()
        self._observation_cameras()
        self.fx, self.fy, self.cx, self.cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        self.m_obs, self.m_anc = pr.obs_kf.size, self.a_slot.size
        self.obs_pt = pr.obs_pt
        self.oi = np.nonzero(self.opt)[0]  # the observations made by optimised keyframes

    def _initial_vector(self) -> np.ndarray:
        pr, nk = self.pr, self.nk
        x0 = np.zeros(6 * nk + 3 * self.npnt)
        for k, i in self.kidx.items():
            x0[6 * i + 3:6 * i + 6] = pr.poses[k][:3, 3]
        x0[6 * nk:] = pr.points.ravel()
        return x0

    def _observation_cameras(self) -> None:
        """Every observation's camera: optimised slot i >= 0, or fixed (-1) with its pose."""
        pr = self.pr
        self.o_slot = np.array([self.kidx.get(int(k), -1) for k in pr.obs_kf], int)
        self.opt = self.o_slot >= 0
        self.a_slot = np.array([self.kidx[int(k)] for k in pr.anc_kf], int)
        self.fixed_R = np.zeros((pr.obs_kf.size, 3, 3))
        self.fixed_t = np.zeros((pr.obs_kf.size, 3))
        for j, k in enumerate(pr.obs_kf):
            if self.o_slot[j] < 0:
                self.fixed_R[j] = pr.fixed_poses[int(k)][:3, :3]
                self.fixed_t[j] = pr.fixed_poses[int(k)][:3, 3]
        self.slot = np.maximum(self.o_slot, 0)

    def unpack(self, x):
        nk = self.nk
        rv = x[:6 * nk].reshape(nk, 6)
        Rs = Rotation.from_rotvec(rv[:, :3]).as_matrix() @ self.R0
        return Rs, rv[:, 3:], x[6 * nk:].reshape(self.npnt, 3)

    def cams(self, x):
        Rs, ts, P = self.unpack(x)
        R = np.where(self.opt[:, None, None], Rs[self.slot], self.fixed_R)
        t = np.where(self.opt[:, None], ts[self.slot], self.fixed_t)
        return Rs, ts, P, R, t

    def residual_blocks(self, x):
        """(r_obs (m, 2), r_anc (a, 2)): weighted reprojection errors of the keypoints and anchor corners."""
        pr = self.pr
        Rs, ts, P, R, t = self.cams(x)
        Xc = np.einsum("nij,nj->ni", R, P[pr.obs_pt]) + t
        r1 = (_project(Xc, self.fx, self.fy, self.cx, self.cy) - pr.obs_uv) * pr.obs_w[:, None]
        if not self.m_anc:
            return r1, np.zeros((0, 2))
        Xa = np.einsum("nij,nj->ni", Rs[self.a_slot], pr.anc_xyz) + ts[self.a_slot]
        return r1, (_project(Xa, self.fx, self.fy, self.cx, self.cy) - pr.anc_uv) * ANCHOR_WEIGHT

    def residuals(self, x):
        """Every residual as one vector (keypoints, then anchor corners)."""
        r1, r2 = self.residual_blocks(x)
        return np.concatenate([r1.ravel(), r2.ravel()])

    def jacobian_blocks(self, x):
        """(J_pt (m, 2, 3) by the point, J_po (len(oi), 2, 6) by the pose of the observations `oi` made by
        optimised keyframes, J_an (a, 2, 6) of the anchor corners by their keyframe's pose): the pose
        columns are the left rotation increment and the translation (see retract)."""
        pr, oi = self.pr, self.oi
        Rs, ts, P, R, t = self.cams(x)
        Xc = np.einsum("nij,nj->ni", R, P[pr.obs_pt]) + t
        Jp = _dproject(Xc, pr.obs_w, self.fx, self.fy)
        J_an = np.zeros((0, 2, 6))
        if self.m_anc:
            Xa = np.einsum("nij,nj->ni", Rs[self.a_slot], pr.anc_xyz) + ts[self.a_slot]
            Ja = _dproject(Xa, np.full(self.m_anc, ANCHOR_WEIGHT), self.fx, self.fy)
            J_an = _dpose(Ja, Xa, ts[self.a_slot])
        return Jp @ R, _dpose(Jp[oi], Xc[oi], t[oi]), J_an

    def retract(self, x, d_cam: np.ndarray, d_pts: np.ndarray) -> np.ndarray:
        """x moved by a step: each keyframe's rotation turned by exp(d_cam[:, :3]) on the left (the increment
        jacobian_blocks differentiates by), its translation and the points added to."""
        nk = self.nk
        rv = x[:6 * nk].reshape(nk, 6)
        turned = Rotation.from_rotvec(d_cam[:, :3]) * Rotation.from_rotvec(rv[:, :3])
        out = x.copy()
        cam = out[:6 * nk].reshape(nk, 6)
        cam[:, :3] = turned.as_rotvec()
        cam[:, 3:] += d_cam[:, 3:]
        out[6 * nk:] += d_pts.ravel()
        return out

    def world_from_camera(self, Rs: np.ndarray, ts: np.ndarray) -> dict:
        """{kf id: world_from_camera} of the optimised keyframes."""
        poses = {}
        for k, i in self.kidx.items():
            T = np.eye(4)
            T[:3, :3] = Rs[i]
            T[:3, 3] = ts[i]
            poses[k] = invert(T)
        return poses

    def inliers(self, x) -> np.ndarray:
        """Observations within the chi-square 95 % bound (2 dof) of their reprojection, in pixels."""
        r = self.residuals(x)[:2 * self.m_obs].reshape(-1, 2) / self.pr.obs_w[:, None]
        return (r**2).sum(1) < 5.991 * 2.0


def _fit(model: _WindowModel, max_nfev: int, huber_px: float) -> np.ndarray:
    """The optimised parameter vector."""
    # Two stages: plain least squares pulls a perturbed window into the basin (robust losses stall from
    # far away), then the Huber loss from there discounts outlier observations.
    x, used = minimise(model, model.x0, max(2, max_nfev // 2))
    x, _ = minimise(model, x, max(2, max_nfev - used), huber=huber_px)
    return x


def solve(problem: BAProblem, K: np.ndarray, max_nfev: int = 20, huber_px: float = 2.0) -> tuple[dict, np.ndarray, np.ndarray]:
    """Optimise; returns ({kf id: world_from_camera}, point positions (P,3), inlier mask of observations).

    Parameters: per optimised keyframe a rotation increment w (R = exp(w) R0) and the
    translation of camera_from_world; per point its world position. The Jacobian is
    analytic, by blocks (2 rows per observation: 6 pose + 3 point columns).
    """
    model = _WindowModel(problem, K)
    x = _fit(model, max_nfev, huber_px)
    Rs, ts, P = model.unpack(x)
    return model.world_from_camera(Rs, ts), P, model.inliers(x)


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
