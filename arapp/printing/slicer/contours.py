"""Layer planes and contours: a triangle mesh cut by planes z = z_k, chained into closed loops.

All coordinates are millimetres in the bed frame (z up). The cut works on the
mesh's unique edges: each edge that crosses a plane gives one point, shared by
the two facets on that edge, so chaining is exact integer bookkeeping rather
than floating-point matching. A vertex within `tol` of a plane counts as lying
on it and is classed above it, so planes through vertices, edges or whole
facets give no duplicate or zero-length pieces. Degenerate facets (repeated
vertices, zero area) are harmless; open chains left by missing facets are
joined end to start within `gap` or closed on themselves.
"""

from __future__ import annotations

import numpy as np
import shapely


def layer_planes(height: float, first_layer_height: float, layer_height: float):
    """Uniform layers for an object standing on z = 0 and `height` mm tall.

    Returns (tops, heights, cut_z): each layer's top (its print z), its
    thickness and the height of its cutting plane (the middle of the layer).
    A layer is kept while its cutting plane lies below the object's top, the
    rule PrusaSlicer uses, so both slicers give the same layer count.
    """
    if first_layer_height <= 0 or layer_height <= 0:
        raise ValueError("layer heights must be positive millimetres")
    if height <= first_layer_height / 2:
        raise ValueError(f"the model is {height:.3f} mm tall, thinner than half a first layer "
                         f"({first_layer_height} mm); it cannot be sliced")
    n = 1 + max(0, int(np.ceil((height - first_layer_height - layer_height / 2) / layer_height - 1e-9)))
    tops = first_layer_height + layer_height * np.arange(n, dtype=float)
    heights = np.full(n, layer_height)
    heights[0] = first_layer_height
    cut_z = tops - heights / 2
    keep = cut_z < height - 1e-9
    return tops[keep], heights[keep], cut_z[keep]


def cut_segments(vertices: np.ndarray, faces: np.ndarray, face_edges: np.ndarray, edges: np.ndarray,
                 planes: np.ndarray, tol: float = 1e-6):
    """Every facet/plane crossing as a directed segment between two edge/plane points.

    vertices (V,3) mm, faces (F,3), face_edges (F,3) indices into edges (E,2)
    for the face sides (v0,v1), (v1,v2), (v2,v0); planes sorted ascending.
    Returns (layer, start_key, end_key, node_keys, node_points): keys are
    layer * E + edge; segments run with the material on their left (outer
    loops counter-clockwise seen from +z) for outward-wound facets.
    """
    planes = np.asarray(planes, dtype=float) - tol  # a vertex within tol of a plane is on it, classed above
    fz = vertices[faces, 2]
    k_lo = np.searchsorted(planes, fz.min(axis=1), side="right")
    k_hi = np.searchsorted(planes, fz.max(axis=1), side="right")
    count = np.maximum(k_hi - k_lo, 0)
    total = int(count.sum())
    if total == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty, np.zeros((0, 2))
    face = np.repeat(np.arange(len(faces)), count)
    starts = np.cumsum(count) - count
    layer = k_lo[face] + (np.arange(total) - np.repeat(starts, count))
    above = fz[face] >= planes[layer][:, None]
    nxt = np.roll(above, -1, axis=1)            # the vertex after each side's start, in winding order
    up = ~above & nxt                             # side climbing through the plane
    down = above & ~nxt                           # side descending through the plane
    up_side = np.argmax(up, axis=1)
    down_side = np.argmax(down, axis=1)
    n_edges = len(edges)
    # Walking a face in winding order, material lies to the left of the
    # segment from the descending side's point to the climbing side's point.
    start_key = layer * n_edges + face_edges[face, down_side]
    end_key = layer * n_edges + face_edges[face, up_side]
    ok = start_key != end_key                     # a facet with a repeated vertex gives a point, not a segment
    layer, start_key, end_key = layer[ok], start_key[ok], end_key[ok]
    node_keys, inverse = np.unique(np.concatenate([start_key, end_key]), return_inverse=True)
    node_layer = node_keys // n_edges
    e = edges[node_keys % n_edges]
    a, b = vertices[e[:, 0]], vertices[e[:, 1]]
    t = (planes[node_layer] - a[:, 2]) / (b[:, 2] - a[:, 2])
    points = a[:, :2] + t[:, None] * (b[:, :2] - a[:, :2])
    m = len(start_key)
    return layer, inverse[:m], inverse[m:], node_keys, points


