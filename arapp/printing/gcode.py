"""Marlin G-code: a writer for the built-in slicer's toolpaths and a parser that reads moves back per layer.

Bed frame, millimetres, seconds. The writer puts `;LAYER:n` (0-based) and
`;TYPE:...` comments in the file: the serial link and the AR preview use them
to know the layer and the feature. The parser also reads PrusaSlicer's
`;LAYER_CHANGE`/`;Z:` and Cura's `;LAYER:` conventions.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from .toolpath import KIND_TYPES, LayerToolpaths

# ---------------------------------------------------------------- writer


def _move_time1(length: float, speed: float, accel: float) -> float:
    """Seconds for one move of `length` mm at `speed` mm/s from and to rest with acceleration `accel` mm/s²
    (trapezoid profile, or a triangle when the move is too short to reach the speed)."""
    if length >= speed * speed / accel:
        return length / speed + speed / accel
    return 2.0 * math.sqrt(max(length, 0.0) / accel)


def _layer_arrays(layer: LayerToolpaths, speeds: dict, area: float, accel: float) -> dict:
    """Everything the writer needs for one layer's extrusions, computed for all its paths at once:
    the `G1 X Y E` lines, E at each path's start and end, feed lines, extrusion time and filament."""
    paths = layer.paths
    counts = np.array([len(p.points) for p in paths])
    pts = np.concatenate([p.points for p in paths])
    path_of_point = np.repeat(np.arange(len(paths)), counts)
    d = np.diff(pts, axis=0)
    inside = path_of_point[1:] == path_of_point[:-1]          # a segment, not a jump between paths
    seg = np.hypot(d[:, 0], d[:, 1]) * inside
    widths = np.array([p.width for p in paths])
    path_of_seg = path_of_point[1:]
    de = widths[path_of_seg] * layer.height * seg / area
    e_cum = np.concatenate([[0.0], np.cumsum(de)])               # E at each point
    first_pt = np.concatenate([[0], np.cumsum(counts)[:-1]])
    last_pt = first_pt + counts - 1
    v = np.array([speeds["first_layer"] if layer.index == 0 else speeds[p.kind] for p in paths])
    # time: full stops at path ends and at corners sharper than 30 degrees
    u = d / np.maximum(seg, 1e-12)[:, None]
    cos_turn = np.einsum("ij,ij->i", u[:-1], u[1:])
    new_piece = np.ones(len(seg), dtype=bool)
    new_piece[1:] = ~inside[1:] | ~inside[:-1] | (cos_turn < np.cos(np.radians(30.0)))
    piece_starts = np.flatnonzero(new_piece)
    pieces = np.add.reduceat(seg, piece_starts) if len(seg) else np.zeros(0)
    pv = v[path_of_seg[piece_starts]] if len(seg) else np.zeros(0)
    full = pieces >= pv * pv / accel
    t = np.where(full, pieces / np.maximum(pv, 1e-9) + pv / accel, 2.0 * np.sqrt(pieces / accel)).sum()
    keep = np.flatnonzero(inside)
    xs, ys, es = pts[keep + 1, 0].tolist(), pts[keep + 1, 1].tolist(), e_cum[keep + 1].tolist()
    lines = list(map("G1 X{:.3f} Y{:.3f} E{:.5f}".format, xs, ys, es))
    first_line = np.concatenate([[0], np.cumsum(counts - 1)]).tolist()
    return {
        "lines": lines,
        "first_line": first_line,
        "e_start": e_cum[first_pt].tolist(),
        "e_end": e_cum[last_pt].tolist(),
        "start_xy": pts[first_pt].tolist(),
        "end_xy": pts[last_pt].tolist(),
        "feed": [f"G1 F{x * 60:.0f}" for x in v.tolist()],
        "time": float(t),
        "filament": float(de.sum()),
    }


