"""Constructions that give exact NURBS nets (docs/domain.md §1).

Curves passed in may be 2-D or 3-D. For `revolve` a 2-D profile point is
(radius, height) and a 3-D one (x, 0, z) in the xz half-plane x >= 0; for all
other constructions 2-D points (x, y) lie in the plane z = 0. Lengths are in
model units.
"""

from __future__ import annotations

import numpy as np

from . import basis
from .curve import NurbsCurve
from .errors import GeometryError, fmt
from .surface import NurbsSurface

# The exact 7-point circle on a square (docs/domain.md §1): unit radius, xy plane.
CIRCLE_POINTS = np.array([[1, 0], [1, 1], [-1, 1], [-1, 0], [-1, -1], [1, -1], [1, 0]], dtype=float)
CIRCLE_WEIGHTS = np.array([1, 0.5, 0.5, 1, 0.5, 0.5, 1])
CIRCLE_KNOTS = np.array([0, 0, 0, 0.25, 0.5, 0.5, 0.75, 1, 1, 1])
# Half of it: a semicircle from angle 0 to 180 degrees.
HALF_POINTS = CIRCLE_POINTS[:4]
HALF_WEIGHTS = CIRCLE_WEIGHTS[:4]
HALF_KNOTS = np.array([0, 0, 0, 0.5, 1, 1, 1])


def _points3(curve: NurbsCurve) -> np.ndarray:
    pts = curve.control_points
    return pts if pts.shape[1] == 3 else np.column_stack([pts, np.zeros(len(pts))])


def _curve3(curve: NurbsCurve) -> NurbsCurve:
    if curve.dimension == 3:
        return curve
    return NurbsCurve(_points3(curve), curve.weights, curve.knots, curve.degree)


# ----------------------------------------------------------------- curves
def line(start, end) -> NurbsCurve:
    """The straight segment start -> end as a degree-1 curve on [0, 1]."""
    return NurbsCurve([start, end], knots=[0, 0, 1, 1])


def circle(radius: float, center=(0.0, 0.0, 0.0)) -> NurbsCurve:
    """Exact full circle in the plane z = center z, counter-clockwise from +x, on [0, 1]."""
    c = np.asarray(center, dtype=float)
    pts = np.column_stack([CIRCLE_POINTS * radius, np.zeros(7)]) + c
    return NurbsCurve(pts, CIRCLE_WEIGHTS, CIRCLE_KNOTS, 2)


def bezier_curve(points, weights=None) -> NurbsCurve:
    """Bézier curve of degree len(points) - 1 on [0, 1] (clamped, no interior knots)."""
    n = len(points)
    return NurbsCurve(points, weights, [0.0] * n + [1.0] * n)


def greville(knots: np.ndarray, degree: int, n: int) -> np.ndarray:
    """Greville abscissae: knot averages, one per basis function (collocation sites)."""
    idx = np.arange(n)[:, None] + 1 + np.arange(degree)[None, :]
    return knots[idx].mean(axis=1)


def refit(curve: NurbsCurve, knots, degree: int) -> NurbsCurve:
    """The same curve on a finer spline space: degree elevation and knot insertion.

    `knots` is clamped on [0, 1] and must contain (after mapping the curve's
    domain linearly onto [0, 1]) each of its interior knots with multiplicity
    at least the original plus the degree raise; then the new space contains
    the curve and collocation at the Greville sites reproduces it exactly (to
    rounding), homogeneous coordinates included.
    """
    knots = np.asarray(knots, dtype=float)
    n = len(knots) - degree - 1
    g = greville(knots, degree, n)
    t0, t1 = curve.domain
    _, hom, _ = curve._homogeneous(t0 + g * (t1 - t0), False)
    colloc = basis.basis_matrix(knots, degree, n, g)
    sol = np.linalg.solve(colloc, hom)
    w = sol[:, -1]
    return NurbsCurve(sol[:, :-1] / w[:, None], w, knots, degree)


