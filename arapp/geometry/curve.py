"""NURBS curves: rational B-spline curves evaluated by homogeneous coordinates."""

from __future__ import annotations

import numpy as np

from . import basis
from .errors import DenominatorError, GeometryError, fmt


def check_weights(weights, shape: tuple, field: str = "weights") -> np.ndarray:
    """Weights of the given shape (ones when None); finite, any sign."""
    if weights is None:
        return np.ones(shape)
    w = basis.finite_array(weights, field)
    if w.shape != tuple(shape):
        raise GeometryError(field, f"must have shape {tuple(shape)} to match the control points, got {w.shape}")
    return w


def denominator_problem(values: np.ndarray, scale: float) -> int | None:
    """Index (flat) of a sample where a denominator is zero or changes sign, else None.

    A continuous function that takes both signs on a connected domain vanishes
    in between; one tiny in magnitude vanishes for practical purposes.
    """
    flat = values.ravel()
    tiny = np.abs(flat) <= 1e-12 * scale
    if tiny.any():
        return int(np.argmax(tiny))
    if flat.min() < 0 < flat.max():
        sign = np.sign(flat[0])
        return int(np.argmax(np.sign(flat) != sign))
    return None


class NurbsCurve:
    """A NURBS curve C(t) = sum w_i P_i N_i,p(t) / sum w_i N_i,p(t).

    control_points: (n+1, d) in model units (d = 2 or 3); weights: (n+1,) any
    sign, default all 1; knots: n+p+2 non-decreasing values, default clamped
    uniform on [0, 1]; degree: implied by the knot count when None.
    """

    def __init__(self, control_points, weights=None, knots=None, degree=None):
        pts = basis.finite_array(control_points, "control_points", ndim=2)
        if pts.shape[0] < 2 or pts.shape[1] not in (2, 3):
            raise GeometryError("control_points", f"must have shape (n >= 2, 2 or 3), got {pts.shape}")
        n = pts.shape[0]
        if knots is None:
            degree = min(3, n - 1) if degree is None else degree
            if isinstance(degree, bool) or int(degree) != degree or not 1 <= degree <= n - 1:
                raise GeometryError("degree", f"must be an integer in 1..{n - 1} for {n} control points, got {degree!r}")
            knots = basis.clamped_uniform_knots(n, int(degree))
        self.knots, self.degree = basis.check_knots(knots, n, degree, "knots")
        self.control_points = pts
        self.weights = check_weights(weights, (n,))
        self._pw = np.concatenate([pts * self.weights[:, None], self.weights[:, None]], axis=1)
        if (self.weights <= 0).any():
            self._check_denominator()

    @property
    def dimension(self) -> int:
        return self.control_points.shape[1]

    @property
    def domain(self) -> tuple[float, float]:
        """(t_p, t_(n+1)): the parameter range where the basis sums to one."""
        return float(self.knots[self.degree]), float(self.knots[len(self.control_points)])

    @property
    def is_rational(self) -> bool:
        return not np.allclose(self.weights, self.weights[0])

    def _homogeneous(self, t, derivative: bool):
        t = np.asarray(t, dtype=float)
        flat = t.ravel()
        n, p = len(self.control_points), self.degree
        span = basis.find_spans(self.knots, p, n, flat, "t")
        idx = span[:, None] - p + np.arange(p + 1)[None, :]
        ctrl = self._pw[idx]  # (m, p+1, d+1)
        if derivative:
            vals, ders = basis.basis_and_derivative(self.knots, p, span, flat)
            return t.shape, np.einsum("ma,mak->mk", vals, ctrl), np.einsum("ma,mak->mk", ders, ctrl)
        vals = basis.basis_functions(self.knots, p, span, flat)
        return t.shape, np.einsum("ma,mak->mk", vals, ctrl), None

    def _divide(self, a: np.ndarray, t_flat: np.ndarray) -> np.ndarray:
        w = a[:, -1]
        bad = np.abs(w) <= 1e-14 * np.abs(self.weights).max()
        if bad.any():
            raise DenominatorError("weights", f"the denominator sum(w N) is zero at t = {fmt(t_flat[np.argmax(bad)])}")
        return w

    def evaluate(self, t) -> np.ndarray:
        """Curve points, shape t.shape + (d,), model units."""
        shape, a, _ = self._homogeneous(t, False)
        w = self._divide(a, np.ravel(t))
        return (a[:, :-1] / w[:, None]).reshape(shape + (self.dimension,))

    def derivative(self, t) -> np.ndarray:
        """First derivative dC/dt, shape t.shape + (d,): (A' - w' C) / w."""
        shape, a, da = self._homogeneous(t, True)
        w = self._divide(a, np.ravel(t))
        point = a[:, :-1] / w[:, None]
        der = (da[:, :-1] - da[:, -1:] * point) / w[:, None]
        return der.reshape(shape + (self.dimension,))

    def sample(self, count: int = 64) -> np.ndarray:
        """`count` points evenly spaced in parameter over the domain, (count, d)."""
        return self.evaluate(np.linspace(*self.domain, count))

    def _check_denominator(self) -> None:
        t0, t1 = self.domain
        inner = np.unique(self.knots[(self.knots >= t0) & (self.knots <= t1)])
        t = np.unique(np.concatenate([np.linspace(a, b, 65) for a, b in zip(inner[:-1], inner[1:])]))
        n = len(self.control_points)
        w = basis.basis_matrix(self.knots, self.degree, n, t) @ self.weights
        k = denominator_problem(w, np.abs(self.weights).max())
        if k is not None:
            raise DenominatorError(
                "weights",
                f"the denominator sum(w N) vanishes inside the domain (near t = {fmt(t[k])}); "
                "negative or zero weights are allowed only where the weighted sum stays non-zero",
            )

    def __repr__(self) -> str:
        return f"NurbsCurve(degree={self.degree}, points={len(self.control_points)}, domain={self.domain})"
