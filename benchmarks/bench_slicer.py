"""Slicing time: arapp's built-in slicer vs PrusaSlicer's CLI on the same ~100k-triangle mesh and settings.

Both timings cover mesh in memory -> G-code file on disk (PrusaSlicer's
include its process start and STL read; the STL is written before its clock
starts). Best of `repeats` runs, measured in the same process run.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

from arapp.printing import SliceSettings, load_profile, slice_mesh  # noqa: E402
from arapp.printing.export import write_stl  # noqa: E402
from arapp.printing.gcode import read_stats  # noqa: E402
from arapp.printing.prusa import find_prusa, prusa_version, run_prusa  # noqa: E402
from arapp.printing.slicer import prepare  # noqa: E402

GOAL = 2.0  # built-in time at most 2x PrusaSlicer's


def models(quick: bool) -> dict:
    """Benchmark meshes (mm): a torus of exactly 100,000 triangles and a bumpy sphere of ~82k."""
    torus = trimesh.creation.torus(major_radius=25, minor_radius=10, major_sections=250, minor_sections=200)
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=20)
    # six lobes make every layer's outline wavy rather than a circle
    v = sphere.vertices
    r = 20 + 2.0 * np.sin(6 * np.arctan2(v[:, 1], v[:, 0])) * (1 - (v[:, 2] / 20) ** 2)
    bumpy = trimesh.Trimesh(v / 20 * r[:, None], sphere.faces)
    out = {"torus 70x70x20 mm": torus, "six-lobed sphere 44 mm": bumpy}
    if quick:
        out = {"torus 70x70x20 mm": torus}
    return out


def _time_builtin(mesh, settings, profile, out: Path, repeats: int):
    best, result = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = slice_mesh(mesh, settings, profile)
        out.write_text(result.gcode)
        best = min(best, time.perf_counter() - t0)
    return best, result


def _time_prusa(mesh, settings, profile, tmp: Path, repeats: int):
    placed, _ = prepare(mesh, settings, profile)
    stl = write_stl(placed, tmp / "model.stl")
    best, stats = float("inf"), {}
    for _ in range(repeats):
        gcode = tmp / "prusa.gcode"
        best = min(best, run_prusa(stl, gcode, settings, profile))
        text = gcode.read_text()
        stats = read_stats(text)
        stats["layers"] = text.count(";LAYER_CHANGE")
    return best, stats


def run(quick: bool = False) -> str:
    """Markdown section: built-in vs PrusaSlicer slicing time per model, with the ratio and the goal."""
    settings = SliceSettings()  # PLA, 0.2 mm layers, 2 walls, 20 % zigzag infill, skirt
    profile = load_profile()
    repeats = 1 if quick else 2
    have_prusa = find_prusa() is not None
    lines = [
        "## Slicing (built-in slicer vs PrusaSlicer CLI)",
        "",
        f"Same mesh and equivalent settings (0.2 mm layers, 2 perimeters, 20 % infill, 0.45 mm lines), "
        f"mesh in memory to G-code on disk, best of {repeats}; this 2-core CPU machine, same run. "
        f"Peer: {prusa_version() or 'PrusaSlicer not installed'}. Goal: built-in at most {GOAL:g}x PrusaSlicer's time.",
        "",
        "| model | triangles | built-in s | PrusaSlicer s | ratio | goal met | layers (built-in/Prusa) | filament m (built-in/Prusa) |",
        "|---|---:|---:|---:|---:|---|---|---|",
    ]
    with tempfile.TemporaryDirectory(prefix="bench-slicer-") as tmp:
        tmp = Path(tmp)
        for name, mesh in models(quick).items():
            t_b, res = _time_builtin(mesh, settings, profile, tmp / "builtin.gcode", repeats)
            if have_prusa:
                t_p, st = _time_prusa(mesh, settings, profile, tmp, repeats)
                ratio = t_b / t_p
                lines.append(
                    f"| {name} | {len(mesh.faces):,} | {t_b:.2f} | {t_p:.2f} | {ratio:.2f} | "
                    f"{'yes' if ratio <= GOAL else 'no'} | {res.layers}/{st.get('layers', '?')} | "
                    f"{res.filament_mm / 1000:.2f}/{st.get('filament_mm', float('nan')) / 1000:.2f} |")
            else:
                lines.append(f"| {name} | {len(mesh.faces):,} | {t_b:.2f} | n/a | n/a | not measured | "
                             f"{res.layers}/- | {res.filament_mm / 1000:.2f}/- |")
    if not have_prusa:
        lines += ["", "PrusaSlicer's CLI (`prusa-slicer`) is not installed, so the ratio could not be measured."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
