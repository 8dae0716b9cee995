"""NURBS evaluation against geomdl and against the defining formulas (docs/domain.md §1)."""

from math import comb

import numpy as np
from geomdl import NURBS

from arapp.geometry import NurbsCurve, NurbsSurface
from arapp.geometry import basis

EXAMPLE_P = [
    [[-2, 2, 1], [-1, 2, 1], [0, 2, 0], [1, 2, 0], [2, 2, 2]],
    [[-2, 1, 2], [-1, 1, 0], [0, 1, 0], [1, 1, 1], [2, 1, 0]],
    [[-2, 0, 0], [-1, 0, 0], [0, 0, 0], [1, 0, 1], [2, 0, 0]],
    [[-2, -1, 0], [-1, -1, 0], [0, -1, 1], [1, -1, 2], [2, -1, 1]],
    [[-2, -2, -1], [-1, -2, 0], [0, -2, 0], [1, -2, -1], [2, -2, 1]],
]
EXAMPLE_W = [[1, 3, 1, 1, 1], [1, 1, 1, 0.5, 1], [4, 0.5, 1, 4, 1], [1, 1, 1, 1, 1], [2, 3, 1, 2, 1]]
EXAMPLE_KU = [0, 1, 2, 3, 4, 5, 6, 7]
EXAMPLE_KV = [-3, -2, 0, 1, 1, 2, 3, 4]


def geomdl_surface(s: NurbsSurface) -> NURBS.Surface:
    g = NURBS.Surface(normalize_kv=False)
    g.degree_u, g.degree_v = s.degree_u, s.degree_v
    g.ctrlpts_size_u, g.ctrlpts_size_v = s.shape
    g.ctrlpts = s.control_points.reshape(-1, 3).tolist()
    g.weights = s.weights.ravel().tolist()
    g.knotvector_u = s.knots_u.tolist()
    g.knotvector_v = s.knots_v.tolist()
    return g


def random_knots(rng, n: int, p: int, clamped: bool, double: bool) -> np.ndarray:
    """n control points, degree p; optionally one interior knot doubled."""
    if clamped:
        inner = np.sort(rng.uniform(0, 1, n - p - 1))
        if double and len(inner) >= 2:
            k = rng.integers(0, len(inner) - 1)
            inner[k + 1] = inner[k]
        return np.concatenate([np.zeros(p + 1), inner, np.ones(p + 1)])
    t = np.sort(rng.uniform(-3, 7, n + p + 1))
    if double and n > p + 1:
        k = rng.integers(p + 1, n)  # inside the domain (t_p, t_(n+1))
        t[k] = t[k - 1]
    return t


def random_surface(rng, p: int, q: int, clamped: bool, double: bool) -> NurbsSurface:
    nu, nv = p + 1 + rng.integers(0, 5), q + 1 + rng.integers(0, 5)
    pts = rng.uniform(-5, 5, (nu, nv, 3))
    w = rng.uniform(0.2, 5.0, (nu, nv))
    return NurbsSurface(pts, w, random_knots(rng, nu, p, clamped, double), random_knots(rng, nv, q, clamped, double))


def params(s: NurbsSurface, rng, k: int = 12):
    (u0, u1), (v0, v1) = s.domain
    # The ends and every knot in the domain, plus random interior values.
    us = np.concatenate([[u0, u1], s.knots_u[(s.knots_u > u0) & (s.knots_u < u1)], rng.uniform(u0, u1, k)])
    vs = np.concatenate([[v0, v1], s.knots_v[(s.knots_v > v0) & (s.knots_v < v1)], rng.uniform(v0, v1, k)])
    n = max(len(us), len(vs))
    return np.resize(us, n), np.resize(rng.permutation(vs), n)


def test_random_rational_surfaces_match_geomdl():
    rng = np.random.default_rng(1)
    worst = 0.0
    count = 0
    for p in range(1, 6):
        for q in range(1, 6):
            for clamped in (True, False):
                double = bool((p + q) % 2)
                s = random_surface(rng, p, q, clamped, double)
                g = geomdl_surface(s)
                us, vs = params(s, rng)
                ref = np.array([g.evaluate_single((float(a), float(b))) for a, b in zip(us, vs)])
                mine = s.evaluate(us, vs)
                worst = max(worst, np.abs(mine - ref).max())
                count += 1
    assert count == 50
    assert worst < 1e-9


