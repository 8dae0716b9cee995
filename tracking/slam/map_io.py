"""The keypoint map as flat numpy arrays (for scene files), back again, and keyframe culling for saving.

    arrays = map_to_arrays(m)          # {name: ndarray}, see ARRAYS; metres, world frame
    m2 = map_from_arrays(arrays)       # a new Map (MapError naming the array when inconsistent)
    adopt(live_map, m2)                # put a loaded map's content into the tracker's own Map object
    cull_keyframes(m, max_keyframes)   # drop redundant keyframes before saving (bounded files)

Keyframe features are stored whole (not only the matched ones): a later run triangulates new points
against the saved keyframes' unmatched features, and bundle adjustment needs every observation. Pixel
coordinates are float32 (1/1000 px at 640 px, far below the detector's noise); poses and point
positions stay float64. Covisibility (keyframe pairs sharing points) is derived from the observations
and written for readers of the file, not read back.
"""

from __future__ import annotations

import numpy as np

from tracking.slam.features import Features
from tracking.slam.map import Keyframe, Map, MapPoint


class MapError(ValueError):
    """Saved map arrays that are missing or inconsistent; the message names the array."""


# name: (dtype kind, trailing shape) - N keyframes, F features over all keyframes, P points, O observations
ARRAYS = {
    "kf_id": ("i", ()),             # (N,) keyframe ids
    "kf_t": ("f", ()),              # (N,) seconds, of the run that made the keyframe
    "kf_pose": ("f", (4, 4)),       # (N,4,4) world_from_camera
    "kf_nfeat": ("i", ()),          # (N,) features per keyframe; features are stored keyframe after keyframe
    "kf_anchor_n": ("i", ()),       # (N,) anchor corners seen per keyframe
    "feat_xy": ("f", (2,)),         # (F,2) distorted pixels
    "feat_und": ("f", (2,)),        # (F,2) undistorted pixels
    "feat_octave": ("i", ()),       # (F,) pyramid level
    "feat_desc": ("u", (32,)),      # (F,32) ORB descriptors
    "feat_point": ("i", ()),        # (F,) map point id of the feature or -1
    "anchor_world": ("f", (3,)),    # (A,3) anchor corners in the world, keyframe after keyframe
    "anchor_uv": ("f", (2,)),       # (A,2) their undistorted pixels
    "pt_id": ("i", ()),             # (P,) map point ids
    "pt_xyz": ("f", (3,)),          # (P,3) metres, world frame
    "pt_desc": ("u", (32,)),        # (P,32) representative descriptor
    "pt_first_kf": ("i", ()),       # (P,) keyframe that created the point
    "pt_counts": ("i", (2,)),       # (P,2) times predicted visible, times matched (tracking statistics)
    "covis": ("i", (3,)),           # (C,3) keyframe a, keyframe b, points they share (derived; not read)
}


def covisibility(m: Map, min_shared: int = 15) -> np.ndarray:
    """(C,3) int: keyframe pairs (a < b) sharing at least `min_shared` map points, and how many."""
    with m.lock:
        pairs: dict[tuple[int, int], int] = {}
        for p in m.points.values():
            ks = sorted(p.obs)
            for i, a in enumerate(ks):
                for b in ks[i + 1:]:
                    pairs[(a, b)] = pairs.get((a, b), 0) + 1
    rows = [(a, b, n) for (a, b), n in sorted(pairs.items()) if n >= min_shared]
    return np.array(rows, np.int64).reshape(-1, 3)


