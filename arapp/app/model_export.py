"""Export the shown model from the app: the edited model as placed, as a mesh file or as NURBS JSON. No Qt.

Mesh files (the suffixes of `arapp.exchange.meshes.EXPORT_SUFFIXES`, written
through its writer table) hold the printable solid in millimetres exactly as
the model is placed on the anchor (size, rotation; standing on z = 0, centred
over the origin): what a print of it would make. The JSON file holds the
edited model in its own units (the control points as edited, the placement as
set), readable by `arapp.geometry.load_model` and the app.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from arapp.exchange.meshes import EXPORT_SUFFIXES, write_atomic, write_mesh
from arapp.printing.export import placed_solid

JSON_SUFFIX = ".json"


def export_suffixes() -> tuple[str, ...]:
    """What the export dialog offers: the mesh formats arapp writes, then the NURBS JSON."""
    return tuple(EXPORT_SUFFIXES) + (JSON_SUFFIX,)


def export_filter() -> str:
    """A file-dialog filter string, one entry per format (STL first: what printers take)."""
    names = {".stl": "STL mesh", ".3mf": "3MF mesh", ".obj": "OBJ mesh", ".ply": "PLY mesh", ".glb": "glTF binary",
             JSON_SUFFIX: "arapp NURBS model (edited)"}
    order = [".stl", ".3mf", ".obj"] + [s for s in export_suffixes() if s not in (".stl", ".3mf", ".obj")]
    return ";;".join(f"{names.get(s, s)} (*{s})" for s in order if s in export_suffixes())


def placed_model(model, placement):
    """A shallow copy of `model` carrying `placement` (the model itself is left as it is)."""
    placed = copy.copy(model)
    if placement is not None:
        placed.placement = placement
    return placed


def model_to_dict(model, placement=None) -> dict:
    """The model as an arapp-model version 1 document (models/README.md): NURBS surfaces with their control
    points (model units), weights, knots and degrees. ValueError for a mesh-only model (no surfaces)."""
    surfaces = getattr(model, "surfaces", None)
    if not surfaces:
        raise ValueError(f"{getattr(model, 'name', 'the model')} is a mesh, not NURBS surfaces; "
                         "export it as STL, 3MF or OBJ instead")
    p = placement if placement is not None else model.placement

    def floats(a):
        return np.asarray(a, dtype=float).tolist()

    return {
        "format": "arapp-model",
        "version": 1,
        "name": str(model.name),
        "units": str(model.units),
        "color": [float(c) for c in model.color],
        "placement": {"size_mm": float(p.size_mm), "offset": [float(x) for x in p.offset],
                      "rotation_deg": [float(x) for x in p.rotation_deg]},
        "surfaces": [{"type": "nurbs", "control_points": floats(s.control_points), "weights": floats(s.weights),
                      "knots_u": floats(s.knots_u), "knots_v": floats(s.knots_v),
                      "degree_u": int(s.degree_u), "degree_v": int(s.degree_v)} for s in surfaces],
    }


def export_model(model, placement, path, thickness_mm: float = 2.0) -> Path:
    """Write the edited `model` at `placement` to `path`; its suffix picks the format (export_suffixes()).

    Raises ValueError with one line naming the file and what to do when the
    suffix is unknown or the model cannot be written that way.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in export_suffixes():
        raise ValueError(f"{p}: cannot export to {suffix or 'a file without a suffix'}; "
                         f"use one of {', '.join(export_suffixes())}")
    if suffix == JSON_SUFFIX:
        text = json.dumps(model_to_dict(model, placement), indent=1)
        return write_atomic(p, text.encode("utf-8"))
    placed = placed_model(model, placement)
    solid = placed_solid(placed, thickness_mm=thickness_mm, center=False)
    return write_mesh(solid, p)