def make_compatible(curves: list[NurbsCurve]) -> list[NurbsCurve]:
    """Curves on [0, 1] with one degree and one knot vector, each unchanged in shape.

    Degrees are raised to the highest; knot vectors (domains mapped onto [0, 1])
    are merged, each interior knot taking the largest multiplicity it needs.
    """
    curves = [_curve3(c) for c in curves]
    degree = max(c.degree for c in curves)
    need: dict[float, int] = {}
    for c in curves:
        t0, t1 = c.domain
        inner = c.knots[(c.knots > t0) & (c.knots < t1)]
        values, counts = np.unique(np.round((inner - t0) / (t1 - t0), 14), return_counts=True)
        for val, cnt in zip(values, counts):
            need[float(val)] = max(need.get(float(val), 0), int(cnt) + degree - c.degree)
    interior = [val for val in sorted(need) for _ in range(need[val])]
    knots = np.array([0.0] * (degree + 1) + interior + [1.0] * (degree + 1))
    return [refit(c, knots, degree) for c in curves]


# --------------------------------------------------------------- surfaces
def bezier_patch(control_points, weights=None) -> NurbsSurface:
    """Bézier patch of degree (n_u - 1, n_v - 1) on [0, 1]^2."""
    pts = np.asarray(control_points, dtype=float)
    if pts.ndim != 3:
        raise GeometryError("control_points", f"must have shape (n_u, n_v, 3), got {pts.shape}")
    n_u, n_v = pts.shape[:2]
    return NurbsSurface(pts, weights, [0.0] * n_u + [1.0] * n_u, [0.0] * n_v + [1.0] * n_v)


def extrude(curve: NurbsCurve, direction) -> NurbsSurface:
    """Curve swept along `direction`: rows P and P + direction, v-knots (0, 0, 1, 1)."""
    d = basis.finite_array(direction, "direction", ndim=1)
    if d.shape != (3,) or not np.linalg.norm(d) > 0:
        raise GeometryError("direction", f"must be a non-zero 3-vector, got {d.tolist()}")
    pts = _points3(curve)
    net = np.stack([pts, pts + d], axis=1)
    w = np.stack([curve.weights, curve.weights], axis=1)
    return NurbsSurface(net, w, curve.knots, [0, 0, 1, 1], curve.degree, 1)


def loft(curves: list[NurbsCurve], degree_v: int = 3) -> NurbsSurface:
    """Surface through all profile curves (skinning), u along profiles, v across.

    Profiles are made compatible, then each column of homogeneous control
    points is interpolated across v at chord-length parameters with averaged
    knots (Piegl & Tiller 9.2.1), so iso-curve v_k is profile k exactly.
    """
    if len(curves) < 2:
        raise GeometryError("curves", f"a loft needs at least 2 profile curves, got {len(curves)}")
    if isinstance(degree_v, bool) or int(degree_v) != degree_v or degree_v < 1:
        raise GeometryError("degree_v", f"must be an integer >= 1, got {degree_v!r}")
    prof = make_compatible(curves)
    k = len(prof)
    q = min(int(degree_v), k - 1)
    hom = np.stack([np.column_stack([c.control_points * c.weights[:, None], c.weights]) for c in prof])  # (k, n, 4)
    chords = np.linalg.norm(np.diff(np.stack([c.control_points for c in prof]), axis=0), axis=2).mean(axis=1)
    if not (chords > 0).all():
        i = int(np.argmin(chords > 0))
        raise GeometryError(f"curves[{i + 1}]", "coincides with the previous profile; lofted profiles must differ")
    params = np.concatenate([[0.0], np.cumsum(chords)]) / chords.sum()
    inner = [params[j : j + q].mean() for j in range(1, k - q)]
    knots_v = np.array([0.0] * (q + 1) + inner + [1.0] * (q + 1))
    colloc = basis.basis_matrix(knots_v, q, k, params)
    sol = np.linalg.solve(colloc, hom.reshape(k, -1)).reshape(hom.shape)  # rows along v
    net = sol.transpose(1, 0, 2)  # (n_u, k, 4)
    w = net[..., 3]
    return NurbsSurface(net[..., :3] / w[..., None], w, prof[0].knots, knots_v, prof[0].degree, q)


def ruled(curve_a: NurbsCurve, curve_b: NurbsCurve) -> NurbsSurface:
    """Ruled surface (1 - v) A(u) + v B(u) in homogeneous form, v-knots (0, 0, 1, 1).

    Degrees and knot vectors are made equal first (degree elevation, knot merging).
    """
    return loft([curve_a, curve_b], degree_v=1)


