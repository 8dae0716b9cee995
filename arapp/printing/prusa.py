"""PrusaSlicer's command line as an alternative slicer, with settings equivalent to the built-in one's.

Needs the `prusa-slicer` executable (Debian package `prusa-slicer`). The mesh
is written as a binary STL in bed millimetres; PrusaSlicer centres it at the
same bed point the built-in slicer uses. A `;LAYER:n` comment is added at each
layer change, as the built-in slicer writes, for the serial link and the AR preview.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from .export import write_stl
from .gcode import read_stats
from .profile import load_profile
from .slicer import SliceCancelled, SliceResult, SliceSettings, prepare

EXECUTABLES = ("prusa-slicer", "PrusaSlicer", "prusa-slicer-console")


class PrusaSlicerNotFound(RuntimeError):
    """PrusaSlicer's CLI is not installed."""


class PrusaSlicerFailed(RuntimeError):
    """PrusaSlicer ran but produced no G-code."""


def find_prusa() -> str | None:
    """Path of the PrusaSlicer executable ($ARAPP_PRUSA_SLICER first), or None."""
    env = os.environ.get("ARAPP_PRUSA_SLICER")
    if env and Path(env).is_file():
        return env
    for name in EXECUTABLES:
        path = shutil.which(name)
        if path:
            return path
    return None


def require_prusa() -> str:
    path = find_prusa()
    if path is None:
        raise PrusaSlicerNotFound(
            "--slicer prusa needs PrusaSlicer's command line (prusa-slicer), which is not installed: "
            "install it (Debian/Ubuntu: apt-get install prusa-slicer) or set ARAPP_PRUSA_SLICER to its path, "
            "or use the built-in slicer (--slicer builtin)"
        )
    return path


def prusa_version() -> str | None:
    """PrusaSlicer's version string, or None when it is not installed."""
    path = find_prusa()
    if path is None:
        return None
    out = subprocess.run([path, "--help"], capture_output=True, text=True, timeout=60)
    for line in (out.stdout + "\n" + out.stderr).splitlines():
        if line.startswith("PrusaSlicer"):
            return line.split(" based on", 1)[0].strip()
    return "PrusaSlicer (unknown version)"


def _g(text: str) -> str:
    """A G-code block as one config line (PrusaSlicer's ini escapes newlines as \\n)."""
    return text.replace("\\", "\\\\").replace("\n", "\\n")


def prusa_config(settings, profile) -> dict:
    """PrusaSlicer options equivalent to the built-in slicer's settings and the printer profile."""
    w = settings.width(profile.nozzle_diameter)
    return {**_shells_and_infill(settings, w), **_skirt_and_retraction(settings), **_speeds_and_heat(settings),
            **_machine(settings, profile)}


def _shells_and_infill(settings, w: float) -> dict:
    """Layers, perimeters, solid layers, infill and extrusion widths (w mm for every feature)."""
    return {
        "layer_height": settings.layer_height,
        "first_layer_height": settings.first_layer_height,
        "perimeters": settings.perimeters,
        "top_solid_layers": settings.top_layers,
        "bottom_solid_layers": settings.bottom_layers,
        "top_solid_min_thickness": 0,
        "bottom_solid_min_thickness": 0,
        "fill_density": f"{settings.infill:g}%",
        "fill_pattern": "rectilinear" if settings.infill_pattern == "zigzag" else "grid",
        "fill_angle": settings.infill_angle,
        "top_fill_pattern": "rectilinear",
        "bottom_fill_pattern": "rectilinear",
        "solid_fill_pattern": "rectilinear",
        "infill_overlap": f"{settings.infill_overlap * 100:g}%",
        "solid_infill_below_area": 0,
        "ensure_vertical_shell_thickness": 0,
        "extra_perimeters": 0,
        "perimeter_generator": "classic",
        "thin_walls": 0,
        "gap_fill_enabled": 0,
        "extrusion_width": w,
        "first_layer_extrusion_width": w,
        "perimeter_extrusion_width": w,
        "external_perimeter_extrusion_width": w,
        "infill_extrusion_width": w,
        "solid_infill_extrusion_width": w,
        "top_infill_extrusion_width": w,
    }


def _skirt_and_retraction(settings) -> dict:
    """Skirt, brim and retraction."""
    return {
        "skirts": settings.skirts,
        "skirt_distance": settings.skirt_distance,
        "skirt_height": 1,
        "min_skirt_length": 0,
        "brim_width": 0,
        "retract_length": settings.retract_length,
        "retract_speed": settings.retract_speed,
        "retract_before_travel": settings.retract_min_travel,
        "retract_lift": settings.z_hop,
        "retract_layer_change": 1,
    }


