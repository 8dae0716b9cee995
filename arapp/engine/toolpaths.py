"""The AR print preview in the live view: sliced toolpaths on the printer bed, built where the pipeline runs.

A preview request ("spec") is a small dict that crosses the process boundary:
`{"gcode": PATH, "printer": PROFILE, "layer": N | None, "current": N | None, "gen": int,
"bed_from_placement": 4x4 | None}`.
`layer` None shows every layer; N shows layers 0..N with N in full colour and
those below dimmed. `current` is the layer being printed (from the printer
link's progress reports): it is drawn highlighted, the layers below it
(printed) solid and those above it (still to print) dimmed
(arapp.engine.toolpath_overlay.toolpath_line_sets' rule); it takes precedence over
`layer`.

`ToolpathStage` parses the G-code (once per file version), builds the line
sets in its own thread (newest request wins, so a layer slider dragged fast
never queues work) and hands them to the pipeline thread between frames.

Where the toolpaths stand: on the printer's bed marker when the printer
profile names one (docs/printer-profile.md) and that marker is one of the
session's anchors (the camera tracks it); otherwise where the model is
placed, through `bed_from_placement` (the slicer's move of the placed part
onto the bed, `bed_from_placement_mm`). The info says which
(`placed_by`: "bed marker" or "model", and `placed_text` in words).
"""

from __future__ import annotations

import threading
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from arapp.printing.printers import resolve_profile
from arapp.geometry.placement import world_from_placement
from arapp.printing.gcode import parse_gcode
from arapp.engine.toolpath_overlay import OUT_OF_BED_COLOUR, out_of_bed, toolpath_line_sets, world_from_bed

# the fields that name a marker (or board, or QR code): equal on two anchors, they are the same one
_MARKER_FIELDS = ("kind", "dictionary", "id", "first_id", "markers_x", "markers_y", "squares_x", "squares_y", "text")


def preview_spec(gcode: str, printer: str | None, layer: int | None = None, current: int | None = None,
                 gen: int = 0, bed_from_placement=None) -> dict:
    """A preview request (see the module doc); paths as strings, layers 0-based, `bed_from_placement` a 4x4
    (mm) or None."""
    return {"gcode": str(gcode), "printer": None if printer is None else str(printer),
            "layer": None if layer is None else int(layer),
            "current": None if current is None or current < 0 else int(current), "gen": int(gen),
            "bed_from_placement": None if bed_from_placement is None
            else np.asarray(bed_from_placement, float).tolist()}


def bed_from_placement_mm(placed_bounds: np.ndarray, bed_bounds: np.ndarray, lowest_z: float) -> np.ndarray:
    """4x4 (mm) from the anchor's placement frame to the bed frame, as the slicer moved the part: the placed
    solid's box (`placed_bounds`, (2, 3): x, y in the placement frame) centred where the sliced part's box
    lies on the bed (`bed_bounds`), its lowest point (`lowest_z`, placement frame) onto z = 0."""
    T = np.eye(4)
    T[:2, 3] = (np.asarray(bed_bounds, float)[:, :2].mean(axis=0) - np.asarray(placed_bounds, float)[:, :2].mean(axis=0))
    T[2, 3] = -float(lowest_z)
    return T


def same_marker(a, b) -> bool:
    """Two AnchorSpecs name the same marker (kind, dictionary, ids; sizes may differ in rounding)."""
    return all(getattr(a, f, None) == getattr(b, f, None) for f in _MARKER_FIELDS)


def marker_text(anchor) -> str:
    """'ArUco DICT_4X4_50 #42' and the like, for people."""
    if anchor.kind == "aruco":
        return f"ArUco {anchor.dictionary} #{anchor.id}"
    if anchor.kind == "qr":
        return f"QR code {anchor.text!r}"
    return f"{anchor.kind} {anchor.dictionary or ''} from #{anchor.first_id}".replace("  ", " ")


