"""Sliced toolpaths drawn in AR on the real printer bed (the print preview).

The recording's (or live session's) first anchor is the printer's bed anchor;
the printer profile's `bed_from_anchor` (docs/printer-profile.md) places it on the
bed. Toolpaths are G-code coordinates in the bed frame (millimetres); this
module turns them into coloured line sets for `arapp.render.OverlayRenderer`
and gives the transform from the bed frame to the world (metres).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arapp.printing import load_profile
from arapp.printing.gcode import parse_gcode
from arapp.render.modes import LineSet

# RGBA per move kind: perimeters warm, infill cool, travel faint, skirt grey.
KIND_COLOURS = {
    "perimeter": (1.0, 0.55, 0.1, 1.0),
    "infill": (0.15, 0.75, 1.0, 1.0),
    "skirt": (0.8, 0.8, 0.8, 1.0),
    "other": (0.9, 0.9, 0.3, 1.0),
    "travel": (0.6, 0.6, 0.6, 0.35),
}
DIM_ALPHA = 0.1  # a hundred dimmed layers stacked must not look solid
CURRENT_COLOUR = (1.0, 0.2, 0.8, 1.0)  # the layer being printed, during a print
OUT_OF_BED_COLOUR = (1.0, 0.1, 0.1, 1.0)
BED_OUTLINE_COLOUR = (0.2, 1.0, 0.3, 0.9)


def world_from_bed(world_from_bed_anchor: np.ndarray, bed_from_anchor_mm: np.ndarray) -> np.ndarray:
    """4x4 similarity from bed coordinates (mm) to the world (metres).

    world_from_bed_anchor: the bed anchor's pose in the world (metres), identity
    when it is the session's first anchor; bed_from_anchor_mm: the profile's
    transform, anchor frame taken in millimetres -> bed frame in millimetres.
    """
    anchor_mm_from_bed = np.linalg.inv(np.asarray(bed_from_anchor_mm, dtype=float))
    m_from_mm = np.diag([1e-3, 1e-3, 1e-3, 1.0])
    return np.asarray(world_from_bed_anchor, dtype=float) @ m_from_mm @ anchor_mm_from_bed


def bed_outline(width_mm: float, depth_mm: float) -> np.ndarray:
    """Closed polyline (5, 3) of the bed's build area at z = 0, bed frame (mm)."""
    return np.array([[0, 0, 0], [width_mm, 0, 0], [width_mm, depth_mm, 0], [0, depth_mm, 0], [0, 0, 0]], float)


def out_of_bed(segments: np.ndarray, width_mm: float, depth_mm: float, height_mm: float | None = None,
               tol: float = 1e-6) -> np.ndarray:
    """Boolean mask (N,) of the (N, 2, 3) segments that leave the build volume."""
    s = np.asarray(segments, dtype=float).reshape(-1, 2, 3)
    lo = (s[..., 0] < -tol) | (s[..., 1] < -tol)
    hi = (s[..., 0] > width_mm + tol) | (s[..., 1] > depth_mm + tol)
    if height_mm is not None:
        hi |= s[..., 2] > height_mm + tol
    return np.any(lo | hi, axis=1)


def toolpath_line_sets(layers, bed_size: tuple[float, float, float], layer: int | None = None,
                       current: int | None = None, travel: bool = True) -> list:
    """Line sets (arapp.render LineSet) of parsed G-code layers, in bed coordinates (mm).

    layer: show layers 0..layer with that layer in full colour and those below
    dimmed (None: all layers in full colour). current: the layer being
    printed (takes precedence over `layer`): the layers below it, printed
    already, are drawn solid (full colour, opaque), the current one in
    `CURRENT_COLOUR`, the layers still to print dimmed above it. Moves
    outside the build volume are drawn red and the bed outline turns red: the
    warning. Segments are grouped by kind and role so a whole print is a
    handful of line sets (each uploaded to the GPU once); a group spanning
    several layers keeps them in order with their starts (LineSet.layer_starts),
    so the renderer can leave out layers that would sit closer than a line's
    width on screen.
    """
    width, depth, height = bed_size
    n = len(layers)
    if current is not None:
        current = min(int(current), n - 1)
        top = n - 1
    else:
        top = n - 1 if layer is None else min(int(layer), n - 1)
    groups: dict[tuple, list] = {}  # (colour, width_px) -> list of (layer index, (N, 2, 3) segments)
    for gl in layers[: top + 1]:
        if current is not None:
            role = "current" if gl.index == current else ("printed" if gl.index < current else "to print")
            full = role != "to print"
        else:
            role = "full" if (layer is None or gl.index == top) else "below"
            full = role == "full"
        _group_layer(groups, gl, role, full, travel, bed_size)
    zs = [float(gl.z) for gl in layers]
    pitch = (zs[-1] - zs[0]) / (n - 1) if n > 1 else 0.0
    sets = [s for s in (_stacked_set(colour, width_px, parts, pitch) for (colour, width_px), parts in groups.items())
            if s is not None]
    any_outside = (OUT_OF_BED_COLOUR, 3.0) in groups
    outline_colour = OUT_OF_BED_COLOUR if any_outside else BED_OUTLINE_COLOUR
    sets.append(LineSet([bed_outline(width, depth)], outline_colour, 3.0 if any_outside else 2.0, 0.0))
    return sets


