"""Constructions: revolution, extrusion, ruled, loft, degree elevation, primitives."""

import numpy as np
import pytest
from geomdl import NURBS

from arapp.geometry import NurbsCurve, construct


def _grid(s, n=41):
    (u0, u1), (v0, v1) = s.domain
    return np.linspace(u0, u1, n), np.linspace(v0, v1, n)


def test_seven_point_circle_is_exact():
    c = construct.circle(3.0, center=(1, 2, 5))
    t = np.linspace(0, 1, 1001)
    p = c.evaluate(t)
    r = np.linalg.norm(p[:, :2] - [1, 2], axis=1)
    assert np.abs(r - 3).max() / 3 < 1e-15 * 10
    assert np.allclose(p[:, 2], 5)


def test_revolution_points_lie_exactly_at_profile_radius():
    rng = np.random.default_rng(11)
    prof = NurbsCurve(np.column_stack([rng.uniform(0.5, 4, 7), np.sort(rng.uniform(-2, 2, 7))]),
                      rng.uniform(0.5, 2, 7), degree=3)
    s = construct.revolve(prof)
    us, vs = rng.uniform(*s.domain[0], 300), rng.uniform(*s.domain[1], 300)
    pts = s.evaluate(us, vs)
    ref = prof.evaluate(us)  # (r, z)
    rel = np.abs(np.hypot(pts[:, 0], pts[:, 1]) - ref[:, 0]) / ref[:, 0]
    assert rel.max() < 1e-12
    assert np.abs(pts[:, 2] - ref[:, 1]).max() < 1e-12
    # The v = 0 iso-curve is the profile itself in the xz plane.
    assert np.abs(s.evaluate(us, 0.0)[:, [0, 2]] - ref).max() < 1e-12


def test_sphere_and_torus_satisfy_implicit_equations():
    rng = np.random.default_rng(12)
    u, v = rng.uniform(0, 1, 500), rng.uniform(0, 1, 500)
    p = construct.sphere(7.0, center=(1, -2, 3)).evaluate(u, v) - [1, -2, 3]
    assert np.abs(np.linalg.norm(p, axis=1) - 7).max() / 7 < 1e-12
    q = construct.torus(5.0, 1.5).evaluate(u, v)
    assert np.abs(np.hypot(np.hypot(q[:, 0], q[:, 1]) - 5, q[:, 2]) - 1.5).max() < 1e-12
    # Normals point away from the centre / the tube's core circle.
    n = construct.torus(5.0, 1.5).normal(u, v)
    core = np.column_stack([q[:, :2] / np.hypot(q[:, 0], q[:, 1])[:, None] * 5, np.zeros(500)])
    assert (np.einsum("ij,ij->i", n, q - core) > 0.99 * 1.5).all()


def test_cylinder_cone_disk():
    rng = np.random.default_rng(13)
    u, v = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    cyl = construct.cylinder(2.0, 5.0).evaluate(u, v)
    assert np.allclose(np.hypot(cyl[:, 0], cyl[:, 1]), 2, rtol=1e-13)
    assert np.allclose(cyl[:, 2], 5 * (1 - u))
    cone = construct.cone(3.0, 6.0).evaluate(u, v)
    assert np.allclose(np.hypot(cone[:, 0], cone[:, 1]), 3 * cone[:, 2] / -6 + 3, atol=1e-12)
    d = construct.disk(4.0)
    assert np.allclose(np.hypot(*d.evaluate(u, v)[:, :2].T), 4 * u)
    assert np.allclose(d.normal(u[:5] * 0.9 + 0.05, v[:5]), [0, 0, 1])
    assert np.allclose(construct.disk(4.0, facing_up=False).normal(0.5, 0.3), [0, 0, -1])


def test_extrusion():
    c = NurbsCurve([[0, 0], [1, 2], [3, -1], [4, 0]], [1, 2, 0.5, 1])
    s = construct.extrude(c, [0, 0.5, 3])
    assert s.shape == (4, 2) and s.degree_v == 1 and list(s.knots_v) == [0, 0, 1, 1]
    t = np.linspace(0, 1, 50)
    base = np.column_stack([c.evaluate(t), np.zeros(50)])
    for v in (0.0, 0.25, 1.0):
        assert np.abs(s.evaluate(t, v) - (base + v * np.array([0, 0.5, 3]))).max() < 1e-13