def map_to_arrays(m: Map) -> dict[str, np.ndarray]:
    """The map's keyframes and points as the flat arrays of ARRAYS (a consistent snapshot)."""
    with m.lock:
        kfs = [m.keyframes[k] for k in sorted(m.keyframes)]
        pts = [m.points[p] for p in sorted(m.points)]
        feats = [k.feats for k in kfs]
        point_of = [np.where([int(q) in m.points for q in k.point_ids], k.point_ids, -1) if len(k.point_ids)
                    else np.zeros(0, int) for k in kfs]
        counts = np.array([m.match_counts(p.id) for p in pts], np.int64).reshape(-1, 2) - 1
        a = {
            "kf_id": np.array([k.id for k in kfs], np.int64),
            "kf_t": np.array([k.t for k in kfs], np.float64),
            "kf_pose": np.array([k.pose for k in kfs], np.float64).reshape(-1, 4, 4),
            "kf_nfeat": np.array([len(f) for f in feats], np.int64),
            "kf_anchor_n": np.array([k.anchor_world.shape[0] for k in kfs], np.int64),
            "feat_xy": _cat([f.xy for f in feats], (0, 2), np.float32),
            "feat_und": _cat([f.und for f in feats], (0, 2), np.float32),
            "feat_octave": _cat([f.octave for f in feats], (0,), np.int8),
            "feat_desc": _cat([f.desc for f in feats], (0, 32), np.uint8),
            "feat_point": _cat(point_of, (0,), np.int64),
            "anchor_world": _cat([k.anchor_world for k in kfs], (0, 3), np.float64),
            "anchor_uv": _cat([k.anchor_uv for k in kfs], (0, 2), np.float32),
            "pt_id": np.array([p.id for p in pts], np.int64),
            "pt_xyz": np.array([p.xyz for p in pts], np.float64).reshape(-1, 3),
            "pt_desc": np.array([p.desc for p in pts], np.uint8).reshape(-1, 32),
            "pt_first_kf": np.array([p.first_kf for p in pts], np.int64),
            "pt_counts": counts,
        }
    a["covis"] = covisibility(m)
    return a


def _cat(parts, empty_shape, dtype) -> np.ndarray:
    parts = [np.asarray(p) for p in parts if len(p)]
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(empty_shape, dtype)


def _check(a: dict) -> None:
    for name, (kind, tail) in ARRAYS.items():
        if name == "covis":
            continue
        if name not in a:
            raise MapError(f"map array {name!r} missing")
        v = a[name]
        if not isinstance(v, np.ndarray) or v.shape[1:] != tail or (
                v.dtype.kind not in (("i", "u") if kind in "iu" else ("f",))):
            raise MapError(f"map array {name!r}: expected {kind} values of shape (n, {', '.join(map(str, tail))}), "
                           f"got {getattr(v, 'dtype', type(v))} {getattr(v, 'shape', '')}")
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            raise MapError(f"map array {name!r}: holds NaN or infinite values")
    n, p = len(a["kf_id"]), len(a["pt_id"])
    for name in ("kf_t", "kf_pose", "kf_nfeat", "kf_anchor_n"):
        if len(a[name]) != n:
            raise MapError(f"map array {name!r}: {len(a[name])} rows for {n} keyframes")
    f = int(a["kf_nfeat"].sum()) if n else 0
    for name in ("feat_xy", "feat_und", "feat_octave", "feat_desc", "feat_point"):
        if len(a[name]) != f:
            raise MapError(f"map array {name!r}: {len(a[name])} rows for {f} keyframe features")
    na = int(a["kf_anchor_n"].sum()) if n else 0
    for name in ("anchor_world", "anchor_uv"):
        if len(a[name]) != na:
            raise MapError(f"map array {name!r}: {len(a[name])} rows for {na} anchor corners")
    for name in ("pt_xyz", "pt_desc", "pt_first_kf", "pt_counts"):
        if len(a[name]) != p:
            raise MapError(f"map array {name!r}: {len(a[name])} rows for {p} points")
    if len(np.unique(a["kf_id"])) != n or len(np.unique(a["pt_id"])) != p:
        raise MapError("map arrays 'kf_id' / 'pt_id': ids repeat")
    if (a["kf_nfeat"] < 0).any() or (a["kf_anchor_n"] < 0).any() or (a["pt_id"] < 0).any() or (a["kf_id"] < 0).any():
        raise MapError("map arrays: negative ids or counts")
    known = set(a["pt_id"].tolist())
    bad = [int(q) for q in np.unique(a["feat_point"]) if q >= 0 and int(q) not in known]
    if bad:
        raise MapError(f"map array 'feat_point': refers to {len(bad)} points not in 'pt_id' (e.g. {bad[0]})")


