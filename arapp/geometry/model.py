"""Model files: JSON NURBS models (schema in models/README.md) and plain meshes.

`load_model(path)` validates everything and raises ModelError (a ValueError)
naming the exact field, e.g. ``surfaces[0].knots_u: must be non-decreasing,
but 0.5 follows 1 at index 2``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from arapp.exchange.files import DocumentFormat, register_document
from arapp.exchange.jsonfile import read_json
from arapp.exchange.meshes import EXPORT_SUFFIXES, MESH_SUFFIXES, MeshFileError, load_mesh, write_mesh

from . import construct
from .curve import NurbsCurve
from .errors import GeometryError, ModelError, fmt
from .library import model_path
from .placement import MAX_SIZE_MM, Placement, check_size_mm  # noqa: F401 - MAX_SIZE_MM: part of this module's API
from .solid import SolidError, shells_solid
from .surface import NurbsSurface
from .tessellate import default_tolerance

FORMAT_VERSION = 1
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
DEFAULT_COLOR = (0.8, 0.55, 0.2, 1.0)
DEFAULT_THICKNESS_MM = 2.0


@dataclass
class Model:
    """A loaded model: NURBS surfaces (or, for mesh files, a mesh) plus display data.

    Coordinates are in `units` ("mm", "cm", "m", "in"); color is RGBA in 0..1.
    """

    name: str
    units: str = "mm"
    color: tuple = DEFAULT_COLOR
    placement: Placement = field(default_factory=Placement)
    surfaces: list = field(default_factory=list)
    path: Path | None = None
    source_mesh: trimesh.Trimesh | None = None
    _meshes: dict = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------- geometry
    def mesh(self, tolerance: float | None = None) -> trimesh.Trimesh:
        """Display mesh in model units: all surfaces tessellated to `tolerance` (chord, model units)."""
        if self.source_mesh is not None:
            return self.source_mesh.copy(include_cache=True)
        if tolerance is None:
            tolerance = self.default_tolerance()
        if tolerance not in self._meshes:  # the GUI asks again and again; surfaces are immutable
            parts = [s.tessellate(tolerance=tolerance) for s in self.surfaces]
            self._meshes[tolerance] = parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)
        return self._meshes[tolerance].copy(include_cache=True)  # keeps the analytic normals

    def default_tolerance(self) -> float:
        """Chord tolerance giving a smooth display: 1/500 of the largest net diagonal."""
        return max(default_tolerance(s) for s in self.surfaces)

    def bounds(self) -> np.ndarray:
        """(2, 3) bounding box of the geometry, model units."""
        if self.source_mesh is not None:
            return np.array(self.source_mesh.bounds)
        # The display mesh (cached) is within the default chord tolerance of the surfaces.
        return np.array(self.mesh().bounds)

    def solid(self, thickness: float | None = None, tolerance: float | None = None) -> trimesh.Trimesh:
        """Watertight, outward-wound solid in model units.

        thickness: wall thickness (model units) for open surfaces; default the
        model-unit length that becomes 2 mm at the placement size.
        """
        if self.source_mesh is not None:
            mesh = self.source_mesh.copy()
            mesh.merge_vertices()
            trimesh.repair.fix_normals(mesh)
            if not mesh.is_watertight:
                raise SolidError(f"{self.path or self.name}: the mesh is not watertight, so it cannot be printed as is")
            return mesh
        if thickness is None:
            lo, hi = self.bounds()
            extent = float((hi - lo).max())
            thickness = DEFAULT_THICKNESS_MM * extent / self.placement.size_mm
        return shells_solid(self.surfaces, thickness, tolerance)

    def lines(self, n_u: int = 8, n_v: int = 8, samples: int = 64) -> list[np.ndarray]:
        """Isolines and control-net polylines of every surface, each (k, 3), model units."""
        out = []
        for s in self.surfaces:
            out += s.isolines(n_u, n_v, samples)
            out += s.control_net()
        return out

    # ------------------------------------------------------------ placement
    def placement_matrix(self, unit: str = "mm") -> np.ndarray:
        """4x4 map from model units to the marker frame (mm, or m with unit="m"): `Placement.matrix` of
        this model's bounds."""
        return self.placement.matrix(self.bounds(), unit)

    def transformed(self, matrix) -> "Model":
        """A copy with the geometry mapped by a 4x4 matrix (nets mapped exactly)."""
        m = np.asarray(matrix, dtype=float)
        mesh = None
        if self.source_mesh is not None:
            mesh = self.source_mesh.copy()
            mesh.apply_transform(m)
        return Model(self.name, self.units, self.color, self.placement,
                     [s.transformed(m) for s in self.surfaces], self.path, mesh)

    def printable(self, size_mm: float | None = None, thickness_mm: float = DEFAULT_THICKNESS_MM,
                  tolerance_mm: float | None = None) -> trimesh.Trimesh:
        """Watertight solid in millimetres, rotated as placed, scaled to size_mm
        (default placement.size_mm), standing on z = 0 centred over the origin."""
        place = Placement(size_mm if size_mm is not None else self.placement.size_mm, (0.0, 0.0, 0.0),
                          self.placement.rotation_deg)
        check_size_mm(place.size_mm, "size")
        if not thickness_mm > 0 or not math.isfinite(thickness_mm):
            raise ModelError("thickness", f"must be a positive number of millimetres, got {thickness_mm!r}")
        if thickness_mm > place.size_mm:
            raise ModelError("thickness", f"{fmt(thickness_mm)} mm is more than the part's size "
                             f"({fmt(place.size_mm)} mm); give a thinner wall")
        if tolerance_mm is not None and not (math.isfinite(tolerance_mm) and 0 < tolerance_mm <= place.size_mm / 10):
            raise ModelError("tolerance", f"must be a positive number of millimetres up to a tenth of the size "
                             f"({fmt(place.size_mm / 10)} mm), got {tolerance_mm!r}")
        placed = Model(self.name, self.units, self.color, place, self.surfaces, self.path, self.source_mesh,
                       self._meshes)  # same surfaces: share the tessellation cache
        mm = placed.transformed(placed.placement_matrix("mm"))
        mm.units = "mm"
        tol = tolerance_mm if tolerance_mm is not None else 0.002 * place.size_mm
        if self.source_mesh is not None:
            return mm.solid()
        return mm.solid(thickness=thickness_mm, tolerance=tol)

    def export(self, path, size_mm: float | None = None, thickness_mm: float = DEFAULT_THICKNESS_MM,
               tolerance_mm: float | None = None) -> trimesh.Trimesh:
        """Write the printable solid (mm) to .stl/.obj/.ply/.3mf/.glb; returns the mesh written."""
        path = Path(path)
        if path.suffix.lower() not in EXPORT_SUFFIXES:
            raise ModelError("output", f"unsupported format {path.suffix or '(none)'!r} for {path}; "
                             f"use one of {', '.join(EXPORT_SUFFIXES)}")
        mesh = self.printable(size_mm, thickness_mm, tolerance_mm)
        if not (mesh.is_watertight and mesh.volume > 0):
            raise ModelError("output", f"the solid for {path} has no volume at this size; "
                             "choose another --size or --thickness")
        write_mesh(mesh, path)  # temporary file renamed into place: no half-written file on failure
        return mesh