def place_toolpaths(anchors: list, profile, bed_from_placement) -> tuple[np.ndarray, str, str]:
    """(world_from_bed, placed_by, placed_text): on the profile's bed marker when one of `anchors` is it,
    else where the model is placed on the session's first anchor (bed_from_placement, mm). ValueError when
    neither can be done."""
    bed = getattr(profile, "bed_anchor", None)
    if bed is not None and profile.bed_from_anchor is not None:
        for anchor in anchors:
            if same_marker(anchor, bed):
                return (world_from_bed(anchor.world_from_anchor, profile.bed_from_anchor), "bed marker",
                        f"on the printer's bed, placed by its bed marker {marker_text(bed)} "
                        f"(printer profile {profile.name})")
    if bed_from_placement is None:
        raise ValueError("print preview: the printer profile has no bed marker in view and the slice does not "
                         "say where the model was placed; slice again")
    why = (f"the printer's bed marker {marker_text(bed)} is not among the markers tracked" if bed is not None
           else "no bed marker is set up for this printer: Printer set-up, Bed marker...")
    placement_from_bed = np.linalg.inv(np.asarray(bed_from_placement, float))
    T = world_from_placement(anchors[0]) @ np.diag([1e-3, 1e-3, 1e-3, 1.0]) @ placement_from_bed
    return T, "model", f"where the model is placed ({why})"


@dataclass
class PreviewSummary:
    """What the dialog shows about sliced toolpaths: layer count, layer heights (mm), the number of moves
    leaving the build volume and their extent in the bed frame (mm, (2, 3): min and max; None when none)."""

    layers: int
    z: list
    outside: int
    outside_bounds: np.ndarray | None

    def warning(self, bed) -> str:
        """'' when every move stays inside the build volume, else the text warning (bed: profile.bed)."""
        if not self.outside:
            return ""
        lo, hi = self.outside_bounds
        return (f"The toolpaths leave the build area: {self.outside} moves go outside the "
                f"{bed.width:g} x {bed.depth:g} x {bed.height:g} mm bed (to x {lo[0]:.1f}..{hi[0]:.1f}, "
                f"y {lo[1]:.1f}..{hi[1]:.1f}, z up to {hi[2]:.1f} mm); they are drawn red on the bed. "
                "Make the part smaller, move it, or fix the profile's start G-code.")


def summarize(layers, bed) -> PreviewSummary:
    """Summary of parsed G-code layers (arapp.printing.gcode.parse_gcode) on a bed (profile.bed)."""
    outside = []
    for gl in layers:
        for extruding, kinds in ((True, ("perimeter", "infill", "skirt", "other")), (False, ("travel",))):
            seg = gl.segments(kinds=kinds, extruding=extruding)
            if len(seg):
                outside.append(seg[out_of_bed(seg, bed.width, bed.depth, bed.height)])
    out = np.concatenate(outside) if outside else np.zeros((0, 2, 3))
    bounds = None
    if len(out):
        pts = out.reshape(-1, 3)
        bounds = np.array([pts.min(axis=0), pts.max(axis=0)])
    return PreviewSummary(len(layers), [float(gl.z) for gl in layers], int(len(out)), bounds)


