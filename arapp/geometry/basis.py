"""B-spline basis functions (Cox-de Boor), vectorised over parameter arrays.

Conventions (docs/domain.md §1): with n+1 control points and degree p there are
n+p+2 non-decreasing knots t_0..t_(n+p+1); the valid domain is
[t_p, t_(n+1)]. Only the p+1 functions N_(s-p..s),p are non-zero on the span
[t_s, t_(s+1)); at the right end of the domain the last non-empty span is
closed on the right so the last point is exact.
"""

from __future__ import annotations

import numpy as np

from .errors import DomainError, GeometryError, fmt


def finite_array(values, field: str, ndim: int | None = None) -> np.ndarray:
    """`values` as a float array; NaN, infinities, ragged lists and text rejected."""
    try:
        raw = np.asarray(values)
        if raw.dtype.kind not in "iuf":  # None, text, booleans, objects: find the culprit
            raise TypeError
        if isinstance(values, (list, tuple)) and raw.size <= 100_000 and _first_bad_entry(values, field)[1]:
            raise TypeError  # a JSON true/false hidden among numbers
        arr = raw.astype(float)
    except (TypeError, ValueError):
        where, problem = _first_bad_entry(values, field)
        raise GeometryError(where, problem or "must be an array of numbers") from None
    if ndim is not None and arr.ndim != ndim:
        raise GeometryError(field, f"must be a {ndim}-D array of numbers, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        where = "[" + "][".join(str(i) for i in idx) + "]" if idx else ""
        raise GeometryError(field + where, f"must be a finite number, got {arr[idx]}")
    return arr


def _first_bad_entry(values, where: str) -> tuple[str, str]:
    """Index path and problem of the first entry that stops `values` being a numeric array."""
    if isinstance(values, (list, tuple)):
        shapes = []
        for i, item in enumerate(values):
            if isinstance(item, (list, tuple)):
                sub = _first_bad_entry(item, f"{where}[{i}]")
                if sub[1]:
                    return sub
                shapes.append(np.shape(np.asarray(item, dtype=float)))
            elif isinstance(item, bool) or not isinstance(item, (int, float)):
                return f"{where}[{i}]", f"must be a number, got {item!r}"
            else:
                shapes.append(())
        for i, shape in enumerate(shapes[1:], start=1):
            if shape != shapes[0]:
                return f"{where}[{i}]", f"has shape {shape}, unlike the first entry's {shapes[0]}; rows must have equal lengths"
        return where, ""
    return where, f"must be an array of numbers, got {values!r}"


def check_knots(knots, n_points: int, degree: int | None, field: str) -> tuple[np.ndarray, int]:
    """Validate a knot vector for `n_points` control points; return (knots, degree).

    The degree, when None, is implied by the count: len(knots) - n_points - 1.
    """
    t = finite_array(knots, field, ndim=1)
    if degree is None:
        degree = len(t) - n_points - 1
        if degree < 1:
            raise GeometryError(
                field,
                f"{len(t)} knots for {n_points} control points imply degree {degree}; "
                f"give at least {n_points + 2} knots (degree >= 1)",
            )
    else:
        if isinstance(degree, bool) or int(degree) != degree or degree < 1:
            raise GeometryError(field.replace("knots", "degree"), f"must be an integer >= 1, got {degree!r}")
        degree = int(degree)
        if len(t) != n_points + degree + 1:
            raise GeometryError(
                field,
                f"expected {n_points + degree + 1} knots for {n_points} control points of degree "
                f"{degree} (count + degree + 1), got {len(t)}",
            )
    if n_points < degree + 1:
        raise GeometryError(field, f"degree {degree} needs at least {degree + 1} control points, got {n_points}")
    drops = np.nonzero(np.diff(t) < 0)[0]
    if drops.size:
        i = int(drops[0]) + 1
        raise GeometryError(field, f"must be non-decreasing, but {fmt(t[i])} follows {fmt(t[i - 1])} at index {i}")
    values, counts = np.unique(t, return_counts=True)
    too_many = counts > degree + 1
    if too_many.any():
        k = int(np.argmax(too_many))
        raise GeometryError(
            field,
            f"knot {fmt(values[k])} is repeated {counts[k]} times; at most degree + 1 = "
            f"{degree + 1} (more leaves a basis function identically zero)",
        )
    if not t[degree] < t[n_points]:
        raise GeometryError(
            field,
            f"empty domain: knots[{degree}] = {fmt(t[degree])} equals knots[{n_points}] = "
            f"{fmt(t[n_points])}; the domain [t_p, t_(n+1)] needs distinct ends",
        )
    return t, degree


def clamped_uniform_knots(n_points: int, degree: int, start: float = 0.0, end: float = 1.0) -> np.ndarray:
    """Clamped knots with uniform interior spacing on [start, end]."""
    inner = np.linspace(start, end, n_points - degree + 1)
    return np.concatenate([np.full(degree, start), inner, np.full(degree, end)])


def find_spans(knots: np.ndarray, degree: int, n_points: int, u: np.ndarray, field: str = "u") -> np.ndarray:
    """Span index s per parameter with t_s <= u < t_(s+1), s in [p, n]; u flat.

    Parameters a hair outside the domain (relative 1e-12) are treated as the end;
    farther ones raise DomainError.
    """
    lo, hi = knots[degree], knots[n_points]
    slack = 1e-12 * max(1.0, abs(lo), abs(hi), hi - lo)
    if u.size and (u.min() < lo - slack or u.max() > hi + slack):
        bad = u[(u < lo - slack) | (u > hi + slack)][0]
        raise DomainError(field, f"parameter {fmt(bad)} is outside the domain [{fmt(lo)}, {fmt(hi)}]")
    span = np.searchsorted(knots, u, side="right") - 1
    # The right end belongs to the last non-empty span, closed on the right.
    last = int(np.searchsorted(knots, hi, side="left")) - 1
    span = np.where(u >= hi, last, span)
    return np.clip(span, degree, last)


def basis_functions(knots: np.ndarray, degree: int, span: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Non-zero basis values N_(s-p+k),p(u), k = 0..p, shape (len(u), p+1).

    Piegl & Tiller A2.2 run over all parameters at once; denominators are
    knot differences that include the (non-empty) span, so never zero.
    """
    m = u.shape[0]
    p = degree
    out = np.zeros((m, p + 1))
    out[:, 0] = 1.0
    left = np.empty((m, p + 1))
    right = np.empty((m, p + 1))
    for j in range(1, p + 1):
        left[:, j] = u - knots[span + 1 - j]
        right[:, j] = knots[span + j] - u
        saved = np.zeros(m)
        for r in range(j):
            temp = out[:, r] / (right[:, r + 1] + left[:, j - r])
            out[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        out[:, j] = saved
    return out


def basis_and_derivative(knots: np.ndarray, degree: int, span: np.ndarray, u: np.ndarray):
    """(N, dN/du), each (len(u), p+1), for the non-zero functions on each span.

    N'_(i,p) = p (N_(i,p-1) / (t_(i+p) - t_i) - N_(i+1,p-1) / (t_(i+p+1) - t_(i+1))).
    """
    p = degree
    values = basis_functions(knots, p, span, u)
    lower = basis_functions(knots, p - 1, span, u)  # N_(s-p+1+j),p-1, j = 0..p-1
    deriv = np.zeros_like(values)
    for k in range(p + 1):
        i = span - p + k
        if k >= 1:
            deriv[:, k] += lower[:, k - 1] / (knots[i + p] - knots[i])
        if k <= p - 1:
            deriv[:, k] -= lower[:, k] / (knots[i + p + 1] - knots[i + 1])
    return values, p * deriv


def basis_matrix(knots: np.ndarray, degree: int, n_points: int, u, derivative: bool = False):
    """Dense matrix B (len(u), n_points) with B[k, i] = N_i,p(u_k) (and dB if asked)."""
    u = np.asarray(u, dtype=float).ravel()
    span = find_spans(knots, degree, n_points, u)
    rows = np.arange(u.size)[:, None]
    cols = span[:, None] - degree + np.arange(degree + 1)[None, :]
    if derivative:
        vals, ders = basis_and_derivative(knots, degree, span, u)
    else:
        vals = basis_functions(knots, degree, span, u)
    mat = np.zeros((u.size, n_points))
    mat[rows, cols] = vals
    if not derivative:
        return mat
    dmat = np.zeros((u.size, n_points))
    dmat[rows, cols] = ders
    return mat, dmat


def refine_coefficients(knots: np.ndarray, degree: int, coeffs: np.ndarray, axis: int = 0):
    """Split every knot span of the domain in two: (new clamped knots, new coefficients).

    The spline sum c_i N_i,p restricted to its domain is re-expressed exactly on
    a clamped knot vector with each span's midpoint added (collocation at the
    Greville sites of the new space, which contains the old). As spans shrink
    the coefficients converge to the function's values, so their signs certify
    the sign of the function (convex-hull property).
    """
    n = coeffs.shape[axis]
    lo, hi = knots[degree], knots[n]
    inside = knots[(knots > lo) & (knots < hi)]
    edges = np.unique(np.concatenate([[lo, hi], inside]))
    mids = (edges[:-1] + edges[1:]) / 2
    new = np.concatenate([np.full(degree + 1, lo), np.sort(np.concatenate([inside, mids])), np.full(degree + 1, hi)])
    count = len(new) - degree - 1
    sites = new[np.arange(count)[:, None] + 1 + np.arange(degree)[None, :]].mean(axis=1)
    old_at_sites = basis_matrix(knots, degree, n, sites)
    colloc = basis_matrix(new, degree, count, sites)
    moved = np.moveaxis(coeffs, axis, 0)
    values = np.tensordot(old_at_sites, moved, axes=(1, 0))
    solved = np.linalg.solve(colloc, values.reshape(count, -1)).reshape((count,) + moved.shape[1:])
    return new, np.moveaxis(solved, 0, axis)


def local_sign(coeffs: np.ndarray, knots: tuple, degrees: tuple) -> int:
    """+1 / -1 if on every non-empty span the p+1 (x q+1) coefficients that act
    there are all > 0 / all < 0 (the spline then keeps that sign: convex
    combination), 0 when undecided."""
    if (coeffs > 0).all():
        return 1
    if (coeffs < 0).all():
        return -1
    windows = np.lib.stride_tricks.sliding_window_view(coeffs, tuple(d + 1 for d in degrees))
    axes = tuple(range(coeffs.ndim, windows.ndim))
    low, high = windows.min(axis=axes), windows.max(axis=axes)
    # Window k covers span k + p; keep the spans of non-zero length only.
    keep = [np.nonzero(t[d : n] < t[d + 1 : n + 1])[0] for t, d, n in zip(knots, degrees, coeffs.shape)]
    low, high = low[np.ix_(*keep)], high[np.ix_(*keep)]
    if (low > 0).all():
        return 1
    if (high < 0).all():
        return -1
    return 0