def test_degree_elevation_and_knot_merging_keep_the_curve():
    rng = np.random.default_rng(14)
    c = NurbsCurve(rng.uniform(-1, 1, (6, 3)), rng.uniform(0.5, 2, 6), [0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1])
    other = NurbsCurve([[0, 0, 0], [1, 1, 1], [2, 0, 1], [3, 0, 0], [4, 1, 0]], knots=[0, 0, 0, 0, 0.4, 1, 1, 1, 1])
    g = NURBS.Curve()  # the original curve, evaluated independently
    g.degree = 2
    g.ctrlpts = c.control_points.tolist()
    g.weights = c.weights.tolist()
    g.knotvector = c.knots.tolist()
    up, other_up = construct.make_compatible([c, other])
    assert up.degree == other_up.degree == 3
    # Raising the degree by one raises each interior knot's multiplicity by one; 0.4 is merged in.
    assert np.allclose(up.knots, [0, 0, 0, 0, 0.25, 0.25, 0.4, 0.5, 0.5, 0.75, 0.75, 1, 1, 1, 1])
    assert np.array_equal(up.knots, other_up.knots)
    t = np.linspace(0, 1, 200)
    ref = np.array([g.evaluate_single(float(x)) for x in t])
    assert np.abs(up.evaluate(t) - ref).max() < 1e-12
    assert np.abs(other_up.evaluate(t) - other.evaluate(t)).max() < 1e-12


def test_ruled_surface_between_different_degrees_and_knots():
    circ = construct.circle(20.0)
    sq = NurbsCurve([[17, 0, 35], [17, 17, 35], [-17, 17, 35], [-17, 0, 35], [-17, -17, 35], [17, -17, 35], [17, 0, 35]],
                    knots=[0, 0, 0.125, 0.375, 0.5, 0.625, 0.875, 1, 1])
    s = construct.ruled(circ, sq)
    assert s.degree_u == 2 and s.degree_v == 1
    t = np.linspace(0, 1, 400)
    assert np.abs(s.evaluate(t, 0.0) - circ.evaluate(t)).max() < 1e-12
    assert np.abs(s.evaluate(t, 1.0) - sq.evaluate(t)).max() < 1e-12
    # Every iso-u line is straight: the midpoint of v lies on the segment between its ends.
    a, b, m = s.evaluate(t, 0.0), s.evaluate(t, 1.0), s.evaluate(t, 0.5)
    cross = np.linalg.norm(np.cross(m - a, b - a), axis=1) / np.linalg.norm(b - a, axis=1)
    assert cross.max() < 1e-9


def test_loft_passes_through_every_profile():
    sections = [
        NurbsCurve([[x, -w, 1], [x, -w, -1], [x, w, -1], [x, w, 1]], degree=3)
        for x, w in [(0, 1), (2, 2), (5, 1.5), (6, 0.5)]
    ]
    sections[2] = NurbsCurve([[5, -1.5, 1], [5, -1.5, -1], [5, 1.5, -1], [5, 1.5, 1]], [1, 0.6, 0.6, 1], degree=2)
    s = construct.loft(sections, degree_v=3)
    assert s.degree_v == 3 and s.shape[1] == 4
    # Recover each profile's parameter v_k from the knot construction: iso-curve there is the profile.
    chords = np.linalg.norm(np.diff(np.stack([c.control_points for c in construct.make_compatible(sections)]),
                                    axis=0), axis=2).mean(axis=1)
    vk = np.concatenate([[0], np.cumsum(chords)]) / chords.sum()
    t = np.linspace(0, 1, 100)
    for c, v in zip(sections, vk):
        assert np.abs(s.evaluate(t, v) - c.evaluate(t)).max() < 1e-10


def test_bezier_patch_is_clamped_single_span():
    pts = np.random.default_rng(15).uniform(size=(3, 4, 3))
    s = construct.bezier_patch(pts)
    assert (s.degree_u, s.degree_v) == (2, 3)
    assert np.allclose(s.evaluate(0, 0), pts[0, 0]) and np.allclose(s.evaluate(1, 1), pts[-1, -1])


@pytest.mark.parametrize("call, field", [
    (lambda: construct.sphere(-1), "radius"),
    (lambda: construct.torus(2, 3), "minor_radius"),
    (lambda: construct.extrude(construct.circle(1), [0, 0, 0]), "direction"),
    (lambda: construct.loft([construct.circle(1)]), "curves"),
    (lambda: construct.revolve(NurbsCurve([[1, 0], [-1, 1]])), "profile.control_points[1]"),
    (lambda: construct.revolve(NurbsCurve([[1, 0.5, 0], [2, 0, 1]])), "profile.control_points"),
])
def test_construction_errors_name_the_field(call, field):
    with pytest.raises(ValueError) as info:
        call()
    assert info.value.field == field