class ToolpathBuilder:
    """Parsed G-code and printer profiles, cached by file version; line sets for a spec."""

    def __init__(self):
        self._gcode: dict[str, tuple[tuple, list]] = {}
        self._profiles: dict[str, tuple[tuple, Any]] = {}

    @staticmethod
    def _version(path: Path) -> tuple:
        st = path.stat()
        return (st.st_mtime_ns, st.st_size)

    def layers(self, gcode_path: str) -> list:
        path = Path(gcode_path)
        if not path.is_file():
            raise FileNotFoundError(f"print preview: the G-code {path} does not exist; slice the model again")
        version = self._version(path)
        hit = self._gcode.get(str(path))
        if hit is None or hit[0] != version:
            layers = parse_gcode(path.read_text(errors="replace"))
            if not layers:
                raise ValueError(f"print preview: {path} has no printing moves (no layers found)")
            self._gcode = {str(path): (version, layers)}  # one file at a time: the dialog's current slice
            hit = self._gcode[str(path)]
        return hit[1]

    def profile(self, printer: str | None):
        key = str(printer)
        p = Path(printer) if printer else None
        version = self._version(p) if p is not None and p.is_file() else ()
        hit = self._profiles.get(key)
        if hit is None or hit[0] != version:
            profile = resolve_profile(printer)
            hit = self._profiles[key] = (version, profile)
        return hit[1]

    def build(self, spec: dict) -> tuple[list, Any, dict]:
        """(line_sets in bed mm, the printer profile, info) for a spec. info: gen, layers, layer, current,
        outside (bool: moves drawn red), z."""
        layers = self.layers(spec["gcode"])
        profile = self.profile(spec.get("printer"))
        bed = (profile.bed.width, profile.bed.depth, profile.bed.height)
        n = len(layers)
        current = spec.get("current")
        layer = spec.get("layer")
        if current is not None:
            current = min(int(current), n - 1)
            layer = current
        elif layer is not None:
            if not 0 <= int(layer) < n:
                raise ValueError(f"print preview: layer {layer} does not exist; {spec['gcode']} has layers "
                                 f"0..{n - 1}")
            layer = int(layer)
        sets = toolpath_line_sets(layers, bed, layer=layer, current=current)
        outside = any(tuple(s.rgba) == tuple(OUT_OF_BED_COLOUR) for s in sets)
        info = {"gen": int(spec.get("gen", 0)), "layers": n, "layer": layer, "current": current,
                "outside": bool(outside), "z": float(layers[layer].z) if layer is not None else None}
        return sets, profile, info


class ToolpathStage:
    """Builds toolpath line sets off the frame loop and gives them to the pipeline thread.

    submit(fn): runs fn(pipeline) in the pipeline's thread between frames.
    on_info(info): called in the pipeline thread once a request is drawn (info
    as `ToolpathBuilder.build`'s, or {"gen": g, "layers": 0} when cleared).
    on_error(title, message): a request that cannot be shown.
    """

    def __init__(self, submit: Callable, on_info: Callable[[dict], None], on_error: Callable[[str, str], None]):
        self.submit, self.on_info, self.on_error = submit, on_info, on_error
        self.builder = ToolpathBuilder()
        self._cond = threading.Condition()
        self._pending: tuple[bool, dict | None] = (False, None)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="arapp-toolpaths", daemon=True)
        self._thread.start()

    def request(self, spec: dict | None, gen: int = 0) -> None:
        """Show `spec` (None: clear); `gen` numbers the request (reported back in the info). Replaces a request
        not yet built."""
        with self._cond:
            self._pending = (True, {"clear": True, "gen": int(gen)} if spec is None else {**spec, "gen": int(gen)})
            self._cond.notify_all()

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._pending[0] or self._stop)
                if self._stop:
                    return
                spec = self._pending[1]
                self._pending = (False, None)
            if spec.get("clear"):
                self.submit(lambda pipe, g=spec["gen"]: self._clear(pipe, g))
                continue
            try:
                sets, profile, info = self.builder.build(spec)
            except (ValueError, OSError) as exc:
                self.on_error("Cannot show the print preview", str(exc))
                continue
            except Exception as exc:  # noqa: BLE001 - a bug here must not end the live view
                self.on_error("Cannot show the print preview", f"{exc}\n{traceback.format_exc(limit=3)}")
                continue
            b = spec.get("bed_from_placement")
            self.submit(lambda pipe, s=sets, p=profile, b=b, i=info: self._apply(pipe, s, p, b, i))

    def _apply(self, pipe, sets, profile, bed_from_placement, info) -> None:
        try:
            T, by, text = place_toolpaths(pipe.anchors, profile, bed_from_placement)
        except ValueError as exc:
            self.on_error("Cannot show the print preview", str(exc))
            return
        pipe.set_toolpaths(sets, T)
        self.on_info({**info, "placed_by": by, "placed_text": text})

    def _clear(self, pipe, gen: int) -> None:
        pipe.toolpaths = None  # Pipeline has no clear method; None is its "no toolpaths" state
        self.on_info({"gen": gen, "layers": 0, "layer": None, "current": None, "outside": False, "z": None,
                      "placed_by": None, "placed_text": ""})
