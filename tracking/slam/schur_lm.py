"""Levenberg-Marquardt for a bundle adjustment window by the Schur complement (tracking.slam.ba).

Each iteration eliminates the points' 3x3 blocks and solves the keyframes' 6-parameter blocks densely (a
window holds a handful of keyframes), so it costs a few numpy passes over the observations. scipy's
least_squares (trust-region reflective with LSMR on the sparse Jacobian), which did this before, took
about 40 % of the tracker's CPU on the fast pans (issue 29); the minimum it reaches is this solver's test
oracle (tests/test_schur_lm.py). Robust loss: Huber on each residual component, as scipy's
loss="huber" with f_scale=huber, by iteratively reweighted least squares. Residuals in weighted pixels.

The model (ba._WindowModel) supplies `residual_blocks(x)` -> (r_obs (m, 2), r_anc (a, 2)),
`jacobian_blocks(x)` -> (J_pt (m, 2, 3), J_po (n, 2, 6) for the observations `oi` of optimised
keyframes, J_an (a, 2, 6)), `retract(x, d_cam (k, 6), d_pts (P, 3))` and the index arrays `obs_pt`,
`oi`, `o_slot`, `a_slot`, `nk`, `npnt`.
"""

from __future__ import annotations

import numpy as np

LAMBDA0 = 1e-4     # first Marquardt damping (relative to the diagonal)
LAMBDA_MAX = 1e6   # beyond this no step lowers the cost: stop
FTOL = 1e-8        # stop when an accepted step lowers the cost by less than this share


def robust_cost(r: np.ndarray, huber: float | None) -> float:
    """0.5 sum rho(r) over every component: r^2 (plain) or Huber's r^2 / 2 |r| huber - huber^2 (robust)."""
    a = np.abs(r)
    if huber is None:
        return 0.5 * float(np.sum(a * a))
    return 0.5 * float(np.sum(np.where(a <= huber, a * a, 2.0 * huber * a - huber * huber)))


def _sqrt_weights(r: np.ndarray, huber: float | None) -> np.ndarray:
    """Per component, the square root of the Huber IRLS weight (1 inside the threshold, huber / |r| out)."""
    if huber is None:
        return np.ones_like(r)
    a = np.abs(r)
    return np.sqrt(np.where(a <= huber, 1.0, huber / np.maximum(a, 1e-300)))


def _tmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A^T B per block: (n, r, i), (n, r, j) -> (n, i, j) (batched matmul: einsum is several times slower)."""
    return A.transpose(0, 2, 1) @ B


def _tvec(A: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A^T r per block: (n, r, i), (n, r) -> (n, i)."""
    return (A.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0]


