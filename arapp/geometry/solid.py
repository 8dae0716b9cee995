"""Watertight printable solids from NURBS surfaces.

A surface that closes on itself (seams, poles) is welded into a closed shell.
An open patch is thickened: a copy offset by `thickness` against its normals
(so the outer, normal-facing side keeps its place), the copy's winding
reversed, and the rim between the two closed with quads. Results are
consistently wound with outward normals and positive volume.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .surface import NurbsSurface
from .tessellate import parameter_grid, sample_grid, grid_faces


class SolidError(RuntimeError):
    """A watertight solid could not be made (the surface is too degenerate)."""


def weld(vertices: np.ndarray, tolerance: float):
    """Merge vertices closer than `tolerance`; return (representative index per vertex, unique mask)."""
    pairs = cKDTree(vertices).query_pairs(tolerance, output_type="ndarray")
    n = len(vertices)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n)
    np.minimum.at(first, label, np.arange(n))
    return first[label]


def _codes(pairs_or_triples: np.ndarray, n: int) -> np.ndarray:
    """One int64 per row of vertex indices (< n), equal rows giving equal codes."""
    code = np.zeros(len(pairs_or_triples), dtype=np.int64)
    for col in pairs_or_triples.T:
        code = code * n + col
    return code


def _contains(haystack: np.ndarray, needles: np.ndarray) -> np.ndarray:
    """Membership by sorting: faster than np.isin for large int arrays."""
    ordered = np.sort(haystack)
    pos = np.minimum(np.searchsorted(ordered, needles), len(ordered) - 1)
    return ordered[pos] == needles


def _clean(faces: np.ndarray) -> np.ndarray:
    """Drop faces with a repeated vertex and exact duplicates of another face's vertex set."""
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces = faces[ok]
    n = int(faces.max()) + 1
    if n < 2_000_000:  # n**3 fits in int64
        _, keep = np.unique(_codes(np.sort(faces, axis=1), n), return_index=True)
    else:
        _, keep = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    return faces[np.sort(keep)]


def boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Directed edges (a, b) whose reverse (b, a) belongs to no face, (k, 2)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = int(faces.max()) + 1
    return edges[~_contains(_codes(edges, n), _codes(edges[:, ::-1], n))]


def _finish(vertices: np.ndarray, faces: np.ndarray, what: str) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.remove_unreferenced_vertices()
    if not mesh.is_watertight or not mesh.is_winding_consistent:
        raise SolidError(f"{what}: the tessellation is not a closed, consistently wound shell; "
                         "try a smaller --tolerance or a different thickness")
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def surface_solid(surface: NurbsSurface, thickness: float, tolerance: float | None = None,
                  what: str = "surface") -> trimesh.Trimesh:
    """Watertight solid of one surface (model units): welded if closed, else thickened.

    thickness: wall thickness in model units for open patches (offset against
    the normals); tolerance: chord tolerance of the tessellation.
    """
    us, vs = parameter_grid(surface, tolerance=tolerance)
    pts, normals = sample_grid(surface, us, vs)
    verts = pts.reshape(-1, 3)
    norms = normals.reshape(-1, 3)
    scale = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))
    rep = weld(verts, 1e-7 * scale)
    faces = _clean(rep[grid_faces(len(us), len(vs))])
    rim = boundary_edges(faces)
    if len(rim) == 0:
        return _finish(verts, faces, what)
    if not thickness or not np.isfinite(thickness) or thickness <= 0:
        raise SolidError(f"{what}: the surface is open; give a positive wall thickness to thicken it")
    # One offset direction per welded vertex: the mean normal of its group (poles, seams).
    summed = np.zeros_like(norms)
    np.add.at(summed, rep, norms)
    length = np.linalg.norm(summed, axis=1)
    direction = summed[rep] / np.where(length > 0, length, 1.0)[rep, None]
    inner = verts - thickness * direction
    n = len(verts)
    a, b = rim[:, 0], rim[:, 1]
    sides = np.concatenate([np.column_stack([b, a, a + n]), np.column_stack([b, a + n, b + n])])
    all_faces = np.concatenate([faces, faces[:, ::-1] + n, sides])
    return _finish(np.concatenate([verts, inner]), all_faces, what)


def shells_solid(surfaces: list[NurbsSurface], thickness: float, tolerance: float | None = None) -> trimesh.Trimesh:
    """Watertight solid of several surfaces.

    If their welded shells close up together (a capped cylinder), that is the
    solid; otherwise each surface becomes a solid and the parts are united
    (manifold3d Boolean union).
    """
    if len(surfaces) == 1:
        return surface_solid(surfaces[0], thickness, tolerance, "surfaces[0]")
    verts, faces, offset = [], [], 0
    for s in surfaces:
        us, vs = parameter_grid(s, tolerance=tolerance)
        pts, _ = sample_grid(s, us, vs)
        verts.append(pts.reshape(-1, 3))
        faces.append(grid_faces(len(us), len(vs)) + offset)
        offset += pts.shape[0] * pts.shape[1]
    v, f = np.concatenate(verts), np.concatenate(faces)
    scale = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    f = _clean(weld(v, 1e-6 * scale)[f])
    if len(boundary_edges(f)) == 0:
        mesh = trimesh.Trimesh(v, f, process=False)
        if mesh.is_watertight and mesh.is_winding_consistent:
            return _finish(v, f, "surfaces")
    parts = [surface_solid(s, thickness, tolerance, f"surfaces[{i}]") for i, s in enumerate(surfaces)]
    united = trimesh.boolean.union(parts, engine="manifold")
    return _finish(united.vertices, united.faces, "surfaces")
