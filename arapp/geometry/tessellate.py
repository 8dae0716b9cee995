"""Triangle meshes of NURBS surfaces: uniform u-v grids and adaptive refinement.

Every quad p_ij p_(i+1)j p_(i+1)(j+1) p_i(j+1) becomes two triangles with the
same winding, so face normals follow S_u x S_v; vertex normals are analytic.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import trimesh

from .errors import GeometryError

if TYPE_CHECKING:  # annotations only: surface.py imports this module for NurbsSurface.tessellate
    from .surface import NurbsSurface

MAX_SAMPLES = 1025  # per direction: a cap so a bad tolerance cannot eat the memory


def default_tolerance(surface: NurbsSurface) -> float:
    """Chord tolerance when none is given: 1/500 of the control net's diagonal."""
    lo, hi = surface.bounds()
    return 2e-3 * float(np.linalg.norm(hi - lo))


def _pair(value, field: str):
    vals = np.broadcast_to(np.asarray(value, dtype=float), (2,))
    if not np.isfinite(vals).all() or (vals <= 0).any():
        raise GeometryError(field, f"must be positive, got {value!r}")
    return vals


def parameter_grid(surface: NurbsSurface, count=None, step=None, tolerance=None):
    """Sample parameters (us, vs) for a grid: by count, by step, or adaptive to a tolerance.

    count: samples per direction (int or (n_u, n_v), >= 2); step: parameter step
    per direction; tolerance: chord tolerance in model units (the default when
    nothing is given).
    """
    (u0, u1), (v0, v1) = surface.domain
    if count is not None:
        n = _pair(count, "count")
        if (n < 2).any() or (n != np.round(n)).any():
            raise GeometryError("count", f"must be whole numbers >= 2, got {count!r}")
        return np.linspace(u0, u1, int(n[0])), np.linspace(v0, v1, int(n[1]))
    if step is not None:
        s = _pair(step, "step")
        nu = min(MAX_SAMPLES, int(np.ceil((u1 - u0) / s[0] - 1e-9)) + 1)
        nv = min(MAX_SAMPLES, int(np.ceil((v1 - v0) / s[1] - 1e-9)) + 1)
        return np.linspace(u0, u1, max(nu, 2)), np.linspace(v0, v1, max(nv, 2))
    tol = default_tolerance(surface) if tolerance is None else float(_pair(tolerance, "tolerance")[0])
    return adaptive_grid(surface, tol)


def _initial(knots: np.ndarray, lo: float, hi: float, degree: int) -> np.ndarray:
    inner = np.unique(knots[(knots >= lo) & (knots <= hi)])
    pieces = max(2, degree)
    return np.unique(np.concatenate([np.linspace(a, b, pieces + 1) for a, b in zip(inner[:-1], inner[1:])]))


def adaptive_grid(surface: NurbsSurface, tolerance: float, max_rounds: int = 12):
    """Tensor grid refined until every chord is within `tolerance` (model units).

    Starts from the distinct knots (creases stay sampled) and splits a u (or v)
    interval wherever the surface at its midpoint, along any sampled v (u), or
    at a quad centre, lies farther than the tolerance from the straight chord.
    Splitting whole rows keeps the grid a tensor grid: no cracks, no T-junctions.
    """
    (u0, u1), (v0, v1) = surface.domain
    us = _initial(surface.knots_u, u0, u1, surface.degree_u)
    vs = _initial(surface.knots_v, v0, v1, surface.degree_v)
    for _ in range(max_rounds):
        pts = surface.evaluate_grid(us, vs)
        um, vm = (us[:-1] + us[1:]) / 2, (vs[:-1] + vs[1:]) / 2
        mid_u = surface.evaluate_grid(um, vs)
        mid_v = surface.evaluate_grid(us, vm)
        centre = surface.evaluate_grid(um, vm)
        err_u = np.linalg.norm(mid_u - (pts[:-1] + pts[1:]) / 2, axis=2).max(axis=1)
        err_v = np.linalg.norm(mid_v - (pts[:, :-1] + pts[:, 1:]) / 2, axis=2).max(axis=0)
        quad = (pts[:-1, :-1] + pts[1:, :-1] + pts[1:, 1:] + pts[:-1, 1:]) / 4
        err_c = np.linalg.norm(centre - quad, axis=2)
        split_u = (err_u > tolerance) | (err_c.max(axis=1) > tolerance)
        split_v = (err_v > tolerance) | (err_c.max(axis=0) > tolerance)
        split_u &= len(us) + split_u.sum() <= MAX_SAMPLES
        split_v &= len(vs) + split_v.sum() <= MAX_SAMPLES
        if not split_u.any() and not split_v.any():
            break
        us = np.sort(np.concatenate([us, um[split_u]]))
        vs = np.sort(np.concatenate([vs, vm[split_v]]))
    return us, vs


def grid_faces(n_u: int, n_v: int) -> np.ndarray:
    """Two triangles per grid quad, (a, b, c) and (a, c, d), vertex index i * n_v + j."""
    i, j = np.meshgrid(np.arange(n_u - 1), np.arange(n_v - 1), indexing="ij")
    a = (i * n_v + j).ravel()
    b, c, d = a + n_v, a + n_v + 1, a + 1
    return np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def sample_grid(surface: NurbsSurface, us: np.ndarray, vs: np.ndarray):
    """Points and unit normals on the grid, each (len(us), len(vs), 3)."""
    pts, su, sv = surface.evaluate_grid(us, vs, derivatives=True)
    normals = surface._unit_normals(us[:, None], vs[None, :], su, sv)
    return pts, normals


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def tessellate_surface(surface: NurbsSurface, count=None, step=None, tolerance=None) -> trimesh.Trimesh:
    """Display mesh of one surface (model units) with analytic vertex normals.

    Zero-area triangles (poles, collapsed rows) are dropped; vertices are not
    welded, so seams keep their analytic normals on both sides.
    """
    us, vs = parameter_grid(surface, count, step, tolerance)
    pts, normals = sample_grid(surface, us, vs)
    verts = pts.reshape(-1, 3)
    faces = grid_faces(len(us), len(vs))
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    scale = max(float(np.linalg.norm(hi - lo)), 1e-300)
    faces = faces[triangle_areas(verts, faces) > 1e-14 * scale * scale]
    normals = normals.reshape(-1, 3)
    used = np.zeros(len(verts), bool)
    used[faces.ravel()] = True
    if not used.all():  # drop vertices only degenerate triangles used (poles)
        new_index = np.cumsum(used) - 1
        verts, normals, faces = verts[used], normals[used], new_index[faces]
    return trimesh.Trimesh(verts, faces, vertex_normals=normals, process=False)
