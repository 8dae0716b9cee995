"""The model as displayed, as a printable solid in the bed frame (mm), and STL/3MF files.

`placed_solid` takes the model's placement on the anchor (size, offset and turn
about the anchor normal, arapp.geometry.placement) to millimetres with the anchor's
out-of-paper normal as +Z, makes it watertight (thickening an open patch),
drops it onto the bed (lowest point at z = 0) and centres it on the bed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

# The mesh formats, their loader (one units rule) and writers live in arapp.exchange; the names stay importable here.
from arapp.exchange.meshes import (  # noqa: F401
    FORMATS,
    MESH_SUFFIXES,
    MeshFileError,
    load_mesh,
    units_to_mm,
    write_atomic,
    write_mesh,
)
from arapp.geometry.placement import Placement

from .profile import load_profile


class ModelDoesNotFitError(ValueError):
    """The model (with its skirt) is larger than the printer's build volume."""


def clean_mesh(mesh: trimesh.Trimesh, merge_digits: int = 4) -> trimesh.Trimesh:
    """A copy with coincident vertices merged (to 10^-digits mm, the bound tolerance for files of limited
    precision), faces with a repeated vertex dropped and, for a closed mesh, outward winding."""
    m = trimesh.Trimesh(vertices=np.asarray(mesh.vertices, dtype=float), faces=np.asarray(mesh.faces), process=False)
    m.merge_vertices(digits_vertex=merge_digits)
    f = m.faces
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    if not keep.all():
        m.update_faces(keep)
    m.remove_unreferenced_vertices()
    if not m.is_winding_consistent:
        trimesh.repair.fix_winding(m)
    if m.is_watertight and m.volume < 0:
        m.invert()
    return m


def thicken(mesh: trimesh.Trimesh, thickness: float) -> trimesh.Trimesh:
    """A closed solid from an open surface patch: offset both ways along the vertex normals by
    thickness/2 and stitch the boundary with a side wall. Units are the mesh's."""
    m = clean_mesh(mesh)
    n = len(m.vertices)
    normals = m.vertex_normals
    top = m.vertices + normals * thickness / 2
    bottom = m.vertices - normals * thickness / 2
    faces = [m.faces, m.faces[:, ::-1] + n]
    edges = m.edges  # directed, in face winding order
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = edges[counts[inverse.ravel()] == 1]
    if len(boundary):
        a, b = boundary[:, 0], boundary[:, 1]
        faces.append(np.column_stack([b, a, a + n]))
        faces.append(np.column_stack([b, a + n, b + n]))
    solid = trimesh.Trimesh(vertices=np.vstack([top, bottom]), faces=np.vstack(faces), process=True)
    if solid.is_watertight and solid.volume < 0:
        solid.invert()
    return solid


def _is_model(obj) -> bool:
    return not isinstance(obj, trimesh.Trimesh) and callable(getattr(obj, "mesh", None))


def _model_matrix(model, placement: Placement | None) -> np.ndarray:
    """4x4 from the model's units to the placement frame (mm, +Z out of the paper), as the model is displayed."""
    if placement is None:
        return np.asarray(model.placement_matrix("mm"), dtype=float)
    return np.asarray(placement.matrix(model.bounds(), "mm"), dtype=float)


def placed_solid(mesh_or_model, placement: Placement | None = None, *, thickness_mm: float = 2.0, profile=None,
                 center: bool = True) -> trimesh.Trimesh:
    """The model as displayed, as a watertight solid in the bed frame (mm).

    `mesh_or_model`: an arapp.geometry Model or a trimesh.Trimesh.
    `placement`: where the model sits on the anchor (arapp.geometry.placement.Placement;
    a dict from outside becomes one through `Placement.from_any`), or None: the model's own
    placement; for a Trimesh, None means it is already in mm with +Z up.
    A model's open surfaces are closed by `Model.solid` with walls of
    `thickness_mm` (in placed millimetres); an open Trimesh patch is thickened
    likewise. The result's lowest point is at z = 0 and, with `center`, its
    bounding box is centred on the bed of `profile` (the generic printer when None).
    """
    if _is_model(mesh_or_model):
        model = mesh_or_model
        M = _model_matrix(model, placement)
        scale = abs(np.linalg.det(M[:3, :3])) ** (1.0 / 3.0)
        if not scale > 0:
            raise ValueError("the placement scales the model to nothing")
        mesh = model.solid(thickness=thickness_mm / scale) if callable(getattr(model, "solid", None)) else model.mesh()
        mesh = mesh.copy()
        mesh.apply_transform(M)
    elif isinstance(mesh_or_model, trimesh.Trimesh):
        mesh = mesh_or_model.copy()
        if placement is not None:
            mesh.apply_transform(placement.matrix(mesh.bounds, "mm"))
    else:
        raise TypeError(f"placed_solid needs a trimesh.Trimesh or an arapp.geometry Model, got {type(mesh_or_model).__name__}")
    if len(mesh.faces) == 0:
        raise MeshFileError("the model has no triangles to print")
    mesh = clean_mesh(mesh)
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        trimesh.repair.fix_winding(mesh)
    if not mesh.is_watertight:
        mesh = thicken(mesh, thickness_mm)
    if mesh.volume < 0:
        mesh.invert()
    return drop_on_bed(mesh, profile, center=center)