def _group_layer(groups: dict, gl, role: str, full: bool, travel: bool, bed_size) -> None:
    """Add layer `gl`'s segments to `groups` {(colour, width_px): [(layer index, segments)]}, by kind, in the
    colour and width of its role ("full", "below", "current", "printed", "to print"); moves outside the
    build volume go to the out-of-bed group."""
    width, depth, height = bed_size
    for kind, rgba in KIND_COLOURS.items():
        if kind == "travel" and (not travel or role not in ("full", "current")):
            continue
        seg = gl.segments(kinds=(kind,), extruding=kind != "travel")
        if not len(seg):
            continue
        outside = out_of_bed(seg, width, depth, height)
        colour = tuple(rgba) if full else (*rgba[:3], rgba[3] * DIM_ALPHA)
        if role == "current" and kind != "travel":
            colour = CURRENT_COLOUR
        width_px = 1.0 if kind == "travel" else (2.0 if full else 1.0)
        if role == "current" and kind != "travel":
            width_px = 3.0
        groups.setdefault((colour, width_px), []).append((gl.index, seg[~outside]))
        if outside.any():
            groups.setdefault((OUT_OF_BED_COLOUR, 3.0), []).append((gl.index, seg[outside]))


def _stacked_set(colour, width_px: float, parts: list, pitch: float):
    """One LineSet of a group's [(layer index, segments)] (in layer order), with the starts of its layers
    when it spans several (LineSet.layer_starts); None when the group has no segment."""
    parts = [(k, p) for k, p in parts if len(p)]
    if not parts:
        return None
    seg = np.concatenate([p for _, p in parts])
    starts, seen, at = [], set(), 0
    for k, p in parts:  # layers in order (toolpath_line_sets walks them bottom up)
        if k not in seen:
            seen.add(k)
            starts.append(at)
        at += len(p)
    stack = len(starts) > 1 and pitch > 0
    return LineSet(seg, colour, width_px, 0.0, layer_starts=np.array(starts) if stack else None,
                   layer_pitch=pitch if stack else 0.0)


def toolpath_overlay(gcode_path: str | Path, printer_path: str | Path | None, anchors, layer: int | None = None,
                     current: int | None = None):
    """(line_sets, world_from_bed) for a G-code file on the bed of a printer profile.

    anchors: the session's anchors; the first is the bed anchor (its frame is the world).
    """
    path = Path(gcode_path)
    if not path.is_file():
        raise FileNotFoundError(f"toolpaths: {path} does not exist; slice a model first (arapp slice MODEL -o {path})")
    layers = parse_gcode(path.read_text(errors="replace"))
    if not layers:
        raise ValueError(f"toolpaths: {path} has no printing moves (no layers found)")
    if layer is not None and not (0 <= layer < len(layers)):
        raise ValueError(f"--layer {layer}: {path} has layers 0..{len(layers) - 1}")
    profile = load_profile(printer_path)
    if profile.bed_from_anchor is None:
        raise ValueError(f"printer profile {profile.source} has no bed_anchor; add one with its bed_from_anchor "
                         f"(see docs/printer-profile.md) so the toolpaths can be placed on the bed")
    bed = (profile.bed.width, profile.bed.depth, profile.bed.height)
    sets = toolpath_line_sets(layers, bed, layer, current)
    return sets, world_from_bed(anchors[0].world_from_anchor, profile.bed_from_anchor)


class PrintProgressOverlay:
    """The toolpaths of a running print with the layer being printed highlighted.

    Fed by a print link's progress reports (`arapp.printing.link.Progress`,
    whose `layer` counts from the printer's acknowledgements), never by a
    timer. `line_sets()` is rebuilt only when the highlighted layer changes.
    """

    def __init__(self, layers, bed_size: tuple[float, float, float]):
        self.layers = layers
        self.bed_size = bed_size
        self.current = -1
        self.percent = 0.0
        self._sets = None

    def update(self, progress) -> bool:
        """Take a progress report; True when the highlighted layer changed."""
        self.percent = float(getattr(progress, "percent", self.percent))
        layer = int(getattr(progress, "layer", -1))
        if layer == self.current:
            return False
        self.current = layer
        self._sets = None
        return True

    def line_sets(self) -> list:
        """Layers printed so far solid, the current one highlighted, those to print dimmed (all layers in
        full colour before the print starts)."""
        if self._sets is None:
            if self.current < 0:
                self._sets = toolpath_line_sets(self.layers, self.bed_size)
            else:
                self._sets = toolpath_line_sets(self.layers, self.bed_size, layer=self.current, current=self.current)
        return self._sets