def format_duration(seconds: float) -> str:
    """The one way arapp writes a duration for people: '1 h 05 min', '48 min 0 s', '40 s'."""
    s = max(0, int(round(seconds)))
    if s >= 3600:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    if s >= 60:
        return f"{s // 60} min {s % 60} s"
    return f"{s} s"


@dataclass
class GcodeStats:
    print_time_s: float
    filament_mm: float
    filament_g: float
    layers: int


class _GcodeBody:
    """The moves of one print as they are written: extruder position, retraction, nozzle position, time.

    `e` is the extruder position while not retracted (mm of filament, absolute,
    reset to 0 each layer); a retraction moves it retract_length lower and the
    un-retraction back. `time_s` adds up the estimated seconds of every move.
    """

    def __init__(self, settings, profile):
        self.settings, self.profile = settings, profile
        self.speeds = settings.speeds()
        self.accel = settings.acceleration
        self.area = profile.filament_area
        self.travel_f = self.speeds["travel"] * 60.0
        self.retract_f = settings.retract_speed * 60.0
        self.lines: list[str] = []
        self.emit = self.lines.append
        self.e = 0.0
        self.filament = 0.0
        self.time_s = 0.0
        self.pos = None
        self.retracted = False
        self.z_now = 0.0
        self.fan_on = False

    def travel_to(self, xy, z) -> None:
        """Travel to xy at height z: retract and hop first when the travel is long, un-retract after."""
        st, speeds, accel, emit = self.settings, self.speeds, self.accel, self.emit
        pos = self.pos
        dist = math.hypot(xy[0] - pos[0], xy[1] - pos[1]) if pos is not None else float("inf")
        long_travel = dist > st.retract_min_travel
        if long_travel and st.retract_length > 0 and not self.retracted and pos is not None:
            emit(f"G1 E{self.e - st.retract_length:.5f} F{self.retract_f:.0f}")
            self.time_s += st.retract_length / st.retract_speed
            self.retracted = True
        hop = long_travel and st.z_hop > 0 and pos is not None
        if hop:
            emit(f"G1 Z{z + st.z_hop:.3f} F{self.travel_f:.0f}")
            self.time_s += _move_time1(st.z_hop, min(speeds["travel"], 10.0), accel)
        if dist > 1e-9:
            emit(f"G0 X{xy[0]:.3f} Y{xy[1]:.3f} F{self.travel_f:.0f}")
            if math.isfinite(dist):
                self.time_s += _move_time1(dist, speeds["travel"], accel)
        if hop:
            emit(f"G1 Z{z:.3f} F{self.travel_f:.0f}")
            self.time_s += _move_time1(st.z_hop, min(speeds["travel"], 10.0), accel)
        if self.retracted:
            emit(f"G1 E{self.e:.5f} F{self.retract_f:.0f}")
            self.time_s += st.retract_length / st.retract_speed
            self.retracted = False
        self.pos = xy

    def start_layer(self, layer: LayerToolpaths) -> None:
        """Layer comments, the fan from layer 1, retract, rise to the layer's z and reset E."""
        st, emit = self.settings, self.emit
        emit(f";LAYER:{layer.index}")
        emit(f";Z:{layer.z:.3f}")
        emit(f";HEIGHT:{layer.height:.3f}")
        if layer.index == 1 and st.fan_percent() > 0 and not self.fan_on:
            emit(f"M106 S{round(255 * st.fan_percent() / 100)}")
            self.fan_on = True
        if self.pos is not None and st.retract_length > 0 and not self.retracted:
            emit(f"G1 E{self.e - st.retract_length:.5f} F{self.retract_f:.0f}")
            self.retracted = True
        emit(f"G1 Z{layer.z:.3f} F{min(self.travel_f, 600.0):.0f}")
        self.time_s += _move_time1(abs(layer.z - self.z_now), 10.0, self.accel)
        self.z_now = layer.z
        # E restarts from 0 each layer; while retracted the filament sits retract_length below that
        emit(f"G92 E{-st.retract_length:.5f}" if self.retracted else "G92 E0")
        self.e = 0.0

    def layer_paths(self, layer: LayerToolpaths) -> None:
        """The layer's paths in order, each reached by travel_to, with a ;TYPE: comment where the kind changes."""
        kind_now = None
        if not layer.paths:
            return
        plan = _layer_arrays(layer, self.speeds, self.area, self.accel)
        self.time_s += plan["time"]
        self.filament += plan["filament"]
        lines, first, es, starts = plan["lines"], plan["first_line"], plan["e_end"], plan["start_xy"]
        for i, path in enumerate(layer.paths):
            self.e = plan["e_start"][i]
            self.travel_to(starts[i], layer.z)
            if path.kind != kind_now:
                self.emit(f";TYPE:{KIND_TYPES[path.kind]}")
                kind_now = path.kind
            self.emit(plan["feed"][i])
            self.lines.extend(lines[first[i]:first[i + 1]])
            self.e = es[i]
            self.pos = plan["end_xy"][i]

    def finish(self, any_layers: bool) -> None:
        """End of the moves: retract, lift clear of the part, fan off (the printer's end code follows)."""
        st = self.settings
        if st.retract_length > 0 and not self.retracted:
            self.e -= st.retract_length
            self.emit(f"G1 E{self.e:.5f} F{self.retract_f:.0f}")
        if any_layers:
            self.emit(f"G1 Z{min(self.z_now + 10.0, self.profile.bed.height):.3f} F{min(self.travel_f, 600.0):.0f}")
        self.emit("M107")