# ---------------------------------------------------------------- loading
def load_model(path) -> Model:
    """Load a JSON model (see models/README.md) or a mesh file (.stl/.obj/.ply/.3mf/.glb); a bare name that is no
    file names a model of the library (`vase`: models/vase.json, arapp.geometry.library)."""
    path = model_path(path)
    if path.suffix.lower() in MESH_SUFFIXES:
        return _load_mesh(path)
    if path.suffix.lower() != ".json":
        raise ModelError(str(path), f"not a model file ({path.suffix or 'no extension'}); give a NURBS model "
                                    f"(.json, models/README.md) or a mesh ({', '.join(MESH_SUFFIXES)})")
    data = read_json(path, "model", lambda message: ModelError("", message), expect=None)
    try:
        model = model_from_dict(data, default_name=path.stem)
    except GeometryError as exc:
        # name the file too: the GUI and CLI show this message as it is
        raise type(exc)(f"{path}: {exc.field}" if exc.field else str(path), exc.problem) from None
    model.path = path
    return model


def _load_mesh(path: Path) -> Model:
    """A mesh file as a Model in millimetres (arapp.exchange.meshes: the one loader and units rule)."""
    try:
        mesh = load_mesh(path)
    except MeshFileError as exc:
        raise ModelError("", str(exc)) from None
    size = float(np.max(mesh.extents)) if np.max(mesh.extents) > 0 else 50.0
    return Model(path.stem, "mm", DEFAULT_COLOR, Placement(size_mm=size), [], path, mesh)


