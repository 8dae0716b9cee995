"""Tessellation, display lines and watertight solids."""

import numpy as np
import pytest
import trimesh

from arapp.geometry import NurbsSurface, construct
from arapp.geometry.solid import SolidError, surface_solid

from test_geometry_eval import EXAMPLE_KU, EXAMPLE_KV, EXAMPLE_P, EXAMPLE_W


def example():
    return NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)


def test_grid_by_count_and_step():
    s = example()
    m = s.tessellate(count=(11, 7))
    assert len(m.vertices) == 77 and len(m.faces) == 2 * 10 * 6
    (u0, u1), (v0, v1) = s.domain
    assert np.allclose(m.vertices[0], s.evaluate(u0, v0)) and np.allclose(m.vertices[-1], s.evaluate(u1, v1))
    m2 = s.tessellate(step=0.5)  # u range 3, v range 2 -> 7 x 5 samples
    assert len(m2.vertices) == 35


def test_winding_follows_analytic_normals():
    for s in (example(), construct.sphere(3.0), construct.torus(4, 1)):
        m = s.tessellate(count=24)
        vn = m.vertex_normals[m.faces].mean(axis=1)
        assert (np.einsum("ij,ij->i", m.face_normals, vn) > 0).all()
        assert np.allclose(np.linalg.norm(m.vertex_normals, axis=1), 1)
        assert m.is_winding_consistent


def test_vertex_normals_are_analytic():
    s = example()
    m = s.tessellate(count=9)
    (u0, u1), (v0, v1) = s.domain
    uu, vv = np.meshgrid(np.linspace(u0, u1, 9), np.linspace(v0, v1, 9), indexing="ij")
    _, su, sv = s.derivatives(uu, vv)
    n = np.cross(su, sv)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    assert np.abs(m.vertex_normals - n.reshape(-1, 3)).max() < 1e-12


def test_degenerate_triangles_dropped_at_poles():
    m = construct.sphere(1.0).tessellate(count=(9, 13))
    assert len(m.faces) == 2 * 8 * 12 - 2 * 12  # one triangle per quad at each pole row is empty
    assert (m.area_faces > 0).all()
    assert len(m.vertices) == 9 * 13 - 2  # the pole copy only empty triangles used is removed ...
    assert np.abs(m.vertex_normals - m.vertices).max() < 1e-6  # ... analytic normals kept, poles included


@pytest.mark.parametrize("tol", [0.05, 0.005])
def test_adaptive_refinement_meets_chord_tolerance(tol):
    s = example()
    m = s.tessellate(tolerance=tol)
    rng = np.random.default_rng(21)
    (u0, u1), (v0, v1) = s.domain
    pts = s.evaluate(rng.uniform(u0, u1, 400), rng.uniform(v0, v1, 400))
    _, dist, _ = trimesh.proximity.closest_point(m, pts)
    assert dist.max() <= tol
    coarse = s.tessellate(tolerance=tol * 10)
    assert len(coarse.faces) < len(m.faces)


def test_isolines_and_control_net():
    s = example()
    lines = s.isolines(n_u=3, n_v=4, samples=20)
    assert len(lines) == 7 and all(line.shape == (20, 3) for line in lines)
    (u0, u1), (v0, v1) = s.domain
    assert np.allclose(lines[0], s.evaluate(u0, np.linspace(v0, v1, 20)))
    assert np.allclose(lines[3], s.evaluate(np.linspace(u0, u1, 20), v0))
    net = s.control_net()
    assert len(net) == 10 and np.array_equal(net[0], np.array(EXAMPLE_P[0], float))


def _check_solid(mesh):
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert mesh.is_volume


def test_closed_surfaces_weld_into_solids():
    sphere = surface_solid(construct.sphere(10.0), thickness=1.0, tolerance=0.01)
    _check_solid(sphere)
    assert abs(sphere.volume - 4 / 3 * np.pi * 1000) / (4 / 3 * np.pi * 1000) < 0.005
    torus = surface_solid(construct.torus(10.0, 3.0), thickness=1.0, tolerance=0.01)
    _check_solid(torus)
    assert abs(torus.volume - 2 * np.pi**2 * 10 * 9) / (2 * np.pi**2 * 90) < 0.005


def test_open_patches_are_thickened():
    plate = construct.bezier_patch([[[0, 0, 0], [0, 10, 0]], [[10, 0, 0], [10, 10, 0]]])
    solid = surface_solid(plate, thickness=2.0)
    _check_solid(solid)
    assert solid.volume == pytest.approx(200.0)
    assert np.allclose(solid.bounds, [[0, 0, -2], [10, 10, 0]])  # offset against the +z normal
    tube = surface_solid(construct.cylinder(5.0, 10.0), thickness=1.0, tolerance=0.005)
    _check_solid(tube)
    assert tube.volume == pytest.approx(np.pi * (25 - 16) * 10, rel=0.005)
    _check_solid(surface_solid(example(), thickness=0.1))
    cup = surface_solid(construct.cone(5.0, 8.0), thickness=0.5)  # apex is a pole
    _check_solid(cup)


def test_open_surface_without_thickness_is_refused():
    with pytest.raises(SolidError, match="thickness"):
        surface_solid(construct.disk(1.0), thickness=0)


def test_three_sided_patch_from_a_collapsed_row():
    net = np.array([[[0, 0, 0]] * 3, [[5, -3, 1], [5, 0, 2], [5, 3, 1]], [[10, -5, 0], [10, 0, 0], [10, 5, 0]]], float)
    s = construct.bezier_patch(net)
    m = s.tessellate(count=9)
    assert (m.area_faces > 0).all() and len(m.faces) == 2 * 8 * 8 - 8
    _check_solid(surface_solid(s, thickness=0.5))


def test_several_surfaces_united_into_one_solid():
    from arapp.geometry.solid import shells_solid

    ball, lid = construct.sphere(10.0), construct.disk(15.0, center=(0, 0, 20))
    solid = shells_solid([ball, lid], thickness=1.0, tolerance=0.01)
    _check_solid(solid)
    separate = surface_solid(ball, 1.0, 0.01).volume + surface_solid(lid, 1.0, 0.01).volume
    assert solid.volume == pytest.approx(separate, rel=1e-6)
    assert len(solid.split(only_watertight=True)) == 2
