"""Mesh file formats: the one table of suffixes, the one loader (with the one units rule) and the writers.

Units rule: mesh files are read in millimetres. Only a format whose files state
their unit in a field of their own (3MF's `unit` attribute) is converted from
that unit to millimetres; every other format (STL, OBJ, PLY, OFF, glTF/GLB) is
taken as millimetres as it stands, which is also how arapp writes them. (trimesh
labels every glTF "meters" whatever the file holds, so that label is not trusted.)

Adding a format = one `MeshFormat` row in `FORMATS` (trimesh must read it, and
write it when `writer` is set).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh


class MeshFileError(ValueError):
    """A mesh file that cannot be read or written; the message names the file."""


_UNIT_MM = {"mm": 1.0, "millimeter": 1.0, "millimeters": 1.0, "millimetre": 1.0, "cm": 10.0, "centimeter": 10.0,
            "centimeters": 10.0, "m": 1000.0, "meter": 1000.0, "meters": 1000.0, "metre": 1000.0,
            "in": 25.4, "inch": 25.4, "inches": 25.4, "um": 1e-3, "micron": 1e-3, "ft": 304.8, "foot": 304.8}


def units_to_mm(units: str | None) -> float:
    """Millimetres per unit named `units`; None or an unknown name is taken as millimetres."""
    if not units:
        return 1.0
    return _UNIT_MM.get(str(units).strip().lower(), 1.0)


def _stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    return trimesh.exchange.stl.export_stl(mesh)


def _3mf_bytes(mesh: trimesh.Trimesh) -> bytes:
    m = mesh.copy()
    m.units = "millimeters"
    return trimesh.exchange.threemf.export_3MF(m)


def _trimesh_bytes(file_type: str) -> Callable[[trimesh.Trimesh], bytes]:
    def write(mesh: trimesh.Trimesh) -> bytes:
        data = mesh.export(file_type=file_type)
        return data.encode("utf-8") if isinstance(data, str) else data
    return write


@dataclass(frozen=True)
class MeshFormat:
    """One mesh file format: `suffix` (lower case, with the dot), what it is, whether its files
    declare their own unit (then converted to mm on load), and its writer (mesh in mm -> bytes) or None."""

    suffix: str
    name: str
    declares_units: bool = False
    writer: Callable[[trimesh.Trimesh], bytes] | None = None


FORMATS: dict[str, MeshFormat] = {f.suffix: f for f in (
    MeshFormat(".stl", "STL (binary written, ASCII or binary read)", writer=_stl_bytes),
    MeshFormat(".obj", "Wavefront OBJ", writer=_trimesh_bytes("obj")),
    MeshFormat(".ply", "PLY", writer=_trimesh_bytes("ply")),
    MeshFormat(".3mf", "3MF (unit attribute honoured)", declares_units=True, writer=_3mf_bytes),
    MeshFormat(".glb", "binary glTF", writer=_trimesh_bytes("glb")),
    MeshFormat(".gltf", "glTF"),
    MeshFormat(".off", "OFF"),
)}

MESH_SUFFIXES: tuple[str, ...] = tuple(FORMATS)
EXPORT_SUFFIXES: tuple[str, ...] = tuple(s for s, f in FORMATS.items() if f.writer is not None)


def is_mesh_path(path) -> bool:
    """Whether `path` names a mesh file by its suffix (case-insensitive)."""
    return Path(path).suffix.lower() in FORMATS


def file_filter() -> str:
    """The mesh suffixes as a file-dialog pattern: '*.stl *.obj ...'."""
    return " ".join(f"*{s}" for s in MESH_SUFFIXES)


def load_mesh(path) -> trimesh.Trimesh:
    """A triangle mesh in millimetres (units rule in the module docstring).

    Normals in the file are ignored (some exporters write zeros). Raises
    MeshFileError naming the file when it is missing, of an unknown kind,
    unreadable or without triangles.
    """
    p = Path(path)
    fmt = FORMATS.get(p.suffix.lower())
    if fmt is None:
        raise MeshFileError(f"{p}: not a mesh file arapp reads; use one of {', '.join(MESH_SUFFIXES)}")
    if not p.is_file():
        raise MeshFileError(f"{p}: no such mesh file")
    try:
        loaded = trimesh.load(p, force="mesh", process=True)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for malformed files
        raise MeshFileError(f"{p}: cannot read mesh: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshFileError(f"{p}: the file holds no triangles")
    if not np.all(np.isfinite(loaded.vertices)):
        raise MeshFileError(f"{p}: the mesh has non-finite vertex coordinates")
    if fmt.declares_units:
        scale = units_to_mm(getattr(loaded, "units", None))
        if scale != 1.0:
            loaded.apply_scale(scale)
    loaded.units = "millimeters"
    return loaded


def write_atomic(path, data: bytes) -> Path:
    """Write `data` to `path` through a temporary file in the same folder renamed into place,
    so a failed write never leaves a half-written file under the final name."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def write_mesh(mesh: trimesh.Trimesh, path) -> Path:
    """Write `mesh` (millimetres) in the format its suffix names (see EXPORT_SUFFIXES); atomic."""
    p = Path(path)
    fmt = FORMATS.get(p.suffix.lower())
    if fmt is None or fmt.writer is None:
        raise MeshFileError(f"unsupported format {p.suffix or '(none)'!r} for {p}; "
                            f"use one of {', '.join(EXPORT_SUFFIXES)}")
    if len(mesh.faces) == 0:
        raise MeshFileError(f"{p}: nothing to write, the mesh has no triangles")
    return write_atomic(p, fmt.writer(mesh))