def _gcode_head(settings, profile, stats: GcodeStats, header: list[str] | None) -> list[str]:
    """The header comments (printer, material, estimates, settings) and the start sequence: heat, home, modes."""
    mat = settings.material_info
    hot, bed = settings.hotend(), settings.bed()
    head = [
        "; generated by arapp built-in slicer",
        f"; printer = {profile.name}",
        f"; material = {mat.name} (density {mat.density} g/cm3)",
        f"; estimated printing time (s) = {stats.print_time_s:.0f}",
        f"; estimated printing time = {format_duration(stats.print_time_s)}",
        f"; filament used [mm] = {stats.filament_mm:.2f}",
        f"; filament used [g] = {stats.filament_g:.2f}",
        f"; layer count = {stats.layers}",
        f"; layer height = {settings.layer_height}, first layer height = {settings.first_layer_height}",
        f"; line width = {settings.width(profile.nozzle_diameter)}, perimeters = {settings.perimeters}, "
        f"infill = {settings.infill:g}% {settings.infill_pattern}",
        *(f"; {h}" for h in (header or [])),
        "",
        "M107",
    ]
    if bed > 0:
        head.append(f"M140 S{bed:.0f} ; bed")
    head.append(f"M104 S{hot:.0f} ; hotend")
    head.extend(profile.start_gcode.splitlines())
    if bed > 0:
        head.append(f"M190 S{bed:.0f} ; wait for bed")
    head += [f"M109 S{hot:.0f} ; wait for hotend", "G21 ; millimetres", "G90 ; absolute positions",
             "M82 ; absolute extrusion", "G92 E0"]
    return head


def write_gcode(layers: list[LayerToolpaths], settings, profile, header: list[str] | None = None) -> tuple[str, GcodeStats]:
    """Marlin G-code for the layers' toolpaths, with travel, retraction and z-hop between paths.

    E (mm of filament, absolute, reset to 0 each layer) = line width x layer
    height x length / filament cross-section (see `_GcodeBody`). Returns the
    text and its statistics (also written in the header).
    """
    body = _GcodeBody(settings, profile)
    for layer in layers:
        body.start_layer(layer)
        body.layer_paths(layer)
    body.finish(bool(layers))
    grams = body.filament * body.area * settings.material_info.density / 1000.0
    stats = GcodeStats(print_time_s=body.time_s, filament_mm=body.filament, filament_g=grams, layers=len(layers))
    head = _gcode_head(settings, profile, stats, header)
    return "\n".join(head + body.lines + profile.end_gcode.splitlines()) + "\n", stats


