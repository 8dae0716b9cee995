"""Walls and solid/sparse areas of one layer, by inward offsets of its region (shapely, mm)."""

from __future__ import annotations

import numpy as np
import shapely


def polygon_parts(geom) -> list:
    """The Polygons of a Polygon/MultiPolygon/collection (empty ones dropped)."""
    if geom is None or geom.is_empty:
        return []
    return [g for g in shapely.get_parts(geom) if g.geom_type == "Polygon" and not g.is_empty]


def rings(poly) -> list[np.ndarray]:
    """Exterior then interior rings of a Polygon as closed (N, 2) arrays (first point repeated last)."""
    out = [np.asarray(poly.exterior.coords)[:, :2]]
    out.extend(np.asarray(r.coords)[:, :2] for r in poly.interiors)
    return [r for r in out if len(r) >= 4]


def combine(parts) -> object:
    """Disjoint polygons (or polygonal geometries) as one Polygon/MultiPolygon, without an overlay."""
    polys = [p for g in parts for p in polygon_parts(g)]
    if not polys:
        return shapely.Polygon()
    return polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys)


def island_walls(islands, count: int, width: float, resolution: float) -> list[list[list[np.ndarray]]]:
    """Wall loops per island, outermost wall first: walls[j][i] is the list of closed loops of
    wall i of island j. Wall i's centre line lies (i + 1/2) line widths inside the island's outline,
    so the outer wall's edge follows the outline. Islands are offset one by one (vectorised), which
    is far cheaper than offsetting a multi-island region.
    """
    islands = np.asarray(islands, dtype=object)
    walls: list[list[list[np.ndarray]]] = [[] for _ in range(len(islands))]
    for i in range(count):
        # the region is already simplified to `resolution`; mitre offsets add no vertices to simplify away
        g = shapely.buffer(islands, -(i + 0.5) * width, join_style="mitre", mitre_limit=2.0)
        for j, geom in enumerate(g):
            loops = [r for p in polygon_parts(geom) for r in rings(p)]
            if loops and len(walls[j]) == i:
                walls[j].append(loops)
    return walls


def fill_area(region, count: int, width: float, overlap: float):
    """The area left for infill inside `count` walls, reaching `overlap` line widths into the inner wall."""
    inset = (count - overlap) * width if count > 0 else 0.5 * width
    parts = polygon_parts(region)
    if not parts:
        return shapely.Polygon()
    return combine(shapely.buffer(np.asarray(parts, dtype=object), -inset, join_style="mitre", mitre_limit=2.0))


def solid_areas(regions: list, fills: list, top: int, bottom: int, width: float) -> list:
    """Per layer, the part of its fill area that must be solid: not covered by the model
    on all of the `top` layers above and the `bottom` layers below (the first `bottom` and
    last `top` layers are solid through). Slivers thinner than half a line width go to sparse infill.
    """
    n = len(regions)
    for r in regions:
        shapely.prepare(r)
    out = []
    for k in range(n):
        fill = fills[k]
        if fill.is_empty or k - bottom < 0 or k + top >= n:
            out.append(fill)
            continue
        window = [regions[j] for j in range(k - bottom, k + top + 1) if j != k]
        parts = np.asarray(polygon_parts(fill), dtype=object)
        # most fill islands lie inside every neighbour layer's region (walls of a prism): no overlay needed
        inside = np.ones(len(parts), dtype=bool)
        for r in window:
            inside &= shapely.contains(r, parts)
        if inside.all():
            out.append(shapely.Polygon())
            continue
        rest = combine(parts[~inside])
        box = rest.bounds
        covered = shapely.intersection_all([shapely.clip_by_rect(r, *box) for r in window])
        solid = open_area(shapely.difference(rest, covered), width / 4)
        out.append(shapely.intersection(solid, rest) if not solid.is_empty else solid)
    return out


def open_area(area, radius: float):
    """Morphological opening (shrink then grow by `radius` mm): drops slivers thinner than 2 x radius
    and the zero-area debris boolean operations leave; the result is valid."""
    if area is None or area.is_empty:
        return shapely.Polygon()
    if not area.is_valid:
        area = shapely.make_valid(area)
    g = shapely.buffer(shapely.buffer(area, -radius, join_style="mitre"), radius, join_style="mitre")
    return g if not g.is_empty else shapely.Polygon()


def split_fill(fill, solid, width: float):
    """(solid, sparse) areas of a fill area; slivers of the sparse part thinner than half a line are dropped."""
    if solid.is_empty:
        return solid, open_area(fill, width / 4)
    return solid, open_area(shapely.difference(fill, solid), width / 4)