def test_random_surface_derivatives_and_normals_match_geomdl():
    rng = np.random.default_rng(2)
    for p, q, clamped in [(2, 3, True), (3, 3, False), (5, 1, True), (4, 2, False)]:
        s = random_surface(rng, p, q, clamped, True)
        g = geomdl_surface(s)
        us, vs = params(s, rng, 6)
        ref = np.array([g.derivatives(float(a), float(b), order=1) for a, b in zip(us, vs)])
        pt, su, sv = s.derivatives(us, vs)
        scale = np.abs(ref).max()
        assert np.abs(pt - ref[:, 0, 0]).max() < 1e-9
        assert np.abs(su - ref[:, 1, 0]).max() < 1e-9 * scale
        assert np.abs(sv - ref[:, 0, 1]).max() < 1e-9 * scale
        n_ref = np.cross(ref[:, 1, 0], ref[:, 0, 1])
        n_ref /= np.linalg.norm(n_ref, axis=1, keepdims=True)
        assert np.abs(s.normal(us, vs) - n_ref).max() < 1e-8


def test_worked_5x5_example_matches_geomdl():
    s = NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)
    assert (s.degree_u, s.degree_v) == (2, 2)
    assert s.domain == ((2.0, 5.0), (0.0, 2.0))
    g = geomdl_surface(s)
    us, vs = np.linspace(2, 5, 31), np.linspace(0, 2, 21)
    ref = np.array([[g.evaluate_single((a, b)) for b in vs] for a in us])
    uu, vv = np.meshgrid(us, vs, indexing="ij")
    assert np.abs(s.evaluate(uu, vv) - ref).max() < 1e-9  # scattered-point path
    assert np.abs(s.evaluate(us[:, None], vs[None, :]) - ref).max() < 1e-9  # outer grid
    assert np.abs(s.evaluate_grid(us, vs) - ref).max() < 1e-9


def test_negative_weights_evaluate_where_denominator_is_nonzero():
    s = NurbsSurface(EXAMPLE_P, np.array(EXAMPLE_W) * [[1, 1, 1, 1, 1]] * 1.0 - 0.0, EXAMPLE_KU, EXAMPLE_KV)
    w = np.array(EXAMPLE_W, float)
    w[0, 0] = -0.05  # small enough that sum(w N N) stays positive
    s = NurbsSurface(EXAMPLE_P, w, EXAMPLE_KU, EXAMPLE_KV)
    g = geomdl_surface(s)
    us, vs = np.linspace(2, 5, 9), np.linspace(0, 2, 7)
    ref = np.array([[g.evaluate_single((a, b)) for b in vs] for a in us])
    assert np.abs(s.evaluate_grid(us, vs) - ref).max() < 1e-9
    # All weights negative: the same surface (numerator and denominator both flip).
    flipped = NurbsSurface(EXAMPLE_P, -np.array(EXAMPLE_W, float), EXAMPLE_KU, EXAMPLE_KV)
    plain = NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)
    assert np.abs(flipped.evaluate_grid(us, vs) - plain.evaluate_grid(us, vs)).max() < 1e-12


def test_curves_match_geomdl():
    rng = np.random.default_rng(3)
    for p in range(1, 6):
        for clamped in (True, False):
            n = p + 1 + int(rng.integers(0, 6))
            c = NurbsCurve(rng.uniform(-3, 3, (n, 3)), rng.uniform(0.3, 3, n), random_knots(rng, n, p, clamped, p > 1))
            g = NURBS.Curve(normalize_kv=False)
            g.degree = p
            g.ctrlpts = c.control_points.tolist()
            g.weights = c.weights.tolist()
            g.knotvector = c.knots.tolist()
            t0, t1 = c.domain
            ts = np.concatenate([[t0, t1], rng.uniform(t0, t1, 20)])
            ref = np.array([g.derivatives(float(t), order=1) for t in ts])
            assert np.abs(c.evaluate(ts) - ref[:, 0]).max() < 1e-9
            assert np.abs(c.derivative(ts) - ref[:, 1]).max() < 1e-9 * np.abs(ref[:, 1]).max()