# ---------------------------------------------------------------- parser

MOVE_KINDS = ("perimeter", "infill", "skirt", "travel", "other")


def feature_kind(type_name: str) -> str:
    """Our move kind for a `;TYPE:` name (ours, PrusaSlicer's or Cura's)."""
    t = type_name.strip().lower()
    if "skirt" in t or "brim" in t:
        return "skirt"
    if "perimeter" in t or "wall" in t or "overhang" in t:
        return "perimeter"
    if "infill" in t or "fill" in t or "skin" in t or "gap" in t:
        return "infill"
    return "other"


@dataclass
class Move:
    """One straight move: `kind` (perimeter, infill, skirt, travel, other), start and end (x, y, z) in mm,
    `e` the filament pushed (mm, > 0 when extruding)."""

    kind: str
    start: tuple[float, float, float]
    end: tuple[float, float, float]
    e: float = 0.0

    @property
    def extruding(self) -> bool:
        return self.e > 1e-9 and self.kind != "travel"


@dataclass
class GcodeLayer:
    """One layer of a parsed file: its index (0-based, file order), z (mm) and moves."""

    index: int
    z: float
    moves: list[Move] = field(default_factory=list)

    def segments(self, kinds=("perimeter", "infill", "skirt", "other"), extruding: bool = True) -> np.ndarray:
        """(N, 2, 3) array of the moves of these kinds (extruding ones only unless `extruding` is False)."""
        sel = [(m.start, m.end) for m in self.moves if m.kind in kinds and (m.extruding or not extruding)]
        return np.asarray(sel, dtype=float).reshape(-1, 2, 3)

    @property
    def filament_mm(self) -> float:
        return float(sum(m.e for m in self.moves if m.e > 0 and m.kind != "travel"))


_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


def _read_comment(c: str, marker: str | None, layers: list[GcodeLayer], z_comment: float, kind: str) -> tuple[float, str]:
    """Apply one comment (text after `;`) to the parse: a layer start is appended to `layers`, a `;Z:`
    sets the open layer's z (or is kept for the next layer), a `;TYPE:` sets the feature kind.
    Returns the (z_comment, kind) that hold after it."""
    if (marker == ";LAYER:" and c.startswith("LAYER:")) or (marker == ";LAYER_CHANGE" and c == "LAYER_CHANGE"):
        layers.append(GcodeLayer(index=len(layers), z=z_comment))
        return math.nan, kind
    if c.startswith("Z:"):
        try:
            zc = float(c[2:])
        except ValueError:
            return z_comment, kind
        if layers and math.isnan(layers[-1].z):
            layers[-1].z = zc
            return z_comment, kind
        return zc, kind
    if c.startswith("TYPE:"):
        return z_comment, feature_kind(c[5:])
    return z_comment, kind


