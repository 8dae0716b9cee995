"""`arapp slice`: a model (JSON NURBS model or STL/OBJ/3MF mesh) to Marlin G-code."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

HELP = "slice a model (JSON model or STL/OBJ/3MF) into G-code for a printer"


def add_arguments(parser):
    parser.add_argument("model", help="model JSON file, a mesh file (.stl, .obj, .3mf) in millimetres, or a "
                        "library model's name (vase)")
    parser.add_argument("-o", "--output", required=True, help="G-code file to write")
    parser.add_argument("--material", default="PLA", type=str.upper,
                        choices=["PLA", "PETG", "ABS", "TPU", "NYLON"], help="filament (temperatures, fan, density)")
    parser.add_argument("--layer-height", type=float, default=0.2, help="layer height, mm (default 0.2)")
    parser.add_argument("--first-layer-height", type=float, default=None, help="first layer height, mm (default: layer height)")
    parser.add_argument("--infill", type=float, default=20.0, help="sparse infill density, percent (default 20)")
    parser.add_argument("--pattern", choices=["zigzag", "grid"], default="zigzag", help="sparse infill pattern")
    parser.add_argument("--perimeters", type=int, default=2, help="walls around each layer (default 2)")
    parser.add_argument("--size", type=float, default=None, metavar="MM",
                        help="largest extent of the printed part, mm (default: the model's placement size; "
                             "mesh files are taken as millimetres)")
    parser.add_argument("--thickness", type=float, default=2.0, metavar="MM",
                        help="wall thickness for open surfaces, mm (default 2)")
    parser.add_argument("--slicer", choices=["builtin", "prusa"], default="builtin",
                        help="built-in slicer (default) or PrusaSlicer's CLI when installed")
    parser.add_argument("--printer", default=None, metavar="PROFILE",
                        help="printer profile JSON (arapp-printer/1) or shipped name (default: generic 250x210 Marlin)")
    parser.add_argument("--scale-to-fit", action="store_true", help="shrink a model that does not fit the bed")
    parser.add_argument("--z-hop", type=float, default=0.0, metavar="MM", help="lift the nozzle on travel, mm")
    parser.add_argument("--retract", type=float, default=1.0, metavar="MM", help="retraction length, mm (0 = off)")
    parser.add_argument("--stl", default=None, metavar="FILE", help="also write the placed solid (.stl or .3mf)")


def load_for_printing(path: str, size_mm: float | None, thickness_mm: float, profile):
    """The model at `path` as a watertight solid on the bed (mm): meshes through arapp.exchange (the one
    loader and units rule), JSON models through arapp.geometry. `size_mm` and `thickness_mm` are checked."""
    from arapp.exchange import is_mesh_path, load_mesh
    from arapp.geometry.placement import check_size_mm
    from arapp.printing.export import placed_solid, scale_to_size

    if size_mm is not None:
        size_mm = check_size_mm(size_mm, "--size")
    check_thickness_mm(thickness_mm, size_mm)
    p = Path(path)
    if is_mesh_path(p):
        mesh = load_mesh(p)
        if size_mm is not None:
            mesh = scale_to_size(mesh, size_mm)
        return placed_solid(mesh, thickness_mm=thickness_mm, profile=profile)
    from arapp.geometry import load_model

    model = load_model(p)
    placement = dataclasses.replace(model.placement, size_mm=size_mm) if size_mm is not None else None
    return placed_solid(model, placement, thickness_mm=thickness_mm, profile=profile)


def check_thickness_mm(thickness_mm: float, size_mm: float | None = None) -> float:
    """The wall thickness for open surfaces (mm) when usable: positive, at most 50 mm and the part's size."""
    limit = min(50.0, size_mm) if size_mm is not None else 50.0
    if not (isinstance(thickness_mm, (int, float)) and 0 < thickness_mm <= limit):
        raise ValueError(f"--thickness must be above 0 and at most {limit:g} mm (the part's size or 50 mm), "
                         f"got {thickness_mm!r}")
    return float(thickness_mm)


def _progress_printer():
    if not sys.stderr.isatty():
        return None
    state = {"last": -1}

    def show(fraction):
        pct = int(fraction * 100)
        if pct != state["last"]:
            state["last"] = pct
            bar = "#" * (pct // 4)
            print(f"\rslicing [{bar:<25}] {pct:3d}%", end="" if pct < 100 else "\n", file=sys.stderr, flush=True)

    return show


def settings_from_args(args, profile=None):
    """The SliceSettings that the slicing flags of `arapp slice` and `arapp print` ask for, checked against
    `profile` (default: the one `args.printer` names): SettingsError names the flag and the allowed range."""
    from arapp.printing import SliceSettings, load_profile

    if profile is None:
        profile = load_profile(getattr(args, "printer", None))
    return SliceSettings(
        material=args.material, layer_height=args.layer_height,
        first_layer_height=args.first_layer_height if args.first_layer_height is not None else args.layer_height,
        infill=args.infill, infill_pattern=args.pattern, perimeters=args.perimeters,
        scale_to_fit=args.scale_to_fit, z_hop=args.z_hop, retract_length=args.retract,
    ).check_for(profile)


def run(args) -> int:
    from arapp.exchange import is_mesh_path, write_atomic, write_mesh
    from arapp.printing import load_profile
    from arapp.printing.gcode import format_duration

    profile = load_profile(args.printer)
    settings = settings_from_args(args, profile)
    out = Path(args.output)
    if is_mesh_path(out) or out.suffix.lower() == ".json" or out.is_dir():
        raise ValueError(f"-o {out}: give a G-code file name (.gcode), not a model or folder")
    mesh = load_for_printing(args.model, args.size, args.thickness, profile)
    if args.slicer == "prusa":
        from arapp.printing.prusa import slice_with_prusa

        result = slice_with_prusa(mesh, settings, profile, progress=_progress_printer())
    else:
        from arapp.printing import slice_mesh

        result = slice_mesh(mesh, settings, profile, progress=_progress_printer())
    write_atomic(out, result.gcode.encode("utf-8"))  # no half-written G-code under the final name
    if args.stl:
        write_mesh(result.mesh, args.stl)
    ext = result.mesh.extents
    print(f"{out}: {result.layers} layers, {format_duration(result.print_time_s)}, "
          f"{result.filament_mm / 1000:.2f} m / {result.filament_g:.1f} g of {settings.material} "
          f"({args.slicer} slicer, part {ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} mm"
          + (f", scaled by {result.scale:.3f} to fit" if result.scale != 1.0 else "") + ")")
    return 0