def test_broadcasting_shapes():
    s = NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)
    u = np.linspace(2, 5, 4)[:, None, None]
    v = np.linspace(0, 2, 5)[None, :, None] * np.ones((1, 1, 2))
    assert s.evaluate(u, v).shape == (4, 5, 2, 3)
    assert s.evaluate(3.0, 1.0).shape == (3,)
    assert s.normal(u, v).shape == (4, 5, 2, 3)
    assert s.evaluate(np.zeros(0), 0.5).shape == (0, 3)
    assert s.derivatives(np.zeros((0, 2)), 0.5)[2].shape == (0, 2, 3)
    pts = s.evaluate(u, v)
    assert np.array_equal(pts[2, 3, 1], s.evaluate(float(u[2, 0, 0]), float(v[0, 3, 1])))


def test_partition_of_unity_clamped_and_unclamped():
    rng = np.random.default_rng(4)
    for p in range(1, 6):
        for clamped in (True, False):
            n = p + 1 + 4
            t = random_knots(rng, n, p, clamped, p > 1)
            lo, hi = t[p], t[n]
            u = np.concatenate([[lo, hi], rng.uniform(lo, hi, 200)])
            b = basis.basis_matrix(t, p, n, u)
            assert np.abs(b.sum(axis=1) - 1).max() < 1e-13
            assert (b >= -1e-15).all()
            # Consequently a net of one repeated point is that point, whatever the weights.
            s = NurbsSurface(np.full((n, 3, 3), 1.5), rng.uniform(0.5, 2, (n, 3)), t, [0, 0, 0, 1, 1, 1], p, 2)
            assert np.abs(s.evaluate(u[:20], 0.3) - 1.5).max() < 1e-13


def test_basis_matches_cox_de_boor_recursion():
    def cox(i, p, t, u):
        if p == 0:
            return 1.0 if t[i] <= u < t[i + 1] else 0.0
        a = 0.0 if t[i + p] == t[i] else (u - t[i]) / (t[i + p] - t[i]) * cox(i, p - 1, t, u)
        b = 0.0 if t[i + p + 1] == t[i + 1] else (t[i + p + 1] - u) / (t[i + p + 1] - t[i + 1]) * cox(i + 1, p - 1, t, u)
        return a + b

    rng = np.random.default_rng(5)
    t = np.array([-1, 0, 0.5, 0.5, 1.2, 2, 3, 3.5, 4, 5.0])
    p, n = 3, 6
    u = rng.uniform(t[p], t[n], 25)
    ref = np.array([[cox(i, p, t, x) for i in range(n)] for x in u])
    assert np.abs(basis.basis_matrix(t, p, n, u) - ref).max() < 1e-14


def test_local_support():
    rng = np.random.default_rng(6)
    s = random_surface(rng, 3, 2, True, False)
    nu, nv = s.shape
    i, j = 2, 1
    moved = s.control_points.copy()
    moved[i, j] += [0.5, -1.0, 2.0]
    s2 = NurbsSurface(moved, s.weights, s.knots_u, s.knots_v)
    (u0, u1), (v0, v1) = s.domain
    us, vs = np.linspace(u0, u1, 101), np.linspace(v0, v1, 101)
    diff = np.abs(s2.evaluate_grid(us, vs) - s.evaluate_grid(us, vs)).max(axis=2)
    inside_u = (us >= s.knots_u[i]) & (us <= s.knots_u[i + s.degree_u + 1])
    inside_v = (vs >= s.knots_v[j]) & (vs <= s.knots_v[j + s.degree_v + 1])
    assert (diff[~inside_u] == 0).all() and (diff[:, ~inside_v] == 0).all()
    assert diff[np.ix_(inside_u, inside_v)].max() > 0.01


def test_projective_invariance():
    rng = np.random.default_rng(7)
    s = random_surface(rng, 3, 3, False, True)
    m = np.eye(4)
    m[:3, :3] = rng.normal(size=(3, 3))
    m[:3, 3] = rng.normal(size=3)
    m[3, :3] = [0.01, -0.02, 0.015]  # perspective part; w stays positive on the net
    m[3, 3] = 1.0
    (u0, u1), (v0, v1) = s.domain
    us, vs = np.linspace(u0, u1, 13), np.linspace(v0, v1, 11)
    pts = s.evaluate_grid(us, vs)
    hom = np.concatenate([pts, np.ones(pts.shape[:2] + (1,))], axis=2) @ m.T
    mapped = s.transformed(m).evaluate_grid(us, vs)
    assert np.abs(mapped - hom[..., :3] / hom[..., 3:]).max() < 1e-9