register_document("model", DocumentFormat("arapp NURBS model", (".json",), load_model, ModelError,
                                          "models/README.md"))

KEYS = {"format", "version", "name", "units", "color", "placement", "surfaces", "description"}
SURFACE_KEYS = {
    "nurbs": {"control_points", "weights", "knots_u", "knots_v", "degree_u", "degree_v"},
    "bezier": {"control_points", "weights"},
    "revolve": {"profile"},
    "extrude": {"curve", "direction"},
    "ruled": {"curves"},
    "loft": {"curves", "degree_v"},
    "sphere": {"radius", "center"},
    "torus": {"major_radius", "minor_radius", "center"},
    "cylinder": {"radius", "height", "center"},
    "cone": {"radius", "height", "top_radius", "center"},
    "disk": {"radius", "center", "facing_up"},
}
CURVE_KEYS = {"control_points", "weights", "knots", "degree"}


def _need(d: dict, key: str, where: str):
    if key not in d:
        raise ModelError(f"{where}.{key}" if where else key, "is required but missing")
    return d[key]


def _check_keys(d, allowed: set, where: str) -> None:
    if not isinstance(d, dict):
        raise ModelError(where, f"must be a JSON object, got {type(d).__name__}")
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise ModelError(f"{where}.{unknown[0]}" if where else unknown[0],
                         f"unknown key; expected one of {', '.join(sorted(allowed))}")


