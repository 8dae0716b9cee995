"""Infill lines: parallel scan lines clipped to an area, joined into zigzags (mm, degrees)."""

from __future__ import annotations

import numpy as np
import shapely
from shapely import affinity


def _rotation(angle_deg: float) -> np.ndarray:
    a = np.radians(angle_deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def scan_segments(area, spacing: float, angle_deg: float, min_length: float):
    """Scan lines at `angle_deg` through `area`, `spacing` apart on a grid anchored at the bed origin.

    Returns (rows, x0, x1, y, rotated_area): segments in the frame rotated by
    -angle (scan lines horizontal), sorted by row then x.
    """
    rot = affinity.rotate(area, -angle_deg, origin=(0.0, 0.0))
    minx, miny, maxx, maxy = rot.bounds
    j0 = int(np.floor(miny / spacing))
    j1 = int(np.ceil(maxy / spacing))
    ys = (np.arange(j0, j1 + 1) + 0.5) * spacing
    ys = ys[(ys > miny) & (ys < maxy)]
    empty = np.zeros(0)
    if len(ys) == 0:
        return np.zeros(0, dtype=int), empty, empty, empty, rot
    coords = np.zeros((len(ys), 2, 2))
    coords[:, 0, 0], coords[:, 1, 0] = minx - 1.0, maxx + 1.0
    coords[:, :, 1] = ys[:, None]
    # clip each scan line only against the islands its bounding box meets (an STRtree), not the whole area
    lines = shapely.linestrings(coords)
    islands = shapely.get_parts(rot)
    li, pi = shapely.STRtree(islands).query(lines, predicate="intersects")
    clipped = shapely.intersection(lines[li], islands[pi])
    parts, sub = shapely.get_parts(clipped, return_index=True)
    idx = li[sub]
    keep = (shapely.get_type_id(parts) == 1) & ~shapely.is_empty(parts)  # LineStrings
    parts, idx = parts[keep], idx[keep]
    if len(parts) == 0:
        return np.zeros(0, dtype=int), empty, empty, empty, rot
    a = shapely.get_coordinates(shapely.get_point(parts, 0))[:, 0]
    b = shapely.get_coordinates(shapely.get_point(parts, -1))[:, 0]
    x0, x1 = np.minimum(a, b), np.maximum(a, b)
    ok = (x1 - x0) >= min_length
    rows, x0, x1 = idx[ok], x0[ok], x1[ok]
    order = np.lexsort((x0, rows))
    return rows[order], x0[order], x1[order], ys[rows[order]], rot


def zigzag(area, spacing: float, angle_deg: float, width: float, link: bool = True) -> list[np.ndarray]:
    """Fill `area` with scan lines, each joined to the next row's nearest line end when the joint
    stays inside the area: a few continuous zigzag polylines ((N, 2) arrays, bed frame)."""
    if area is None or area.is_empty:
        return []
    if not area.is_valid:  # clipping against an invalid area can return lines outside it
        area = shapely.make_valid(area)
    rows, x0, x1, y, rot = scan_segments(area, spacing, angle_deg, min_length=width * 0.5)
    n = len(rows)
    if n == 0:
        return []
    guard = shapely.buffer(rot, width * 0.25)
    shapely.prepare(guard)
    by_row: dict[int, list[int]] = {}
    for i, r in enumerate(rows.tolist()):
        by_row.setdefault(r, []).append(i)
    used = np.zeros(n, dtype=bool)
    max_link = 3.0 * spacing + width
    rows_l, x0_l, x1_l, y_l = rows.tolist(), x0.tolist(), x1.tolist(), y.tolist()
    paths = []
    for first in range(n):
        if used[first]:
            continue
        used[first] = True
        pts = [(x0_l[first], y_l[first]), (x1_l[first], y_l[first])]
        r = rows_l[first]
        while link:
            ex, ey = pts[-1]
            best, best_d, best_flip = -1, max_link, False
            for j in by_row.get(r + 1, ()):
                if used[j]:
                    continue
                for xj, flip in ((x0_l[j], False), (x1_l[j], True)):
                    d = abs(xj - ex)
                    if d < best_d:
                        best, best_d, best_flip = j, d, flip
            if best < 0:
                break
            near = (x1_l[best], y_l[best]) if best_flip else (x0_l[best], y_l[best])
            if not guard.covers(shapely.LineString([pts[-1], near])):
                break
            used[best] = True
            far = (x0_l[best], y_l[best]) if best_flip else (x1_l[best], y_l[best])
            pts.extend([near, far])
            r += 1
        paths.append(np.asarray(pts) @ _rotation(angle_deg).T)
    return paths
