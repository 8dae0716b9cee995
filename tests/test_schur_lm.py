"""The bundle adjustment window's Levenberg-Marquardt (tracking/slam/schur_lm.py) against scipy's
least_squares minimising the same residuals (finite-difference Jacobian: nothing of the solver under test),
and against the scene's truth. The window: 4 keyframes around a desk, the oldest held fixed,
keypoints with 0.5 px noise and 6 % gross outliers, anchor corners seen exactly, everything perturbed.

The reference minimum is scipy's started at the truth (from the perturbed start, scipy's trust region
stops at a higher cost than this solver with these outliers: 1931 against 1492 on seed 1)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from test_slam import K, cv_project, look, scene_points
from tracking.poses import invert, make_pose
from tracking.slam.ba import BAProblem, _fit, _WindowModel
from tracking.slam.schur_lm import minimise, robust_cost

HUBER = 2.0


def window(seed: int, outliers: float = 0.06, anchors: bool = True):
    """(BAProblem perturbed, true cam_from_world of the optimised keyframes, true points)."""
    rng = np.random.default_rng(seed)
    X = scene_points(120, seed=seed)
    poses = [look([x, -0.3, 0.4]) for x in (-0.08, -0.02, 0.04, 0.1)]
    # the gauge: the anchors' corners, or without them two keyframes held (one would leave the scale free)
    fixed = {k: invert(poses[k]) for k in ((0,) if anchors else (0, 1))}
    ids = [k for k in range(4) if k not in fixed]
    obs_kf, obs_pt, obs_uv = [], [], []
    for k, pose in enumerate(poses):
        uv = cv_project(pose, X) + rng.normal(0, 0.5, (len(X), 2))
        bad = rng.random(len(X)) < outliers
        uv[bad] += rng.normal(0, 20, (bad.sum(), 2))
        obs_kf += [k] * len(X)
        obs_pt += list(range(len(X)))
        obs_uv.append(uv)
    corners = np.array([[-0.05, 0.05, 0], [0.05, 0.05, 0], [0.05, -0.05, 0], [-0.05, -0.05, 0]])
    anc_kf = [k for k in ids for _ in range(4)] if anchors else []
    anc_uv = np.concatenate([cv_project(poses[k], corners) for k in ids]) if anchors else np.zeros((0, 2))
    truth = {k: invert(poses[k]) for k in ids}
    start = {k: invert(poses[k] @ make_pose(Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix(),
                                           rng.normal(0, 0.005, 3))) for k in ids}
    pr = BAProblem(ids, fixed, start, np.arange(len(X)), X + rng.normal(0, 0.005, X.shape), np.array(obs_kf),
                   np.array(obs_pt), np.concatenate(obs_uv), np.ones(len(obs_kf)), np.array(anc_kf, int),
                   np.tile(corners, (len(ids), 1)) if anchors else np.zeros((0, 3)), anc_uv)
    return pr, truth, X


def true_vector(model: _WindowModel, truth: dict, X: np.ndarray) -> np.ndarray:
    """The parameter vector of the true poses and points (rotations as increments on the start's)."""
    x = model.x0.copy()
    for i, k in enumerate(model.pr.kf_ids):
        x[6 * i:6 * i + 3] = Rotation.from_matrix(truth[k][:3, :3] @ model.R0[i].T).as_rotvec()
        x[6 * i + 3:6 * i + 6] = truth[k][:3, 3]
    x[6 * model.nk:] = X.ravel()
    return x


def sparsity(model: _WindowModel) -> lil_matrix:
    """Which parameters each residual depends on (its keyframe's 6 when optimised, its point's 3): scipy then
    differences groups of independent columns together, the Jacobian staying a finite difference."""
    n_obs, n_anc, k = model.m_obs, model.m_anc, model.nk
    S = lil_matrix((2 * (n_obs + n_anc), model.x0.size), dtype=int)
    for j in range(n_obs):
        p = 6 * k + 3 * int(model.pr.obs_pt[j])
        S[2 * j:2 * j + 2, p:p + 3] = 1
        if model.o_slot[j] >= 0:
            S[2 * j:2 * j + 2, 6 * model.o_slot[j]:6 * model.o_slot[j] + 6] = 1
    for i in range(n_anc):
        r = 2 * (n_obs + i)
        S[r:r + 2, 6 * model.a_slot[i]:6 * model.a_slot[i] + 6] = 1
    return S


def reference(model: _WindowModel, truth: dict, X: np.ndarray) -> np.ndarray:
    """scipy's Huber minimum next to the truth, run to convergence with a finite-difference Jacobian."""
    return least_squares(model.residuals, true_vector(model, truth, X), loss="huber", f_scale=HUBER,
                         method="trf", x_scale="jac", max_nfev=200, jac="2-point", jac_sparsity=sparsity(model),
                         tr_options={"atol": 1e-14, "btol": 1e-14, "maxiter": 3000, "regularize": False}).x


def scipy_same_budget(model: _WindowModel, max_nfev: int) -> np.ndarray:
    """What tracking.slam.ba did before this solver: scipy's two stages in the same evaluation budget."""
    opts = dict(method="trf", x_scale="jac", jac="2-point", jac_sparsity=sparsity(model), tr_options={"maxiter": 40})
    first = least_squares(model.residuals, model.x0, loss="linear", max_nfev=max(2, max_nfev // 2), **opts)
    return least_squares(model.residuals, first.x, loss="huber", f_scale=HUBER,
                         max_nfev=max(2, max_nfev - first.nfev), **opts).x


@pytest.mark.parametrize("seed,anchors", [(1, True), (2, True), (3, False)])
def test_reaches_the_minimum_next_to_the_truth(seed, anchors):
    pr, truth, X = window(seed, anchors=anchors)
    model = _WindowModel(pr, K)
    ref = reference(model, truth, X)
    ref_cost = robust_cost(model.residuals(ref), HUBER)
    assert robust_cost(model.residuals(model.x0), HUBER) > 5 * ref_cost  # the start is far: work to do
    # given the evaluations, it converges onto scipy's minimum
    x = _fit(model, max_nfev=60, huber_px=HUBER)
    assert robust_cost(model.residuals(x), HUBER) <= ref_cost * 1.0005
    Rs, ts, P = model.unpack(x)
    Rr, tr, Pr = model.unpack(ref)
    assert np.abs(ts - tr).max() < 1e-4                                  # metres
    assert np.median(np.linalg.norm(P - Pr, axis=1)) < 1e-4
    assert max(np.degrees(np.linalg.norm(Rotation.from_matrix(a @ b.T).as_rotvec())) for a, b in zip(Rs, Rr)) < 0.01
    # in the mapping thread's budget (10 evaluations): within 1 % of it, below scipy's cost in that budget,
    # and the keyframes within 2 mm of the truth (0.5 px noise at ~0.45 m)
    x10 = _fit(model, max_nfev=10, huber_px=HUBER)
    cost10 = robust_cost(model.residuals(x10), HUBER)
    assert cost10 <= ref_cost * 1.01 and cost10 < robust_cost(model.residuals(scipy_same_budget(model, 10)), HUBER)
    _, ts10, _ = model.unpack(x10)
    for i, k in enumerate(pr.kf_ids):
        assert np.linalg.norm(ts10[i] - truth[k][:3, 3]) < 2e-3


def test_keeps_to_its_evaluation_budget_and_never_raises_the_cost():
    """The mapping thread's time per window is the budget: never more evaluations than given, and each
    accepted step lowers the cost (a rejected one is not kept)."""
    pr, _, _ = window(4)
    model = _WindowModel(pr, K)
    start = robust_cost(model.residuals(model.x0), HUBER)
    last = start
    for budget in (2, 3, 5, 8):
        x, used = minimise(model, model.x0, budget, huber=HUBER)
        cost = robust_cost(model.residuals(x), HUBER)
        assert used <= budget and cost <= last
        last = cost
    assert last < 0.5 * start


def test_robust_cost_is_scipys_huber():
    """0.5 f_scale^2 sum rho((f / f_scale)^2) with scipy's huber rho(z) = z (z <= 1), 2 sqrt(z) - 1."""
    r = np.array([0.0, 0.5, -1.9, 2.0, 3.0, -10.0])
    z = (r / HUBER) ** 2
    rho = np.where(z <= 1, z, 2 * np.sqrt(z) - 1)
    assert robust_cost(r, HUBER) == pytest.approx(0.5 * HUBER**2 * rho.sum())
    assert robust_cost(r, None) == pytest.approx(0.5 * (r**2).sum())