def _sum_by(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """out[i] = sum of values[j] with index[j] == i, for i < n (np.add.at's result, by one bincount per entry:
    add.at is the slowest numpy way to do it)."""
    flat = values.reshape(len(values), -1)
    out = np.empty((n, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.bincount(index, weights=flat[:, c], minlength=n)
    return out.reshape((n,) + values.shape[1:])


def _blocks(model, x, r_o, r_a, huber):
    """The normal equations by blocks: Hpp (P,3,3), gp (P,3), Hcc (k,6,6), gc (k,6), and the (point,
    keyframe) table of the cross blocks W (P, k, 6, 3), zero where the keyframe does not see the point."""
    J_pt, J_po, J_an = model.jacobian_blocks(x)
    s_o, s_a = _sqrt_weights(r_o, huber), _sqrt_weights(r_a, huber)
    r_o, r_a = r_o * s_o, r_a * s_a
    J_pt = J_pt * s_o[:, :, None]
    oi = model.oi
    J_po = J_po * s_o[oi][:, :, None]
    J_an = J_an * s_a[:, :, None]
    P, k = model.npnt, model.nk
    Hpp = _sum_by(model.obs_pt, _tmul(J_pt, J_pt), P)
    gp = _sum_by(model.obs_pt, _tvec(J_pt, r_o), P)
    slots = np.concatenate([model.o_slot[oi], model.a_slot])
    J_c = np.concatenate([J_po, J_an])
    Hcc = _sum_by(slots, _tmul(J_c, J_c), k)
    gc = _sum_by(slots, _tvec(J_c, np.concatenate([r_o[oi], r_a])), k)
    W = np.zeros((P, k, 6, 3))
    # a keyframe sees a point once: each (point, keyframe) cross block comes from one observation
    W[model.obs_pt[oi], model.o_slot[oi]] = _tmul(J_po, J_pt[oi])
    return Hpp, gp, Hcc, gc, W


def _damped(H: np.ndarray, lam: float) -> np.ndarray:
    """H (n, d, d) with lam times its diagonal (and a floor) added: Marquardt's damping."""
    idx = np.arange(H.shape[1])
    d = H[:, idx, idx]
    out = H.copy()
    out[:, idx, idx] += lam * d + 1e-12 * (1.0 + d)
    return out


def _step(Hpp, gp, Hcc, gc, W, lam):
    """The damped Gauss-Newton step (d_cam (k, 6), d_pts (P, 3)) by the Schur complement; None if singular."""
    k = Hcc.shape[0]
    try:
        Hpp_inv = np.linalg.inv(_damped(Hpp, lam))
    except np.linalg.LinAlgError:
        return None
    P = W.shape[0]
    Wr = W.reshape(P, 6 * k, 3)
    Y = Wr @ Hpp_inv                                          # W Hpp^-1, per point: (P, 6k, 3)
    Yf = Y.transpose(1, 0, 2).reshape(6 * k, 3 * P)
    S = np.zeros((k, 6, k, 6))
    S[np.arange(k), :, np.arange(k), :] = _damped(Hcc, lam)
    S = S.reshape(6 * k, 6 * k) - Yf @ Wr.transpose(1, 0, 2).reshape(6 * k, 3 * P).T
    b = gc.reshape(-1) - Yf @ gp.reshape(-1)
    try:
        d_cam = np.linalg.solve(S, -b)
    except np.linalg.LinAlgError:
        return None
    back = -gp - (Wr.transpose(0, 2, 1) @ d_cam)               # (P, 3)
    d_pts = (Hpp_inv @ back[:, :, None])[:, :, 0]
    d_cam = d_cam.reshape(k, 6)
    return d_cam, d_pts


def minimise(model, x0: np.ndarray, max_nfev: int, huber: float | None = None) -> tuple[np.ndarray, int]:
    """The parameter vector after Levenberg-Marquardt from `x0` with at most `max_nfev` evaluations of the
    residuals (as scipy counts them), and the evaluations used."""
    x = np.asarray(x0, float).copy()
    r_o, r_a = model.residual_blocks(x)
    cost = robust_cost(np.concatenate([r_o.ravel(), r_a.ravel()]), huber)
    nfev, lam = 1, LAMBDA0
    blocks = None
    while nfev < max_nfev and lam < LAMBDA_MAX:
        if blocks is None:
            blocks = _blocks(model, x, r_o, r_a, huber)
        step = _step(*blocks, lam)
        if step is None:
            lam *= 10.0
            continue
        x_new = model.retract(x, *step)
        r_o_new, r_a_new = model.residual_blocks(x_new)
        nfev += 1
        cost_new = robust_cost(np.concatenate([r_o_new.ravel(), r_a_new.ravel()]), huber)
        if np.isfinite(cost_new) and cost_new < cost:
            small = cost - cost_new < FTOL * cost
            x, r_o, r_a, cost = x_new, r_o_new, r_a_new, cost_new
            blocks, lam = None, max(lam / 10.0, 1e-9)
            if small:
                break
        else:
            lam *= 10.0  # the same linearisation, a shorter step
    return x, nfev
