"""Display modes and coloured line sets of the overlay.

Modes (what the surface looks like):
- "shaded": opaque, lit by a headlight at the camera plus ambient light.
- "wireframe": the mesh edges (hidden edges removed) over a faint surface.
- "isolines": `lines` (e.g. NURBS isolines and the control net) over a faintly shaded surface.
- "translucent": the nearest surface layer, shaded, at partial opacity.

Line sets are drawn on top in every mode, each with its own colour and width in pixels: the AR
print preview draws sliced toolpaths this way (perimeters, infill, travel in different colours):

    perim = LineSet(perimeter_polylines, (1.0, 0.5, 0.0, 1.0), width_px=2.0)
    travel = LineSet(travel_polylines, (0.2, 0.6, 1.0, 0.6), width_px=1.0, hidden_alpha=0.0)
    renderer.draw(frame, None, camera_from_printer, line_sets=[perim, travel])

Polylines are (k, 3) arrays in the model frame (same units and `camera_from_model` as the mesh).
Parts of a line behind the surface are drawn at `hidden_alpha` times its opacity (0 hides them).
Keep a LineSet object alive and pass the same one each frame: its GPU buffer is built once and
reused (keyed by the object); a plain tuple `(polylines, rgba[, width_px])` works too but is
uploaded on every call.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

MODES = ("shaded", "wireframe", "isolines", "translucent")

#: surface opacity per mode
SURFACE_ALPHA = {"shaded": 1.0, "wireframe": 0.18, "isolines": 0.35, "translucent": 0.45}

DEFAULT_COLOR = (0.72, 0.78, 0.90, 1.0)  # light steel blue, RGBA 0..1
ISOLINE_COLOR = (1.0, 0.55, 0.05, 1.0)  # orange, like a CAD control-net overlay
WIRE_COLOR = (0.10, 0.95, 0.35, 1.0)


def parse_rgba(color, default=DEFAULT_COLOR) -> tuple[float, float, float, float]:
    """RGBA floats 0..1 from None (default), 3 or 4 floats 0..1, or 3 or 4 ints 0..255."""
    if color is None:
        return tuple(float(c) for c in default)
    c = np.asarray(color, dtype=float).ravel()
    if c.size not in (3, 4) or not np.all(np.isfinite(c)):
        raise ValueError(f"colour must be 3 or 4 numbers (RGB[A], 0..1 floats or 0..255 ints), got {color!r}")
    if np.any(c > 1.0):
        c = c / 255.0
    if c.size == 3:
        c = np.append(c, 1.0)
    if np.any(c < 0) or np.any(c > 1):
        raise ValueError(f"colour components must be within 0..1 (or 0..255), got {color!r}")
    return tuple(float(v) for v in c)


@dataclass(eq=False)
class LineSet:
    """Polylines drawn in one colour and width. See the module docstring."""

    polylines: Sequence[np.ndarray]
    rgba: tuple = ISOLINE_COLOR
    width_px: float = 2.0
    hidden_alpha: float = 0.3
    # a stack of layers (toolpaths): segment index where each layer begins (ascending), and the distance
    # between layers (model units). The renderer then draws every k-th layer (and always the top one) when
    # k layers fit in `LAYER_PX_PER_WIDTH * width_px` pixels at the stack's nearest point: the same picture.
    layer_starts: np.ndarray | None = None
    layer_pitch: float = 0.0
    _segments: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        self.rgba = parse_rgba(self.rgba, ISOLINE_COLOR)
        self.width_px = float(self.width_px)
        if not (0.0 < self.width_px <= 64.0):
            raise ValueError(f"LineSet width_px must be in (0, 64] pixels, got {self.width_px}")
        if not (0.0 <= self.hidden_alpha <= 1.0):
            raise ValueError(f"LineSet hidden_alpha must be in [0, 1], got {self.hidden_alpha}")

    def segments(self) -> np.ndarray:
        """(2n, 3) float32 segment end points (GL_LINES order), built once."""
        if self._segments is None:
            self._segments = polylines_to_segments(self.polylines)
        return self._segments


LAYER_PX_PER_WIDTH = 0.5  # layers closer than half a line's width on screen: only every k-th drawn


def layer_stride(pitch_px: float, width_px: float) -> int:
    """How many layers of a stack each drawn layer stands for: layers `pitch_px` apart on screen, lines
    `width_px` wide, drawn so that the drawn ones stay at most LAYER_PX_PER_WIDTH * width_px apart."""
    if not pitch_px > 0:
        return 1
    return max(1, int(LAYER_PX_PER_WIDTH * width_px / pitch_px))


def layer_ranges(starts: np.ndarray, total: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(firsts, counts) in vertices (2 per segment) of every `stride`-th layer counted down from the top one
    (which is always drawn); neighbouring layers merged into one range."""
    starts = np.asarray(starts, np.int64)
    ends = np.append(starts[1:], total)
    keep = np.arange(len(starts))[::-1][::max(1, int(stride))][::-1]
    if stride <= 1:
        return np.array([2 * starts[0]], np.int32), np.array([2 * (total - starts[0])], np.int32)
    return (2 * starts[keep]).astype(np.int32), (2 * (ends[keep] - starts[keep])).astype(np.int32)