def _number(value, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ModelError(where, f"must be a finite number, got {json.dumps(value)}")
    if positive and value <= 0:
        raise ModelError(where, f"must be positive, got {fmt(value)}")
    return float(value)


def _vector(value, n: int, where: str) -> tuple:
    if not isinstance(value, list) or len(value) != n:
        raise ModelError(where, f"must be a list of {n} numbers, got {json.dumps(value)}")
    return tuple(_number(x, f"{where}[{i}]") for i, x in enumerate(value))


def _curve(d, where: str) -> NurbsCurve:
    _check_keys(d, CURVE_KEYS, where)
    try:
        return NurbsCurve(_need(d, "control_points", where), d.get("weights"), d.get("knots"), d.get("degree"))
    except ModelError:
        raise
    except GeometryError as exc:
        raise ModelError(f"{where}.{exc.field}", exc.problem) from exc


def _surface(d, where: str) -> NurbsSurface:
    if not isinstance(d, dict):
        raise ModelError(where, f"must be a JSON object, got {type(d).__name__}")
    kind = d.get("type", "nurbs")
    if kind not in SURFACE_KEYS:
        raise ModelError(f"{where}.type", f"unknown surface type {json.dumps(kind)}; expected one of "
                         f"{', '.join(SURFACE_KEYS)}")
    _check_keys(d, SURFACE_KEYS[kind] | {"type", "name"}, where)
    center = _vector(d["center"], 3, f"{where}.center") if "center" in d else (0.0, 0.0, 0.0)
    try:
        if kind == "nurbs":
            return NurbsSurface(_need(d, "control_points", where), d.get("weights"), d.get("knots_u"),
                                d.get("knots_v"), d.get("degree_u"), d.get("degree_v"))
        if kind == "bezier":
            return construct.bezier_patch(_need(d, "control_points", where), d.get("weights"))
        if kind == "revolve":
            return construct.revolve(_curve(_need(d, "profile", where), f"{where}.profile"))
        if kind == "extrude":
            return construct.extrude(_curve(_need(d, "curve", where), f"{where}.curve"), _need(d, "direction", where))
        if kind in ("ruled", "loft"):
            curves = _need(d, "curves", where)
            if not isinstance(curves, list):
                raise ModelError(f"{where}.curves", "must be a list of curves")
            if kind == "ruled" and len(curves) != 2:
                raise ModelError(f"{where}.curves", f"a ruled surface needs exactly 2 curves, got {len(curves)}")
            parsed = [_curve(c, f"{where}.curves[{i}]") for i, c in enumerate(curves)]
            if kind == "ruled":
                return construct.ruled(*parsed)
            return construct.loft(parsed, d.get("degree_v", 3))
        radius = _number(_need(d, "radius", where), f"{where}.radius", positive=True) if kind != "torus" else None
        if kind == "sphere":
            return construct.sphere(radius, center)
        if kind == "torus":
            return construct.torus(_number(_need(d, "major_radius", where), f"{where}.major_radius", True),
                                   _number(_need(d, "minor_radius", where), f"{where}.minor_radius", True), center)
        if kind == "cylinder":
            return construct.cylinder(radius, _number(_need(d, "height", where), f"{where}.height", True), center)
        if kind == "cone":
            top = _number(d.get("top_radius", 0.0), f"{where}.top_radius")
            return construct.cone(radius, _number(_need(d, "height", where), f"{where}.height", True), top, center)
        facing = d.get("facing_up", True)
        if not isinstance(facing, bool):
            raise ModelError(f"{where}.facing_up", f"must be true or false, got {json.dumps(facing)}")
        return construct.disk(radius, center, facing)
    except ModelError:
        raise
    except GeometryError as exc:
        raise ModelError(f"{where}.{exc.field}", exc.problem) from exc


def model_from_dict(data, default_name: str = "model") -> Model:
    """Validate a parsed JSON model and build it; ModelError names the bad field."""
    _check_keys(data, KEYS, "")
    if data.get("format", "arapp-model") != "arapp-model":
        raise ModelError("format", f"must be \"arapp-model\", got {json.dumps(data['format'])}")
    version = _need(data, "version", "")
    if version != FORMAT_VERSION:
        raise ModelError("version", f"this arapp reads version {FORMAT_VERSION}, got {json.dumps(version)}")
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise ModelError("name", f"must be a non-empty string, got {json.dumps(name)}")
    units = data.get("units", "mm")
    if units not in UNITS_MM:
        raise ModelError("units", f"must be one of {', '.join(UNITS_MM)}, got {json.dumps(units)}")
    color = DEFAULT_COLOR
    if "color" in data:
        c = data["color"]
        if not isinstance(c, list) or len(c) not in (3, 4):
            raise ModelError("color", f"must be [r, g, b] or [r, g, b, a] in 0..1, got {json.dumps(c)}")
        color = tuple(_number(x, f"color[{i}]") for i, x in enumerate(c))
        bad = [i for i, x in enumerate(color) if not 0 <= x <= 1]
        if bad:
            raise ModelError(f"color[{bad[0]}]", f"must be between 0 and 1, got {fmt(color[bad[0]])}")
        color = color + (1.0,) * (4 - len(color))
    placement = Placement()
    if "placement" in data:
        p = data["placement"]
        _check_keys(p, {"size_mm", "offset", "rotation_deg"}, "placement")
        placement = Placement(
            check_size_mm(_number(p.get("size_mm", 50.0), "placement.size_mm", positive=True), "placement.size_mm"),
            _vector(p.get("offset", [0, 0, 0]), 3, "placement.offset"),
            _vector(p.get("rotation_deg", [0, 0, 0]), 3, "placement.rotation_deg"),
        )
    surfaces = _need(data, "surfaces", "")
    if not isinstance(surfaces, list) or not surfaces:
        raise ModelError("surfaces", "must be a non-empty list of surfaces")
    built = [_surface(s, f"surfaces[{i}]") for i, s in enumerate(surfaces)]
    for i, s in enumerate(built):
        lo, hi = s.bounds()
        if not float(np.max(hi - lo)) > 0:
            # a zero-size net has no chord tolerance, no normals and nothing to print
            raise ModelError(f"surfaces[{i}].control_points", "all control points coincide, so the surface is a "
                             "single point; move them apart")
    return Model(name, units, color, placement, built)