def drop_on_bed(mesh: trimesh.Trimesh, profile=None, center: bool = True) -> trimesh.Trimesh:
    """The mesh moved so its lowest point is at z = 0 and (with `center`) its bounding box centred on the bed."""
    profile = profile or load_profile()
    lo, hi = mesh.bounds
    shift = np.array([0.0, 0.0, -lo[2]])
    if center:
        cx, cy = profile.bed_center
        shift[:2] = [cx - (lo[0] + hi[0]) / 2, cy - (lo[1] + hi[1]) / 2]
    out = mesh.copy()
    out.apply_translation(shift)
    return out


def fit_on_bed(mesh: trimesh.Trimesh, profile, margin: float = 0.0, scale_to_fit: bool = False,
               center: bool = True) -> tuple[trimesh.Trimesh, float]:
    """The mesh on the bed (z from 0, centred when asked) and the scale applied (1 unless scaled to fit).

    `margin` mm must stay free around the footprint (the skirt). A model that
    does not fit raises ModelDoesNotFitError, unless `scale_to_fit` shrinks it
    uniformly until it does.
    """
    extent = mesh.extents
    bed = profile.bed
    room = np.array([bed.width - 2 * margin, bed.depth - 2 * margin, bed.height])
    scale = 1.0
    if np.any(extent > room + 1e-9):
        if not scale_to_fit:
            raise ModelDoesNotFitError(
                f"the model is {extent[0]:.1f} x {extent[1]:.1f} x {extent[2]:.1f} mm"
                + (f" (plus {margin:.1f} mm of skirt around it)" if margin > 0 else "")
                + f" but the bed of '{profile.name}' is {bed.width:g} x {bed.depth:g} x {bed.height:g} mm; "
                "make it smaller (--size MM) or let arapp shrink it (--scale-to-fit)"
            )
        if np.any(room <= 0):
            raise ModelDoesNotFitError(f"the skirt margin ({margin:.1f} mm) leaves no room on the bed of '{profile.name}'")
        scale = float(np.min(room / np.maximum(extent, 1e-12))) * 0.999
        mesh = mesh.copy()
        mesh.apply_scale(scale)
    return drop_on_bed(mesh, profile, center=center), scale


def scale_to_size(mesh: trimesh.Trimesh, size_mm: float) -> trimesh.Trimesh:
    """The mesh scaled uniformly so its largest extent is `size_mm` (as a model's placement size)."""
    if not size_mm > 0:
        raise ValueError(f"--size must be a positive number of millimetres, got {size_mm}")
    ref = float(np.max(mesh.extents))
    if not ref > 0:
        raise ValueError("the mesh has no extent; it cannot be scaled to a size")
    out = mesh.copy()
    out.apply_scale(size_mm / ref)
    return out


def write_stl(mesh: trimesh.Trimesh, path: str | Path) -> Path:
    """Write a binary STL (millimetres) to `path` whatever its suffix; atomic."""
    return write_atomic(path, FORMATS[".stl"].writer(mesh))


def write_3mf(mesh: trimesh.Trimesh, path: str | Path) -> Path:
    """Write a 3MF file (unit: millimetre) to `path` whatever its suffix; atomic."""
    return write_atomic(path, FORMATS[".3mf"].writer(mesh))