def chain_loops(start: np.ndarray, end: np.ndarray, n_nodes: int) -> tuple[list[np.ndarray], list[bool]]:
    """Chain directed segments (node index pairs) into node sequences.

    Returns (chains, is_open): closed cycles come back without the repeated
    first node; open chains (left by holes in the mesh) are flagged in `is_open`.
    """
    nxt = np.full(n_nodes, -1, dtype=np.int64)
    nxt[start] = end
    has_in = np.zeros(n_nodes, dtype=bool)
    has_in[end] = True
    chains, is_open = [], []
    nxt_list = nxt.tolist()  # plain lists: the walk below is a tight Python loop
    used_list = [False] * n_nodes
    present = np.zeros(n_nodes, dtype=bool)
    present[start] = True
    present[end] = True
    open_starts = np.flatnonzero(present & ~has_in).tolist()
    for seeds, opened in ((open_starts, True), (np.flatnonzero(present).tolist(), False)):
        for s in seeds:
            if used_list[s]:
                continue
            seq = []
            n = s
            while n != -1 and not used_list[n]:
                used_list[n] = True
                seq.append(n)
                n = nxt_list[n]
            chains.append(np.asarray(seq, dtype=np.int64))
            is_open.append(opened or n != s)
    return chains, is_open


def _close_open_chains(chains: list[np.ndarray], gap: float) -> list[np.ndarray]:
    """Join open chains (lists of points) end to start when the gap is below `gap` mm; close the rest."""
    chains = [c for c in chains if len(c) >= 2]
    loops = []
    while chains:
        cur = chains.pop(0)
        while chains:
            starts = np.array([c[0] for c in chains])
            d = np.linalg.norm(starts - cur[-1], axis=1)
            j = int(np.argmin(d))
            if d[j] > gap or np.linalg.norm(cur[0] - cur[-1]) < d[j]:
                break
            cur = np.vstack([cur, chains.pop(j)])
        loops.append(cur)
    return loops


def slice_loops(mesh, planes: np.ndarray, tol: float = 1e-6, gap: float = 1.0) -> list[list[np.ndarray]]:
    """Closed contour loops per plane: a list (one entry per plane) of (N, 2) point arrays in mm."""
    vertices = np.asarray(mesh.vertices, dtype=float)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    edges = np.asarray(mesh.edges_unique, dtype=np.int64)
    face_edges = np.asarray(mesh.faces_unique_edges, dtype=np.int64)
    layer, s, e, keys, points = cut_segments(vertices, faces, face_edges, edges, planes, tol)
    result: list[list[np.ndarray]] = [[] for _ in range(len(planes))]
    open_by_layer: dict[int, list[np.ndarray]] = {}
    if len(s) == 0:
        return result
    node_layer = keys // len(edges)
    chains, is_open = chain_loops(s, e, len(keys))
    for seq, opened in zip(chains, is_open):
        k = int(node_layer[seq[0]])
        pts = points[seq]
        if opened:
            open_by_layer.setdefault(k, []).append(pts)
        elif len(pts) >= 3:
            result[k].append(pts)
    for k, open_chains in open_by_layer.items():
        result[k].extend(c for c in _close_open_chains(open_chains, gap) if len(c) >= 3)
    return result


def loops_to_region(loops: list[np.ndarray], simplify: float = 0.0):
    """The filled region bounded by loops: counter-clockwise loops add material, clockwise ones remove it.

    Loops are applied from the largest area to the smallest, so holes and islands
    inside holes nest correctly and overlapping shells unite.
    """
    if not loops:
        return shapely.Polygon()
    coords = np.concatenate([np.vstack([l, l[:1]]) for l in loops])
    ids = np.repeat(np.arange(len(loops)), [len(l) + 1 for l in loops])
    rings = shapely.linearrings(coords, indices=ids)
    polys = shapely.polygons(rings)
    ccw = shapely.is_ccw(rings)
    polys = shapely.make_valid(shapely.polygons(rings), method="structure") if not np.all(shapely.is_valid(polys)) else polys
    area = shapely.area(polys)
    signed = np.where(ccw, area, -area)
    if signed.sum() < 0:  # an open mesh wound inside out: every loop runs backwards
        ccw = ~ccw
    if simplify > 0:
        polys = shapely.simplify(polys, simplify)
    order = np.argsort(-area)
    if np.all(ccw):
        region = shapely.multipolygons(polys) if len(polys) > 1 else polys[0]
        if not shapely.is_valid(region):  # overlapping shells: unite them
            region = shapely.union_all(polys)
    else:
        region = shapely.Polygon()
        for i in order:
            if area[i] <= 1e-9:
                continue
            region = shapely.union(region, polys[i]) if ccw[i] else shapely.difference(region, polys[i])
    return _polygonal(region)


def _polygonal(geom):
    """Only the polygonal part of a geometry, as a Polygon or MultiPolygon."""
    if geom.is_empty:
        return shapely.Polygon()
    if geom.geom_type in ("Polygon", "MultiPolygon"):
        return geom
    parts = [g for g in shapely.get_parts(geom) if g.geom_type in ("Polygon", "MultiPolygon")]
    return shapely.union_all(parts) if parts else shapely.Polygon()
