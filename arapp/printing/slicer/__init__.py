"""The built-in slicer: a mesh in millimetres to Marlin G-code, layer by layer.

Pipeline: clean and place the mesh on the bed (refusing or shrinking a model
that does not fit) -> uniform layer planes -> contour loops -> layer regions
-> walls by inward offsets -> solid/sparse areas -> zigzag infill -> skirt ->
ordered toolpaths -> G-code (arapp.printing.gcode).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..export import clean_mesh, fit_on_bed
from ..profile import load_profile
from .contours import layer_planes, loops_to_region, slice_loops
from .perimeters import fill_area, solid_areas, split_fill
from ..gcode import write_gcode
from ..toolpath import LayerToolpaths, ToolPath
from .planner import plan_layer, skirt_loops
from .settings import INFILL_PATTERNS, SliceSettings

__all__ = ["SliceSettings", "SliceResult", "SliceCancelled", "slice_mesh", "INFILL_PATTERNS",
           "LayerToolpaths", "ToolPath"]


class SliceCancelled(RuntimeError):
    """Slicing stopped because the caller's cancel flag was set."""


@dataclass
class SliceResult:
    """G-code and its statistics: print time (s), filament length (mm) and mass (g).

    `toolpaths` are the layers' extrusions in print order (bed frame, mm);
    `mesh` is the solid as sliced (on the bed); `scale` the factor applied to fit the bed.
    """

    gcode: str
    layers: int
    print_time_s: float
    filament_mm: float
    filament_g: float
    toolpaths: list[LayerToolpaths] = field(default_factory=list, repr=False)
    mesh: object = field(default=None, repr=False)
    scale: float = 1.0
    slicer: str = "builtin"


def skirt_margin(settings: SliceSettings, width: float) -> float:
    """Room the skirt takes around the model's footprint (mm)."""
    return settings.skirt_distance + settings.skirts * width if settings.skirts > 0 else 0.0


def prepare(mesh_mm, settings: SliceSettings, profile):
    """The mesh cleaned and placed on the bed, and the scale applied to fit it (see export.fit_on_bed)."""
    mesh = clean_mesh(mesh_mm)
    width = settings.width(profile.nozzle_diameter)
    return fit_on_bed(mesh, profile, margin=skirt_margin(settings, width),
                      scale_to_fit=settings.scale_to_fit, center=settings.center)


def slice_mesh(mesh_mm, settings: SliceSettings | None = None, profile=None, progress=None, cancel=None) -> SliceResult:
    """Slice a triangle mesh (millimetres, +Z up) into Marlin G-code.

    `profile`: a PrinterProfile (generic when None). `progress(fraction)` is
    called with fractions rising from 0 to 1; `cancel` (a threading.Event)
    stops the work with SliceCancelled once set. A model that does not fit
    the bed raises ModelDoesNotFitError unless settings.scale_to_fit.
    """
    settings = settings or SliceSettings()
    profile = profile or load_profile()
    settings.check_for(profile)  # ranges tied to this printer's nozzle, height and heaters

    def report(f):
        if cancel is not None and cancel.is_set():
            raise SliceCancelled("slicing cancelled")
        if progress is not None:
            progress(float(min(max(f, 0.0), 1.0)))

    report(0.0)
    mesh, scale = prepare(mesh_mm, settings, profile)
    width = settings.width(profile.nozzle_diameter)
    tops, heights, cut_z = layer_planes(float(mesh.bounds[1, 2]), settings.first_layer_height, settings.layer_height)
    n = len(tops)
    report(0.02)
    loops = slice_loops(mesh, cut_z, tol=settings.contour_tolerance, gap=2.0 * width)
    report(0.1)
    regions, fills = [], []
    for k in range(n):
        r = loops_to_region(loops[k], simplify=settings.resolution)
        regions.append(r)
        fills.append(fill_area(r, settings.perimeters, width, settings.infill_overlap))
        if k % 16 == 0:
            report(0.1 + 0.15 * k / n)
    solids = solid_areas(regions, fills, settings.top_layers, settings.bottom_layers, width)
    report(0.3)
    sparse = [split_fill(f, s, width)[1] for f, s in zip(fills, solids)]
    skirt = skirt_loops(regions[0], settings.skirts, settings.skirt_distance, width)
    pos = np.zeros(2)  # after homing the nozzle is at the bed origin
    layers = []
    for k in range(n):
        layer, pos = plan_layer(k, float(tops[k]), float(heights[k]), regions[k], solids[k], sparse[k], settings,
                                width, pos, skirt if k == 0 else None)
        layers.append(layer)
        if k % 4 == 0:
            report(0.3 + 0.6 * k / n)
    # Layers that print nothing at the top (a sliver thinner than a wall) are dropped, as PrusaSlicer does.
    while layers and not layers[-1].paths:
        layers.pop()
    if not layers:
        raise ValueError("the model is too thin to print: no layer has room for a single line "
                         f"of {width:.2f} mm; make it larger (--size MM)")
    n = len(layers)
    report(0.9)
    header = [f"model scaled by {scale:.4f} to fit the bed"] if scale != 1.0 else []
    text, stats = write_gcode(layers, settings, profile, header=header)
    report(1.0)
    return SliceResult(gcode=text, layers=n, print_time_s=stats.print_time_s, filament_mm=stats.filament_mm,
                       filament_g=stats.filament_g, toolpaths=layers, mesh=mesh, scale=scale)