def map_from_arrays(a: dict) -> Map:
    """A Map from the arrays of `map_to_arrays` (MapError when they do not fit together)."""
    _check(a)
    m = Map()
    f0 = a0 = 0
    for i, kid in enumerate(a["kf_id"].tolist()):
        nf, na = int(a["kf_nfeat"][i]), int(a["kf_anchor_n"][i])
        s = slice(f0, f0 + nf)
        feats = Features(a["feat_xy"][s].astype(float), a["feat_und"][s].astype(float),
                         a["feat_octave"][s].astype(int), np.ascontiguousarray(a["feat_desc"][s], np.uint8))
        kf = Keyframe(int(kid), float(a["kf_t"][i]), a["kf_pose"][i].astype(float).copy(), feats,
                      a["feat_point"][s].astype(int).copy(),
                      a["anchor_world"][a0:a0 + na].astype(float).copy(), a["anchor_uv"][a0:a0 + na].astype(float))
        m.keyframes[kf.id] = kf
        f0, a0 = f0 + nf, a0 + na
    for i, pid in enumerate(a["pt_id"].tolist()):
        m.points[int(pid)] = MapPoint(int(pid), a["pt_xyz"][i].astype(float).copy(),
                                      np.ascontiguousarray(a["pt_desc"][i], np.uint8), {}, int(a["pt_first_kf"][i]))
    for kf in m.keyframes.values():
        for fi, pid in enumerate(kf.point_ids.tolist()):
            if pid >= 0:
                m.points[pid].obs[kf.id] = fi
    # points no keyframe sees any more carry nothing (bundle adjustment could not hold them)
    for pid in [p.id for p in m.points.values() if not p.obs]:
        del m.points[pid]
    m._next_kf = (max(m.keyframes) + 1) if m.keyframes else 0
    m._next_pt = (max(m.points) + 1) if m.points else 0
    counts = a["pt_counts"]
    if m._next_pt:
        m._visible = np.zeros(m._next_pt, np.int32)
        m._found = np.zeros(m._next_pt, np.int32)
        for pid, (v, f) in zip(a["pt_id"].tolist(), counts.tolist()):
            if pid in m.points:
                m._visible[pid], m._found[pid] = max(0, v), max(0, f)
    m.version += 1
    return m


def adopt(dst: Map, src: Map) -> None:
    """Replace `dst`'s content by `src`'s (the tracker and its mapper keep their reference to `dst`)."""
    with dst.lock, src.lock:
        dst.keyframes = src.keyframes
        dst.points = src.points
        dst._next_kf, dst._next_pt = src._next_kf, src._next_pt
        dst._visible, dst._found = src._visible.copy(), src._found.copy()
        dst.version += 1
        dst._cache_version = -1


def cull_keyframes(m: Map, max_keyframes: int = 120, redundancy: float = 0.9, min_views: int = 3,
                   keep_anchor_kfs: int = 4) -> int:
    """Remove redundant keyframes: those whose map points (at least `redundancy` of them) are each seen
    by `min_views` other keyframes (ORB-SLAM's rule), most redundant first; then, while more than
    `max_keyframes` remain, the most redundant of the rest. The last `keep_anchor_kfs` keyframes that saw
    anchor corners always stay (they tie the map to the markers). Points left without observations go too.
    Returns keyframes removed."""
    removed = 0
    with m.lock:
        while len(m.keyframes) > 2:
            score = {}
            anchored = sum(kf.from_anchors for kf in m.keyframes.values())
            for kf in m.keyframes.values():
                if kf.from_anchors and anchored <= keep_anchor_kfs:
                    continue
                pids = [int(p) for p in kf.point_ids if p >= 0 and int(p) in m.points]
                if not pids:
                    score[kf.id] = 1.0
                    continue
                seen = sum(1 for p in pids if len(m.points[p].obs) - 1 >= min_views)
                score[kf.id] = seen / len(pids)
            if not score:
                break
            kid = max(score, key=lambda k: (score[k], -k))
            if score[kid] < redundancy and len(m.keyframes) <= max_keyframes:
                break
            _drop_keyframe(m, kid)
            removed += 1
    return removed


def _drop_keyframe(m: Map, kid: int) -> None:
    kf = m.keyframes.pop(kid)
    for pid in kf.point_ids:
        p = m.points.get(int(pid))
        if pid >= 0 and p is not None:
            p.obs.pop(kid, None)
            if len(p.obs) == 0:
                m.points.pop(int(pid))
    m.version += 1