def _speeds_and_heat(settings) -> dict:
    """Feature speeds (mm/s), temperatures (deg C) and the part fan."""
    speeds = settings.speeds()
    fan = settings.fan_percent()
    return {
        "perimeter_speed": speeds["perimeter"],
        "external_perimeter_speed": speeds["external_perimeter"],
        "small_perimeter_speed": speeds["perimeter"],
        "infill_speed": speeds["sparse_infill"],
        "solid_infill_speed": speeds["solid_infill"],
        "top_solid_infill_speed": speeds["solid_infill"],
        "first_layer_speed": speeds["first_layer"],
        "travel_speed": speeds["travel"],
        "temperature": round(settings.hotend()),
        "first_layer_temperature": round(settings.hotend()),
        "bed_temperature": round(settings.bed()),
        "first_layer_bed_temperature": round(settings.bed()),
        "cooling": 1 if fan > 0 else 0,
        "fan_always_on": 1 if fan > 0 else 0,
        "min_fan_speed": fan,
        "max_fan_speed": fan,
        "disable_fan_first_layers": 1,
    }


def _machine(settings, profile) -> dict:
    """The printer: bed shape, nozzle, filament, G-code flavour and the start/end G-code."""
    bed = profile.bed
    mat = settings.material_info
    return {
        "bed_shape": f"0x0,{bed.width:g}x0,{bed.width:g}x{bed.depth:g},0x{bed.depth:g}",
        "max_print_height": bed.height,
        "nozzle_diameter": profile.nozzle_diameter,
        "filament_diameter": profile.filament_diameter,
        "filament_density": mat.density,
        "gcode_flavor": "marlin2",
        "use_relative_e_distances": 0,
        "start_gcode": _g(profile.start_gcode),
        "end_gcode": _g(profile.end_gcode),
        "before_layer_gcode": ";LAYER:[layer_num]",
        "elefant_foot_compensation": 0,
        "avoid_crossing_perimeters": 0,
        "complete_objects": 0,
    }


def run_prusa(stl_path: Path, gcode_path: Path, settings, profile, timeout: float = 600.0, cancel=None) -> float:
    """Run PrusaSlicer on an STL already in bed millimetres; returns its wall-clock seconds.

    `cancel` (threading.Event): once set, PrusaSlicer is stopped and SliceCancelled raised.
    """
    exe = require_prusa()
    cfg = gcode_path.with_suffix(".ini")
    cfg.write_text("".join(f"{k} = {v}\n" for k, v in prusa_config(settings, profile).items()))
    cx, cy = profile.bed_center
    cmd = [exe, "--export-gcode", "--load", str(cfg), "--center", f"{cx:g},{cy:g}", "-o", str(gcode_path), str(stl_path)]
    log = gcode_path.with_suffix(".log")
    t0 = time.perf_counter()
    with open(log, "w") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT)
        try:
            while True:
                try:
                    proc.wait(timeout=0.1)
                    break
                except subprocess.TimeoutExpired:
                    pass
                if cancel is not None and cancel.is_set():
                    raise SliceCancelled("slicing cancelled")
                if time.perf_counter() - t0 > timeout:
                    raise PrusaSlicerFailed(f"PrusaSlicer took more than {timeout:.0f} s on {stl_path}")
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0 or not gcode_path.exists():
        tail = "\n".join(log.read_text(errors="replace").strip().splitlines()[-8:])
        raise PrusaSlicerFailed(f"PrusaSlicer failed (exit {proc.returncode}) on {stl_path}:\n{tail}")
    return elapsed


def slice_with_prusa(mesh_mm, settings=None, profile=None, progress=None, cancel=None, workdir=None):
    """Slice with PrusaSlicer: the same mesh preparation (bed fit, centring) as `slice_mesh`, then its CLI.

    Returns a SliceResult (toolpaths empty; parse the G-code with parse_gcode for moves).
    """
    settings = settings or SliceSettings()
    profile = profile or load_profile()
    settings.check_for(profile)  # the same ranges as the built-in slicer
    require_prusa()
    if progress:
        progress(0.0)
    mesh, scale = prepare(mesh_mm, settings, profile)
    if cancel is not None and cancel.is_set():
        raise SliceCancelled("slicing cancelled")
    with tempfile.TemporaryDirectory(prefix="arapp-prusa-", dir=workdir) as tmp:
        stl = Path(tmp) / "model.stl"
        out = Path(tmp) / "model.gcode"
        write_stl(mesh, stl)
        run_prusa(stl, out, settings, profile, cancel=cancel)
        text = out.read_text()
    stats = read_stats(text)
    layers = text.count(";LAYER_CHANGE")
    if progress:
        progress(1.0)
    return SliceResult(gcode=text, layers=layers, print_time_s=stats.get("print_time_s", float("nan")),
                       filament_mm=stats.get("filament_mm", float("nan")),
                       filament_g=stats.get("filament_g", float("nan")), toolpaths=[], mesh=mesh, scale=scale,
                       slicer="prusa")
