"""NURBS surfaces: tensor-product rational B-splines, vectorised evaluation.

Q(u, v) = sum w_ij P_ij N_i,p(u) N_j,q(v) / sum w_ij N_i,p(u) N_j,q(v), evaluated
as the B-spline of the homogeneous net (w x, w y, w z, w) followed by a divide.
"""

from __future__ import annotations

import numpy as np

from . import basis
from .curve import check_weights, denominator_problem
from .errors import DenominatorError, GeometryError, fmt
from .tessellate import tessellate_surface

_CHUNK = 1 << 15  # points per gather, bounds memory at ~(p+1)(q+1)*4*8*_CHUNK bytes


class NurbsSurface:
    """A NURBS surface patch.

    control_points: (n_u, n_v, 3) in model units, rows along u; weights:
    (n_u, n_v), any sign (default 1); knots_u / knots_v: non-decreasing,
    default clamped uniform; degree_u / degree_v: implied by the knot counts
    when None. Invalid input raises a GeometryError (a ValueError) naming the
    field; a denominator that vanishes inside the domain raises DenominatorError.
    """

    def __init__(self, control_points, weights=None, knots_u=None, knots_v=None, degree_u=None, degree_v=None):
        pts = basis.finite_array(control_points, "control_points")
        if pts.ndim != 3 or pts.shape[2] != 3 or pts.shape[0] < 2 or pts.shape[1] < 2:
            raise GeometryError("control_points", f"must have shape (n_u >= 2, n_v >= 2, 3), got {pts.shape}")
        n_u, n_v = pts.shape[:2]
        self.knots_u, self.degree_u = _knots(knots_u, n_u, degree_u, "knots_u")
        self.knots_v, self.degree_v = _knots(knots_v, n_v, degree_v, "knots_v")
        self.control_points = pts
        self.weights = check_weights(weights, (n_u, n_v))
        self._pw = np.concatenate([pts * self.weights[..., None], self.weights[..., None]], axis=2)
        self._pw_flat = self._pw.reshape(-1, 4)
        self._wmax = float(np.abs(self.weights).max())
        if self._wmax == 0:
            raise DenominatorError("weights", "all weights are zero; give at least one non-zero weight")
        if (self.weights <= 0).any():
            self._check_denominator()

    # ------------------------------------------------------------------ info
    @property
    def shape(self) -> tuple[int, int]:
        """(n_u, n_v): control points per direction."""
        return self.control_points.shape[:2]

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((t_p, t_(n+1)) in u, (t_q, t_(m+1)) in v)."""
        n_u, n_v = self.shape
        return (
            (float(self.knots_u[self.degree_u]), float(self.knots_u[n_u])),
            (float(self.knots_v[self.degree_v]), float(self.knots_v[n_v])),
        )

    @property
    def is_rational(self) -> bool:
        return not np.allclose(self.weights, self.weights.flat[0])

    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned box of the control net (contains the surface for positive weights)."""
        pts = self.control_points.reshape(-1, 3)
        return np.array([pts.min(axis=0), pts.max(axis=0)])

    def transformed(self, matrix) -> "NurbsSurface":
        """The surface under a 4x4 affine (or projective) map, applied to the net exactly.

        A projective map multiplies each weight by the homogeneous w of its image.
        """
        m = np.asarray(matrix, dtype=float)
        hom = np.concatenate([self.control_points, np.ones(self.shape + (1,))], axis=2) @ m.T
        return NurbsSurface(
            hom[..., :3] / hom[..., 3:], self.weights * hom[..., 3], self.knots_u, self.knots_v, self.degree_u, self.degree_v
        )

    # ------------------------------------------------------------ evaluation
    def _spans(self, u: np.ndarray, v: np.ndarray):
        n_u, n_v = self.shape
        su = basis.find_spans(self.knots_u, self.degree_u, n_u, u, "u")
        sv = basis.find_spans(self.knots_v, self.degree_v, n_v, v, "v")
        return su, sv

    def _gather(self, su: np.ndarray, sv: np.ndarray) -> np.ndarray:
        """Homogeneous control points of each point's (p+1) x (q+1) support, (m, (p+1)(q+1), 4)."""
        p, q = self.degree_u, self.degree_v
        iu = su[:, None] - p + np.arange(p + 1)[None, :]
        iv = sv[:, None] - q + np.arange(q + 1)[None, :]
        flat = (iu[:, :, None] * self.shape[1] + iv[:, None, :]).reshape(len(su), (p + 1) * (q + 1))
        # take() on a flat index is several times faster than 2-D fancy indexing.
        return self._pw_flat.take(flat, axis=0)

    def _homogeneous(self, u: np.ndarray, v: np.ndarray, derivatives: bool):
        """A (and A_u, A_v) for flat parameter arrays, each (m, 4)."""
        out = [[], [], []]

        def combine(a, b, ctrl):
            tensor = (a[:, :, None] * b[:, None, :]).reshape(len(a), 1, a.shape[1] * b.shape[1])
            return np.matmul(tensor, ctrl)[:, 0]

        for s in range(0, max(u.size, 1), _CHUNK):
            cu, cv = u[s : s + _CHUNK], v[s : s + _CHUNK]
            su, sv = self._spans(cu, cv)
            ctrl = self._gather(su, sv)
            if derivatives:
                nu, dnu = basis.basis_and_derivative(self.knots_u, self.degree_u, su, cu)
                nv, dnv = basis.basis_and_derivative(self.knots_v, self.degree_v, sv, cv)
                out[0].append(combine(nu, nv, ctrl))
                out[1].append(combine(dnu, nv, ctrl))
                out[2].append(combine(nu, dnv, ctrl))
            else:
                nu = basis.basis_functions(self.knots_u, self.degree_u, su, cu)
                nv = basis.basis_functions(self.knots_v, self.degree_v, sv, cv)
                out[0].append(combine(nu, nv, ctrl))
        return [np.concatenate(o) if o else None for o in out]

    def _denominator(self, w: np.ndarray, u: np.ndarray, v: np.ndarray) -> None:
        bad = np.abs(w) <= 1e-14 * self._wmax
        if bad.any():
            k = np.unravel_index(np.argmax(bad), bad.shape)
            uu, vv = np.broadcast_to(u, bad.shape)[k], np.broadcast_to(v, bad.shape)[k]
            raise DenominatorError(
                "weights", f"the denominator sum(w N N) is zero at (u, v) = ({fmt(uu)}, {fmt(vv)})"
            )

    def evaluate(self, u, v) -> np.ndarray:
        """Surface points, shape broadcast(u, v).shape + (3,), model units."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        if u.ndim == 2 and v.ndim == 2 and u.shape[1] == 1 and v.shape[0] == 1:
            return self.evaluate_grid(u[:, 0], v[0])  # outer grid u[:, None], v[None, :]
        u, v = np.broadcast_arrays(u, v)
        (a, _, _) = self._homogeneous(u.ravel(), v.ravel(), False)
        self._denominator(a[:, 3], u.ravel(), v.ravel())
        return (a[:, :3] / a[:, 3:]).reshape(u.shape + (3,))

    def derivatives(self, u, v):
        """(S, S_u, S_v), each broadcast(u, v).shape + (3,): point and first partials.

        Quotient rule in homogeneous form: S_u = (A_u - w_u S) / w.
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        a, au, av = self._homogeneous(u.ravel(), v.ravel(), True)
        self._denominator(a[:, 3], u.ravel(), v.ravel())
        w = a[:, 3:]
        s = a[:, :3] / w
        su = (au[:, :3] - au[:, 3:] * s) / w
        sv = (av[:, :3] - av[:, 3:] * s) / w
        shape = u.shape + (3,)
        return s.reshape(shape), su.reshape(shape), sv.reshape(shape)

    def evaluate_grid(self, u, v, derivatives: bool = False):
        """Points on the tensor grid u (m,) x v (k,): (m, k, 3); with derivatives, (S, S_u, S_v).

        Uses dense basis matrices (B_u P B_v^T per coordinate): the fast path for
        tessellation, same results as `evaluate` on the meshgrid.
        """
        u = np.asarray(u, dtype=float).ravel()
        v = np.asarray(v, dtype=float).ravel()
        n_u, n_v = self.shape
        if derivatives:
            bu, dbu = basis.basis_matrix(self.knots_u, self.degree_u, n_u, u, derivative=True)
            bv, dbv = basis.basis_matrix(self.knots_v, self.degree_v, n_v, v, derivative=True)
        else:
            bu = basis.basis_matrix(self.knots_u, self.degree_u, n_u, u)
            bv = basis.basis_matrix(self.knots_v, self.degree_v, n_v, v)
        rows = np.tensordot(bu, self._pw, axes=(1, 0))  # (m, n_v, 4)
        a = np.einsum("ibk,jb->ijk", rows, bv)
        self._denominator(a[..., 3], u[:, None], v[None, :])
        w = a[..., 3:]
        s = a[..., :3] / w
        if not derivatives:
            return s
        au = np.einsum("ibk,jb->ijk", np.tensordot(dbu, self._pw, axes=(1, 0)), bv)
        av = np.einsum("ibk,jb->ijk", rows, dbv)
        su = (au[..., :3] - au[..., 3:] * s) / w
        sv = (av[..., :3] - av[..., 3:] * s) / w
        return s, su, sv

    def normal(self, u, v) -> np.ndarray:
        """Unit normal S_u x S_v / |S_u x S_v|, shape broadcast(u, v).shape + (3,).

        Where the surface is degenerate (poles, collapsed rows) the normal is the
        limit from a parameter nudged 1e-7 of the domain towards its centre.
        """
        u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
        _, su, sv = self.derivatives(u, v)
        return self._unit_normals(u, v, su, sv)

    def _unit_normals(self, u, v, su, sv) -> np.ndarray:
        n = np.cross(su, sv)
        length = np.linalg.norm(n, axis=-1)
        scale = np.linalg.norm(su, axis=-1) * np.linalg.norm(sv, axis=-1)
        bad = length <= 1e-9 * np.maximum(scale, 1e-300)
        if bad.any():
            (u0, u1), (v0, v1) = self.domain
            bu, bv = np.broadcast_to(u, bad.shape)[bad], np.broadcast_to(v, bad.shape)[bad]
            for h in (1e-7, 1e-4, 1e-2):
                nu = bu + h * (u1 - u0) * np.sign((u0 + u1) / 2 - bu + 1e-300)
                nv = bv + h * (v1 - v0) * np.sign((v0 + v1) / 2 - bv + 1e-300)
                _, a, b = self.derivatives(nu, nv)
                fix = np.cross(a, b)
                fl = np.linalg.norm(fix, axis=-1)
                if (fl > 1e-9 * np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)).all():
                    break
            n = n.copy()
            n[bad] = fix
            length = np.linalg.norm(n, axis=-1)
        return n / np.where(length > 0, length, 1.0)[..., None]

    def _check_denominator(self) -> None:
        us = _span_samples(self.knots_u, self.degree_u, self.shape[0], 17)
        vs = _span_samples(self.knots_v, self.degree_v, self.shape[1], 17)
        bu = basis.basis_matrix(self.knots_u, self.degree_u, self.shape[0], us)
        bv = basis.basis_matrix(self.knots_v, self.degree_v, self.shape[1], vs)
        w = bu @ self.weights @ bv.T
        k = denominator_problem(w, self._wmax)
        if k is None:
            # No zero among the samples; prove it by refining until the local
            # coefficients of sum(w N N) all share one sign. Undecided after
            # that (a zero touched tangentially between samples at most), the
            # evaluation-time check still refuses to divide by zero.
            coeffs, ku, kv = self.weights, self.knots_u, self.knots_v
            for _ in range(5):
                if basis.local_sign(coeffs, (ku, kv), (self.degree_u, self.degree_v)):
                    return
                ku, coeffs = basis.refine_coefficients(ku, self.degree_u, coeffs, axis=0)
                kv, coeffs = basis.refine_coefficients(kv, self.degree_v, coeffs, axis=1)
                if coeffs.size > 250_000:
                    break
            return
        if k is not None:
            i, j = np.unravel_index(k, w.shape)
            raise DenominatorError(
                "weights",
                f"the denominator sum(w N N) vanishes inside the domain (near u = {fmt(us[i])}, "
                f"v = {fmt(vs[j])}); negative or zero weights are allowed only where the weighted "
                "sum stays non-zero",
            )

    # ----------------------------------------------------------- display/mesh
    def tessellate(self, count=None, step=None, tolerance=None):
        """Triangle mesh of the surface (trimesh.Trimesh, model units); see tessellate.py."""
        return tessellate_surface(self, count=count, step=step, tolerance=tolerance)

    def isolines(self, n_u: int = 8, n_v: int = 8, samples: int = 64) -> list[np.ndarray]:
        """n_u curves of constant u and n_v of constant v, each (samples, 3)."""
        (u0, u1), (v0, v1) = self.domain
        us, vs = np.linspace(u0, u1, n_u), np.linspace(v0, v1, n_v)
        ts_u, ts_v = np.linspace(u0, u1, samples), np.linspace(v0, v1, samples)
        lines = list(self.evaluate_grid(us, ts_v)) if n_u else []
        if n_v:
            lines += list(self.evaluate_grid(ts_u, vs).transpose(1, 0, 2))
        return [np.ascontiguousarray(line) for line in lines]

    def control_net(self) -> list[np.ndarray]:
        """Rows and columns of the control net as polylines, each (k, 3)."""
        pts = self.control_points
        return [pts[i].copy() for i in range(pts.shape[0])] + [pts[:, j].copy() for j in range(pts.shape[1])]

    def __repr__(self) -> str:
        return (
            f"NurbsSurface(degree=({self.degree_u}, {self.degree_v}), points={self.shape}, domain={self.domain})"
        )


def _knots(knots, n: int, degree, field: str):
    if knots is None:
        degree = min(3, n - 1) if degree is None else degree
        if isinstance(degree, bool) or int(degree) != degree or not 1 <= degree <= n - 1:
            raise GeometryError(
                field.replace("knots", "degree"), f"must be an integer in 1..{n - 1} for {n} control points, got {degree!r}"
            )
        knots = basis.clamped_uniform_knots(n, int(degree))
    return basis.check_knots(knots, n, degree, field)


def _span_samples(knots: np.ndarray, degree: int, n: int, per_span: int) -> np.ndarray:
    """Parameters: every distinct knot in the domain plus `per_span` per span."""
    lo, hi = knots[degree], knots[n]
    inner = np.unique(knots[(knots >= lo) & (knots <= hi)])
    return np.unique(np.concatenate([np.linspace(a, b, per_span) for a, b in zip(inner[:-1], inner[1:])]))