def as_line_set(item, default_rgba=ISOLINE_COLOR, default_width=2.0) -> LineSet:
    """A LineSet from a LineSet or a tuple (polylines, rgba[, width_px[, hidden_alpha]])."""
    if isinstance(item, LineSet):
        return item
    if not isinstance(item, (tuple, list)) or not 1 <= len(item) <= 4:
        raise ValueError(
            "each line set must be a LineSet or a tuple (polylines, rgba[, width_px[, hidden_alpha]])"
        )
    polylines = item[0]
    rgba = item[1] if len(item) > 1 else default_rgba
    width = item[2] if len(item) > 2 else default_width
    hidden = item[3] if len(item) > 3 else 0.3
    return LineSet(polylines, rgba, width, hidden)


def polylines_to_segments(polylines: Sequence[np.ndarray]) -> np.ndarray:
    """(2n, 3) float32 GL_LINES vertex list from polylines, each (k, 3) with k >= 2 (shorter ones skipped).

    Vectorised: an (n, k, 3) array or a list of many short polylines (e.g. toolpath segments) costs a
    few array operations, not a Python loop per segment.
    """
    if not isinstance(polylines, np.ndarray) and len(polylines) > 64:
        shapes = {getattr(p, "shape", None) for p in polylines}
        if len(shapes) == 1 and None not in shapes:  # many equal-shape arrays (toolpath segments): stack in C
            polylines = np.array(polylines, dtype=np.float32)
    if isinstance(polylines, np.ndarray):
        if polylines.ndim == 2:
            polylines = polylines[None]
        if polylines.ndim != 3 or polylines.shape[-1] != 3:
            raise ValueError(f"polylines must be (k, 3) arrays or an (n, k, 3) array, got shape {polylines.shape}")
        arr = polylines.astype(np.float32)
        if arr.shape[1] < 2:
            return np.zeros((0, 3), np.float32)
        out = np.stack([arr[:, :-1], arr[:, 1:]], axis=2).reshape(-1, 3)
    else:
        arrays = [np.asarray(p, dtype=np.float32) for p in polylines]
        for i, p in enumerate(arrays):
            if p.ndim != 2 or p.shape[1] != 3:
                raise ValueError(f"polyline {i} must be a (k, 3) array of model-frame points, got shape {p.shape}")
        arrays = [p for p in arrays if len(p) >= 2]
        if not arrays:
            return np.zeros((0, 3), np.float32)
        pts = np.concatenate(arrays)
        lengths = np.array([len(p) for p in arrays])
        last = np.cumsum(lengths) - 1  # index of each polyline's last point: no segment starts there
        start = np.ones(len(pts), bool)
        start[last] = False
        idx = np.nonzero(start)[0]
        out = np.empty((2 * len(idx), 3), np.float32)
        out[0::2] = pts[idx]
        out[1::2] = pts[idx + 1]
    if not np.all(np.isfinite(out)):
        raise ValueError("polylines contain NaN or infinite coordinates")
    return np.ascontiguousarray(out)
