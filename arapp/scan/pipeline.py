"""The scan pipeline: frames -> tracked views -> chosen views -> refined poses -> depth maps -> solid.

    result = scan(source, camera, anchors, ScanOptions(), progress=print_progress)
    result.mesh          # trimesh.Trimesh, watertight, world frame (the anchors' frame), metres
    write_mesh(result.mesh, "vase.stl", print_mm=True)   # temp file + rename: never half-written

Steps (each reports to `progress(stage, done, total)`): the tracker places
every frame from the markers (metres); views are chosen by sharpness and
baseline; SIFT + bundle adjustment refine their poses with the markers'
corners as fixed points; SGBM gives depth per rectified pair, filtered for
multi-view consistency (or, when the frames carry depth from a depth camera or
a recording's depth stream, each view's own depth is used, cleaned map by map:
no matching); the object's region is what stands on the board; a
TSDF over it, closed by the silhouette hull and cut at the paper, gives a
watertight solid by marching cubes.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh

from arapp.scan import depth as dpt
from arapp.scan import fusion as fu
from arapp.scan.refine import refine_poses
from arapp.scan.views import ScanCancelled, View, look_at_point, select_views, track_views

Progress = Callable[[str, int, int], None]


@dataclass
class ScanOptions:
    """max_views: views used for depth; min_angle_deg: least angle between chosen views (seen from the
    object); refine: run the SIFT bundle adjustment; voxel: TSDF voxel (m; None = object extent / 90);
    z_margin: SGBM searches depths within the board's reach of the look-at point plus this (m);
    min_agree: depth maps that must confirm a depth; max_frames: frames read at most; keep_frames:
    candidate views kept in memory (longer recordings are subsampled evenly); use_depth: when frames
    carry depth (depth camera, recorded depth stream), use it instead of SGBM (False: match anyway);
    depth_views: views used with camera depth (at most max_views): each measured map covers all the
    object its view sees, so fewer are needed than SGBM pairs (and fusion time grows with their number);
    depth_stride: camera depth is subsampled to every n-th pixel (a 640-px-wide camera's 0.5 mm pixels at
    30 cm become 1 mm, about the voxel; an OAK-D's depth comes from a 640 x 400 pair anyway)."""

    max_views: int = 20
    min_angle_deg: float = 7.0
    refine: bool = True
    voxel: float | None = None
    z_margin: float = 0.05
    min_agree: int = 2
    max_frames: int | None = None
    keep_frames: int = 240
    use_depth: bool = True
    depth_views: int = 12
    depth_stride: int = 2


@dataclass
class ScanResult:
    mesh: trimesh.Trimesh
    views: list[View]
    poses: list[np.ndarray]
    frames_tracked: int
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def _check(cancel):
    if cancel is not None and cancel.is_set():
        raise ScanCancelled()


def scan(source, camera, anchors, options: ScanOptions | None = None, progress: Progress | None = None,
         cancel=None) -> ScanResult:
    """Reconstruct the object standing on the first anchor from the frames of `source`."""
    opt = options or ScanOptions()
    timings, stats = {}, {}
    t = time.perf_counter()
    views, chosen, use_depth = _choose_views(source, camera, anchors, opt, progress, cancel, stats)
    timings["track_s"] = time.perf_counter() - t
    K = camera.K.copy()
    t = time.perf_counter()
    poses = _refined_poses(chosen, K, anchors, opt, progress, cancel, stats)
    timings["refine_s"] = time.perf_counter() - t
    t = time.perf_counter()
    frame = fu.board_frame(anchors)
    maps = _depth_maps(chosen, poses, K, frame, use_depth, opt, progress, cancel)
    stats["depth_maps"] = len(maps)
    timings["depth_s"] = time.perf_counter() - t
    if len(maps) < 2:
        raise RuntimeError("the depth maps do not agree; is the object textured, and the board flat?")
    t = time.perf_counter()
    mesh = _fused_mesh(maps, frame, opt, progress, cancel, stats)
    timings["fuse_s"] = time.perf_counter() - t
    return ScanResult(mesh, chosen, poses, len(views), timings, stats)


def _choose_views(source, camera, anchors, opt: ScanOptions, progress, cancel, stats: dict):
    """Track every frame, then choose sharp views from different directions.

    Returns (views tracked, views chosen, whether the chosen views' measured depth is used).
    """
    # every frame is tracked, but only up to `keep_frames` evenly spread ones are kept in memory as candidates
    total = getattr(source, "frame_count", 0) or 0
    every = max(1, -(-total // opt.keep_frames)) if total else 1
    views = track_views(source, camera, anchors, progress, cancel, opt.max_frames, every=every)
    if len(views) < 3:
        raise RuntimeError(f"only {len(views)} frames were placed from the markers; keep the board in view "
                           "while circling the object")
    with_depth = [v for v in views if v.depth is not None]
    use_depth = opt.use_depth and len(with_depth) >= 3
    stats["depth_from"] = "camera" if use_depth else "stereo matching"
    chosen = select_views(with_depth if use_depth else views,
                          min(opt.max_views, opt.depth_views) if use_depth else opt.max_views, opt.min_angle_deg)
    if len(chosen) < 3:
        raise RuntimeError("fewer than 3 sharp views from different directions; circle the object more slowly")
    stats["views"] = len(chosen)
    return views, chosen, use_depth


def _refined_poses(chosen, K, anchors, opt: ScanOptions, progress, cancel, stats: dict) -> list[np.ndarray]:
    """The chosen views' poses (world_from_camera), bundle-adjusted on matched features when opt.refine."""
    poses = [v.pose for v in chosen]
    if not opt.refine:
        return poses
    _check(cancel)
    if progress:
        progress("refining poses", 0, 1)
    ref = refine_poses(chosen, K, anchors)
    stats.update(ba_rms_before_px=ref.rms_before, ba_rms_after_px=ref.rms_after, ba_tracks=ref.tracks,
                 ba_moved_mm=ref.moved_m * 1000, ba_turned_deg=ref.turned_deg)
    if progress:
        progress("refining poses", 1, 1)
    return ref.poses


def _depth_maps(chosen, poses, K, frame, use_depth: bool, opt: ScanOptions, progress, cancel) -> list:
    """Depth maps of the chosen views (measured, or by stereo matching of pairs), kept only where they
    see what stands on the board and (for matched maps) where enough maps agree; sparse maps dropped."""
    target = look_at_point(chosen)
    # depth search range: what lies within the board's reach of the look-at point (disparity range = time)
    reach = float(np.max(np.linalg.norm(frame.to_world(np.c_[frame.outline, np.zeros(len(frame.outline))])
                                        - target, axis=1))) + opt.z_margin

    def z_range(i):
        dist = float(np.linalg.norm(poses[i][:3, 3] - target))
        return max(0.02, dist - reach), dist + reach

    maps = []
    if use_depth:   # the camera measured depth: each view is its own depth map
        for i, v in enumerate(chosen):
            _check(cancel)
            maps.append(dpt.sensor_depth(v.depth, v.image, K, poses[i], z_range(i), i, stride=opt.depth_stride))
            if progress:
                progress("depth maps", i + 1, len(chosen))
    else:
        pairs = dpt.choose_pairs(poses, target)
        for k, (i, j) in enumerate(pairs):
            _check(cancel)
            dm = dpt.stereo_depth(chosen[i].image, chosen[j].image, K, poses[i], poses[j], z_range(i), i)
            if dm is not None:
                maps.append(dm)
            if progress:
                progress("dense matching", k + 1, len(pairs))
    if len(maps) < 2:
        raise RuntimeError("no pair of views could be matched densely; circle the object at one height too")
    # only what stands on the board matters: the rest is not checked (saves time) and not kept
    def on_board(X):
        L = frame.to_local(X)
        return frame.on_board(L, 0.01) & (L[:, 2] > -0.01)

    _check(cancel)
    if use_depth:
        # the camera's left-right check and sensor_depth's edge and speckle filters stand in for the
        # cross-check, which on dense measured maps would cost more than all the rest of this step.
        # Only what stands on the board is kept.
        for dm in maps:
            X, flat = dm.points()
            dm.depth.ravel()[flat[~on_board(X)]] = 0
    else:
        dpt.filter_consistent(maps, min_agree=opt.min_agree, keep=on_board)
    return [m for m in maps if np.count_nonzero(m.depth) > 500]


def _fused_mesh(maps, frame, opt: ScanOptions, progress, cancel, stats: dict) -> trimesh.Trimesh:
    """Fuse the depth maps in a voxel grid around the object on the board and take its surface (metres)."""
    points = np.concatenate([m.points()[0] for m in maps])
    region = fu.object_region(points, frame)
    if region is None:
        raise RuntimeError("nothing stands on the board; put the object on the printed board and scan again")
    lo, hi = region
    extent = float(np.max(hi - lo))
    voxel = opt.voxel or float(np.clip(extent / 90.0, 0.0003, 0.005))
    trunc = max(3.0 * voxel, 0.002)
    masks = fu.object_masks(maps, frame, lo, hi)
    _check(cancel)
    field_, lo2, voxel = fu.fuse(maps, frame, lo, hi, voxel, trunc, masks,
                                 hull_slack=max(2, len(maps) // 8), progress=progress)
    _check(cancel)
    mesh = fu.surface_from_field(field_, lo2, voxel, frame)
    stats.update(voxel_mm=voxel * 1000, faces=len(mesh.faces), watertight=bool(mesh.is_watertight))
    return mesh


def print_frame(anchors) -> np.ndarray:
    """4x4 from the world frame (m) to the print frame (mm): up along +z, the paper at z = 0."""
    fr = fu.board_frame(anchors)
    T = np.eye(4)
    T[:3, :3] = fr.R.T * 1000.0
    T[:3, 3] = -fr.R.T @ fr.origin * 1000.0
    return T


def write_mesh(mesh: trimesh.Trimesh, path: str | Path, transform: np.ndarray | None = None) -> Path:
    """Write `mesh` (optionally transformed) to path (.ply, .stl, .obj) through a temporary file in the same
    folder renamed into place, so an interrupted write never leaves a partial file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".stl", ".obj"):
        raise ValueError(f"{path}: unsupported mesh type {suffix or '(none)'}; use .ply, .stl or .obj")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path.parent}: folder does not exist; create it or choose another -o")
    m = mesh.copy()
    if transform is not None:
        m.apply_transform(transform)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{suffix}")
    try:
        m.export(tmp, file_type=suffix[1:])
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