def test_bezier_equals_bernstein():
    rng = np.random.default_rng(8)
    for m, n in [(1, 1), (2, 3), (3, 3), (4, 2), (5, 5)]:
        pts = rng.uniform(-1, 1, (m + 1, n + 1, 3))
        w = rng.uniform(0.5, 2, (m + 1, n + 1))
        s = NurbsSurface(pts, w, [0] * (m + 1) + [1] * (m + 1), [0] * (n + 1) + [1] * (n + 1))
        u = np.concatenate([[0, 1], rng.uniform(0, 1, 20)])
        v = np.concatenate([[1, 0], rng.uniform(0, 1, 20)])
        bu = np.array([[comb(m, i) * x**i * (1 - x) ** (m - i) for i in range(m + 1)] for x in u])
        bv = np.array([[comb(n, j) * y**j * (1 - y) ** (n - j) for j in range(n + 1)] for y in v])
        num = np.einsum("ki,kj,ij,ijc->kc", bu, bv, w, pts)
        den = np.einsum("ki,kj,ij->k", bu, bv, w)
        assert np.abs(s.evaluate(u, v) - num / den[:, None]).max() < 1e-12
        # Corner points lie on the surface.
        assert np.abs(s.evaluate([0, 1, 0, 1], [0, 0, 1, 1]) - pts[[0, -1, 0, -1], [0, 0, -1, -1]]).max() < 1e-14


def test_exact_at_domain_ends_and_continuity_at_simple_knots():
    t = [0, 0, 0, 0, 0.3, 0.6, 1, 1, 1, 1]
    rng = np.random.default_rng(9)
    c = NurbsCurve(rng.uniform(-1, 1, (6, 3)), rng.uniform(0.5, 2, 6), t)
    assert np.abs(c.evaluate(1.0) - c.control_points[-1]).max() < 1e-15
    assert np.abs(c.evaluate(0.0) - c.control_points[0]).max() < 1e-15
    # C^(p-1) = C^2 at simple knots: first derivative continuous across 0.3 and 0.6.
    for k in (0.3, 0.6):
        left, right = c.derivative(k - 1e-9), c.derivative(k + 1e-9)
        assert np.abs(left - right).max() < 1e-6


def test_normal_is_unit_and_matches_faces_at_sphere_pole():
    from arapp.geometry import construct

    s = construct.sphere(2.0)
    n = s.normal([0.0, 1.0, 0.3], [0.2, 0.7, 0.5])
    assert np.allclose(np.linalg.norm(n, axis=1), 1)
    assert np.allclose(n[0], [0, 0, 1], atol=1e-5) and np.allclose(n[1], [0, 0, -1], atol=1e-5)
    p = s.evaluate(0.3, 0.5)
    assert np.allclose(n[2], p / 2, atol=1e-12)


def test_knot_refinement_keeps_the_spline_and_certifies_sign():
    rng = np.random.default_rng(10)
    for p, clamped in [(2, False), (3, True), (4, False)]:
        n = p + 5
        t = random_knots(rng, n, p, clamped, True)
        c = rng.uniform(-1, 1, (n, 2))
        new_t, new_c = basis.refine_coefficients(t, p, c, axis=0)
        u = rng.uniform(t[p], t[n], 100)
        assert np.abs(basis.basis_matrix(new_t, p, len(new_c), u) @ new_c - basis.basis_matrix(t, p, n, u) @ c).max() < 1e-12
    # A positive function with a negative coefficient: undecided, then proven positive after refinement.
    t = np.array([0, 0, 0, 1, 2, 2, 2.0])
    c = np.array([[1.0], [-0.2], [1.0], [1.0]])
    assert basis.local_sign(c, (t, np.array([0.0, 1.0])), (2, 0)) == 0
    assert (basis.basis_matrix(t, 2, 4, np.linspace(0, 2, 201)) @ c > 0).all()
    for _ in range(3):
        t, c = basis.refine_coefficients(t, 2, c)
    assert basis.local_sign(c, (t, np.array([0.0, 1.0])), (2, 0)) == 1
