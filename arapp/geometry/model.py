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
from .solid import SolidError, shells_solid
from .surface import NurbsSurface
from .tessellate import default_tolerance

FORMAT_VERSION = 1
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
MAX_SIZE_MM = 10_000.0  # 10 m: larger than any printer; past it the float maths of placement breaks down
DEFAULT_COLOR = (0.8, 0.55, 0.2, 1.0)
DEFAULT_THICKNESS_MM = 2.0


@dataclass
class Placement:
    """Where the model sits on its marker.

    size_mm: largest extent of the model on the marker, millimetres;
    offset: translation in the marker frame (x right, y up the marker, z out
    of it), millimetres, applied last; rotation_deg: rotations about x, y, z
    (applied in that order) before scaling.
    """

    size_mm: float = 50.0
    offset: tuple = (0.0, 0.0, 0.0)
    rotation_deg: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        # A single angle turns the model about the marker normal (z), as the GUI edits it.
        if np.isscalar(self.rotation_deg):
            self.rotation_deg = (0.0, 0.0, float(self.rotation_deg))
        self.size_mm = float(self.size_mm)
        self.offset = tuple(float(x) for x in self.offset)
        self.rotation_deg = tuple(float(x) for x in self.rotation_deg)

    @classmethod
    def from_any(cls, value, default: "Placement | None" = None) -> "Placement":
        """A Placement from a Placement, None (the default), or a dict with some of size_mm, offset (mm)
        and rotation_deg (x, y, z degrees, or one angle about the anchor normal); missing keys from `default`."""
        base = default or cls()
        if value is None:
            return base
        if isinstance(value, Placement):
            return value
        if not isinstance(value, dict):
            raise TypeError(f"a placement must be a Placement or a dict, got {type(value).__name__}")
        unknown = set(value) - {"size_mm", "offset", "rotation_deg"}
        if unknown:
            raise ModelError("placement", f"unknown key(s) {', '.join(sorted(unknown))}; "
                             "use size_mm, offset (mm) and rotation_deg (x, y, z degrees)")
        size = check_size_mm(value.get("size_mm", base.size_mm), "placement.size_mm")
        place = cls(size, value.get("offset", base.offset), value.get("rotation_deg", base.rotation_deg))
        if len(place.offset) != 3 or len(place.rotation_deg) != 3:
            raise ModelError("placement", "offset and rotation_deg need three components (x, y, z)")
        return place

    def rotation(self) -> np.ndarray:
        """3x3 rotation R = Rz @ Ry @ Rx."""
        ax, ay, az = np.radians(self.rotation_deg)
        rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
        ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
        rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
        return rz @ ry @ rx


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
        """4x4 map from model units to the marker frame (mm, or m with unit="m").

        Rotates by placement.rotation_deg, scales so the largest extent is
        placement.size_mm, centres the model over the marker (x, y) standing on
        it (lowest z = 0), then adds placement.offset.
        """
        rot = self.placement.rotation()
        lo, hi = self.bounds()
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        rc = corners @ rot.T
        extent = float((rc.max(axis=0) - rc.min(axis=0)).max())
        scale = self.placement.size_mm / extent if extent > 0 else 1.0
        rlo, rhi = rc.min(axis=0) * scale, rc.max(axis=0) * scale
        shift = -np.array([(rlo[0] + rhi[0]) / 2, (rlo[1] + rhi[1]) / 2, rlo[2]]) + np.asarray(self.placement.offset)
        m = np.eye(4)
        m[:3, :3] = scale * rot
        m[:3, 3] = shift
        if unit == "m":
            m[:3] *= 1e-3
        elif unit != "mm":
            raise ValueError(f"unit must be 'mm' or 'm', got {unit!r}")
        return m

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
    """Load a JSON model (see models/README.md) or a mesh file (.stl/.obj/.ply/.3mf/.glb)."""
    path = Path(path)
    if not path.exists():
        raise ModelError(str(path), "no such file")
    if path.suffix.lower() in MESH_SUFFIXES:
        return _load_mesh(path)
    data = read_json(path, "model", lambda message: ModelError("", message), expect=None)
    try:
        model = model_from_dict(data, default_name=path.stem)
    except GeometryError as exc:
        # name the file too: the GUI and CLI show this message as it is
        raise type(exc)(f"{path}: {exc.field}" if exc.field else str(path), exc.problem) from None
    model.path = path
    return model


def check_size_mm(size, where: str = "size") -> float:
    """`size` (mm) as a float when it is a usable part size, 0 < size <= MAX_SIZE_MM; else ModelError at `where`."""
    try:
        value = float(size)
    except (TypeError, ValueError):
        raise ModelError(where, f"must be a number of millimetres, got {size!r}") from None
    if not (math.isfinite(value) and 0 < value <= MAX_SIZE_MM):
        raise ModelError(where, f"must be a positive number of millimetres up to {fmt(MAX_SIZE_MM)}, got {size!r}")
    return value


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
