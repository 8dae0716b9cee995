"""Per-layer path planning: skirt, walls (inner to outer), solid then sparse infill, in nearest-first order.

Everything is in the bed frame, millimetres. The planner only orders
extrusions; travel moves, retraction and z-hop are added by the G-code writer
between consecutive paths.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely

from ..toolpath import LayerToolpaths, ToolPath
from .infill import zigzag
from .perimeters import island_walls, polygon_parts

def _start_loop_near(loop: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """A closed loop (first point repeated last) restarted at its vertex nearest `pos`."""
    core = loop[:-1]
    i = int(np.argmin(((core - pos) ** 2).sum(axis=1)))
    core = np.roll(core, -i, axis=0)
    return np.vstack([core, core[:1]])


def order_polylines(polylines: list[np.ndarray], pos: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Open polylines in nearest-end-first order, each reversed when its far end is nearer. Returns (ordered, end)."""
    n = len(polylines)
    if n == 0:
        return [], pos
    starts = np.array([p[0] for p in polylines])
    ends = np.array([p[-1] for p in polylines])
    left = np.ones(n, dtype=bool)
    out = []
    for _ in range(n):
        ds = ((starts - pos) ** 2).sum(axis=1)
        de = ((ends - pos) ** 2).sum(axis=1)
        d = np.where(left, np.minimum(ds, de), np.inf)
        i = int(np.argmin(d))
        left[i] = False
        p = polylines[i][::-1] if de[i] < ds[i] else polylines[i]
        out.append(p)
        pos = p[-1]
    return out, pos


def _nearest_first(items: list, anchors: np.ndarray, pos: np.ndarray):
    """Items in greedy nearest-first order by their anchor points (N, 2), starting from `pos`."""
    left = np.ones(len(items), dtype=bool)
    for _ in range(len(items)):
        d = np.where(left, ((anchors - pos) ** 2).sum(axis=1), np.inf)
        i = int(np.argmin(d))
        left[i] = False
        pos = anchors[i]
        yield items[i]


def skirt_loops(first_region, count: int, distance: float, width: float) -> list[np.ndarray]:
    """Skirt loops around the convex hull of the first layer, `distance` mm out, outermost last."""
    if count <= 0 or first_region.is_empty:
        return []
    hull = shapely.convex_hull(first_region)
    loops = []
    for i in range(count):
        g = shapely.buffer(hull, distance + (i + 0.5) * width, quad_segs=8)
        loops.append(np.asarray(g.exterior.coords)[:, :2])
    return loops


def plan_layer(index: int, z: float, height: float, region, solid, sparse, settings, width: float,
               pos: np.ndarray, skirt: list[np.ndarray] | None = None) -> tuple[LayerToolpaths, np.ndarray]:
    """Toolpaths of one layer, starting from nozzle position `pos`; returns the layer and the end position."""
    layer = LayerToolpaths(index=index, z=z, height=height)
    for loop in skirt or []:
        loop = _start_loop_near(loop, pos)
        layer.paths.append(ToolPath("skirt", loop, width))
        pos = loop[-1]
    islands = polygon_parts(region)
    anchors = np.array([isl.exterior.coords[0][:2] for isl in islands]).reshape(-1, 2)
    all_walls = island_walls(islands, settings.perimeters, width, settings.resolution)
    for walls in _nearest_first(all_walls, anchors, pos):
        for i in range(len(walls) - 1, -1, -1):
            kind = "external_perimeter" if i == 0 else "perimeter"
            loops = list(walls[i])
            while loops:
                dists = [np.min(((l - pos) ** 2).sum(axis=1)) for l in loops]
                loop = _start_loop_near(loops.pop(int(np.argmin(dists))), pos)
                layer.paths.append(ToolPath(kind, loop, width))
                pos = loop[-1]
    angle = settings.infill_angle + (90.0 if index % 2 else 0.0)
    if solid is not None and not solid.is_empty:
        lines, pos = order_polylines(zigzag(solid, width, angle, width), pos)
        layer.paths.extend(ToolPath("solid_infill", p, width) for p in lines)
    if sparse is not None and not sparse.is_empty and settings.infill > 0:
        density = settings.infill / 100.0
        if settings.infill_pattern == "grid":
            lines = zigzag(sparse, 2 * width / density, settings.infill_angle, width)
            lines += zigzag(sparse, 2 * width / density, settings.infill_angle + 90.0, width)
        else:
            lines = zigzag(sparse, width / density, angle, width)
        lines, pos = order_polylines(lines, pos)
        layer.paths.extend(ToolPath("sparse_infill", p, width) for p in lines)
    return layer, pos