def parse_gcode(text: str) -> list[GcodeLayer]:
    """Layers of G-code text with their moves (G0/G1 in G90/G91 and M82/M83, G92 respected).

    A layer starts at `;LAYER:n` or `;LAYER_CHANGE`; a file with neither is cut
    into layers where extrusion first happens at a new z. Moves before the first
    layer (start code) are dropped; a pure retraction is not a move; an
    extruding move has its feature's kind, a move without extrusion is travel.
    """
    marker = ";LAYER:" if ";LAYER:" in text else (";LAYER_CHANGE" if ";LAYER_CHANGE" in text else None)
    has_markers = marker is not None
    z_comment = math.nan  # a `;Z:` seen since the last layer start (PrusaSlicer writes it before `;LAYER:`)
    layers: list[GcodeLayer] = []
    x = y = z = e = 0.0
    abs_xyz = abs_e = True
    kind = "other"
    for raw in text.splitlines():
        line = raw.strip()
        if not line:
            continue
        if line[0] == ";":
            z_comment, kind = _read_comment(line[1:].strip(), marker, layers, z_comment, kind)
            continue
        code = line.split(";", 1)[0].strip()
        if not code:
            continue
        head = code.split(None, 1)[0].upper()
        if head in ("G0", "G1", "G00", "G01"):
            words = {k.upper(): float(v) for k, v in _WORD.findall(code[len(head):])}
            nx = (words["X"] if abs_xyz else x + words["X"]) if "X" in words else x
            ny = (words["Y"] if abs_xyz else y + words["Y"]) if "Y" in words else y
            nz = (words["Z"] if abs_xyz else z + words["Z"]) if "Z" in words else z
            de = 0.0
            if "E" in words:
                de = words["E"] - e if abs_e else words["E"]
                e = words["E"] if abs_e else e + words["E"]
            moved = nx != x or ny != y or nz != z
            if moved:
                extruding = de > 0 and (nx != x or ny != y)
                if not has_markers and extruding and (not layers or abs(nz - layers[-1].z) > 1e-6):
                    layers.append(GcodeLayer(index=len(layers), z=nz))
                if layers:
                    mk = (kind if kind != "travel" else "other") if extruding else "travel"
                    layers[-1].moves.append(Move(mk, (x, y, z), (nx, ny, nz), de if extruding else 0.0))
                    if extruding and math.isnan(layers[-1].z):
                        layers[-1].z = nz
            x, y, z = nx, ny, nz
        else:
            x, y, z, e, abs_xyz, abs_e = _other_command(head, code, (x, y, z, e), abs_xyz, abs_e)
    return layers


def _other_command(head: str, code: str, pos: tuple, abs_xyz: bool, abs_e: bool) -> tuple:
    """(x, y, z, e, abs_xyz, abs_e) after a command that is not a move: G90/G91 and M82/M83 switch
    absolute/relative positions and extrusion, G92 sets the position (all of it to 0 without words), G28
    homes the axes it names (all without); anything else changes nothing."""
    x, y, z, e = pos
    if head == "G90":
        abs_xyz = True
    elif head == "G91":
        abs_xyz = False
    elif head == "M82":
        abs_e = True
    elif head == "M83":
        abs_e = False
    elif head == "G92":
        words = {k.upper(): float(v) for k, v in _WORD.findall(code[len(head):])}
        x, y, z, e = words.get("X", x), words.get("Y", y), words.get("Z", z), words.get("E", e)
        if not words:
            x = y = z = e = 0.0
    elif head == "G28":
        axes = code[len(head):].upper()
        if not any(a in axes for a in "XYZ"):
            x = y = z = 0.0
        else:
            x = 0.0 if "X" in axes else x
            y = 0.0 if "Y" in axes else y
            z = 0.0 if "Z" in axes else z
    return x, y, z, e, abs_xyz, abs_e


_STAT_PATTERNS = {
    "filament_mm": re.compile(r"^;\s*filament used \[mm\]\s*=\s*([\d.]+)", re.M),
    "filament_g": re.compile(r"^;\s*(?:total )?filament used \[g\]\s*=\s*([\d.]+)", re.M),
    "print_time_s": re.compile(r"^;\s*estimated printing time \(s\)\s*=\s*([\d.]+)", re.M),
}
_PRUSA_TIME = re.compile(r"^;\s*estimated printing time \(normal mode\)\s*=\s*(.+)$", re.M)


def read_stats(text: str) -> dict:
    """Filament (mm, g) and print time (s) from a G-code header or footer (ours or PrusaSlicer's)."""
    out = {}
    for key, pat in _STAT_PATTERNS.items():
        m = pat.search(text)
        if m:
            out[key] = float(m.group(1))
    m = _PRUSA_TIME.search(text)
    if "print_time_s" not in out and m:
        total = 0.0
        for value, unit in re.findall(r"(\d+)\s*([dhms])", m.group(1)):
            total += int(value) * {"d": 86400, "h": 3600, "m": 60, "s": 1}[unit]
        out["print_time_s"] = total
    return out