def revolve(profile: NurbsCurve) -> NurbsSurface:
    """Full revolution of a planar profile about the z axis (u: profile, v: angle).

    Each profile control point (r, z), weight w, becomes the exact 7-point circle
    of radius r at height z with weights w * (1, 1/2, 1/2, 1, 1/2, 1/2, 1) and
    v-knots (0, 0, 0, 1/4, 1/2, 1/2, 3/4, 1, 1, 1); every surface point lies at
    the profile point's radius. Normals face outward when the profile runs
    downwards on its outer side (top to bottom).
    """
    pts = profile.control_points
    if pts.shape[1] == 3:
        off = np.abs(pts[:, 1]).max()
        if off > 1e-12 * max(1.0, np.abs(pts).max()):
            raise GeometryError("profile.control_points", f"must lie in the xz plane (y = 0), but |y| reaches {fmt(off)}")
        r, z = pts[:, 0], pts[:, 2]
    else:
        r, z = pts[:, 0], pts[:, 1]
    if (r < 0).any():
        i = int(np.argmax(r < 0))
        raise GeometryError(f"profile.control_points[{i}]", f"radius must be >= 0, got {fmt(r[i])}")
    net = np.empty((len(r), 7, 3))
    net[..., 0] = r[:, None] * CIRCLE_POINTS[None, :, 0]
    net[..., 1] = r[:, None] * CIRCLE_POINTS[None, :, 1]
    net[..., 2] = z[:, None]
    w = profile.weights[:, None] * CIRCLE_WEIGHTS[None, :]
    return NurbsSurface(net, w, profile.knots, CIRCLE_KNOTS, profile.degree, 2)


def _positive(value, field: str) -> float:
    if not np.isfinite(value) or value <= 0:
        raise GeometryError(field, f"must be a positive number, got {value!r}")
    return float(value)


def _moved(surface: NurbsSurface, center) -> NurbsSurface:
    c = basis.finite_array(center, "center", ndim=1)
    if c.shape != (3,):
        raise GeometryError("center", f"must be 3 numbers, got {c.tolist()}")
    return NurbsSurface(surface.control_points + c, surface.weights, surface.knots_u, surface.knots_v,
                        surface.degree_u, surface.degree_v)


def sphere(radius: float, center=(0.0, 0.0, 0.0)) -> NurbsSurface:
    """Sphere: revolution of a half circle from the north pole to the south pole (normals outward)."""
    r = _positive(radius, "radius")
    half = np.column_stack([HALF_POINTS[:, 1], HALF_POINTS[:, 0]]) * r  # (r sin, r cos): north -> south
    return _moved(revolve(NurbsCurve(half, HALF_WEIGHTS, HALF_KNOTS, 2)), center)


def torus(major_radius: float, minor_radius: float, center=(0.0, 0.0, 0.0)) -> NurbsSurface:
    """Torus about z: revolution of a circle of `minor_radius` centred at distance `major_radius`."""
    big, small = _positive(major_radius, "major_radius"), _positive(minor_radius, "minor_radius")
    if small >= big:
        raise GeometryError("minor_radius", f"must be smaller than major_radius ({fmt(big)}), got {fmt(small)}")
    # Clockwise in the (r, z) plane so that normals face outward.
    prof = np.column_stack([big + small * CIRCLE_POINTS[:, 0], -small * CIRCLE_POINTS[:, 1]])
    return _moved(revolve(NurbsCurve(prof, CIRCLE_WEIGHTS, CIRCLE_KNOTS, 2)), center)


def cylinder(radius: float, height: float, center=(0.0, 0.0, 0.0)) -> NurbsSurface:
    """Open cylindrical tube about z from z = 0 to z = height (plus center), normals outward."""
    r, h = _positive(radius, "radius"), _positive(height, "height")
    return _moved(revolve(line([r, h], [r, 0.0])), center)


def cone(radius: float, height: float, top_radius: float = 0.0, center=(0.0, 0.0, 0.0)) -> NurbsSurface:
    """Cone (or frustum when top_radius > 0) about z, base radius at z = 0, open base."""
    r, h = _positive(radius, "radius"), _positive(height, "height")
    if not np.isfinite(top_radius) or top_radius < 0:
        raise GeometryError("top_radius", f"must be >= 0, got {top_radius!r}")
    return _moved(revolve(line([top_radius, h], [r, 0.0])), center)


def disk(radius: float, center=(0.0, 0.0, 0.0), facing_up: bool = True) -> NurbsSurface:
    """Flat disk in the plane z = center z: a revolved segment collapsed at the centre."""
    r = _positive(radius, "radius")
    seg = line([0.0, 0.0], [r, 0.0]) if facing_up else line([r, 0.0], [0.0, 0.0])
    return _moved(revolve(seg), center)
