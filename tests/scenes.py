"""Synthetic scenes (tracking.synth) used by the SLAM tests and benchmark, and a runner that
tracks a rendered sequence and scores it against its ground truth.

Scenes are desk planes with one ArUco marker; trajectories are given in desk
coordinates around the marker (metres, seconds).
"""

from __future__ import annotations

import time

import numpy as np

from tracking.evaluation import TrajectoryMetrics, evaluate


def scene_dict(name: str, keys: list[dict], fps: float = 30.0, width: int = 640, height: int = 480,
               noise: float = 1.5, occluder: dict | None = None, seed: int = 5, marker_length: float = 0.08,
               supersample: int = 1, dist: list[float] | None = None, desk_style: str = "desk") -> dict:
    """A synth scene JSON with a `keyframes` trajectory (keys: t, eye, target)."""
    duration = float(keys[-1]["t"])
    effects = {"noise": noise}
    if occluder:
        effects["occluder"] = occluder
    cam = {"width": width, "height": height, "hfov_deg": 62}
    if dist is not None:
        cam["dist"] = dist
    return {
        "name": name, "seed": seed, "fps": fps, "duration": duration, "camera": cam,
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": marker_length}],
        "desk": {"size": [1.6, 1.2], "ppm": 1500, "seed": seed, "style": desk_style},
        "trajectory": {"kind": "keyframes", "keys": keys},
        "effects": effects, "supersample": supersample,
    }


def rolling_shutter_pixels(camera, world, pose_at, t: float, iterations: int = 30):
    """Pixels (N,2) of world points (N,3) under a rolling shutter: each seen at the time of the row it lands
    on (row y exposed at t + camera.readout * ((y + 0.5) / height - 0.5)), by fixed-point iteration;
    `pose_at(t)` gives world_from_camera at any time t (seconds)."""
    import numpy as np

    world = np.asarray(world, float).reshape(-1, 3)
    px = camera.project_world(world, pose_at(t))
    for _ in range(iterations):
        d = camera.readout * ((px[:, 1] + 0.5) / camera.height - 0.5)
        px = np.array([camera.project_world(world[i:i + 1], pose_at(t + d[i]))[0] for i in range(len(world))])
    return px


# A 5x3 GridBoard of 32 mm DICT_4X4_50 markers (ids 0-14), 8 mm apart: the kind of board fast pans are tracked on.
BOARD_5X3 = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 5, "markers_y": 3,
             "marker_length": 0.032, "separation": 0.008, "first_id": 0}


def board_scene_dict(name: str, keys: list[dict], seed: int, **effects) -> dict:
    """scene_dict with the 5x3 board (BOARD_5X3) as the anchor, sensor noise 1.0 and `effects` added
    (e.g. motion_blur=0.6, blur_samples=7)."""
    sj = scene_dict(name, keys, noise=1.0, seed=seed)
    sj["anchors"] = [dict(BOARD_5X3)]
    sj["effects"].update(effects)
    return sj


def away_and_back_keys(away_s: float = 5.0, height: float = 0.42) -> list[dict]:
    """Look at the marker while moving (parallax for the map), pan away so the marker leaves the
    view for `away_s` seconds, wander there, come back."""
    h = height
    keys = [
        {"t": 0.0, "eye": [-0.12, -0.30, h], "target": [0.0, 0.0, 0.0]},
        {"t": 1.5, "eye": [0.10, -0.28, h], "target": [0.02, 0.0, 0.0]},
        {"t": 2.5, "eye": [0.16, -0.25, h], "target": [0.22, 0.05, 0.0]},
        {"t": 3.0, "eye": [0.22, -0.24, h], "target": [0.42, 0.08, 0.0]},
    ]
    t = 3.0
    wander = [([0.28, -0.20, h], [0.46, 0.12, 0.0]), ([0.22, -0.26, h - 0.03], [0.40, 0.04, 0.0])]
    step = away_s / (len(wander) + 1)
    for eye, target in wander:
        t += step
        keys.append({"t": round(t, 3), "eye": eye, "target": target})
    t += step
    keys.append({"t": round(t, 3), "eye": [0.2, -0.25, h], "target": [0.38, 0.06, 0.0]})
    keys.append({"t": round(t + 1.0, 3), "eye": [0.08, -0.28, h], "target": [0.05, 0.0, 0.0]})
    keys.append({"t": round(t + 2.0, 3), "eye": [-0.05, -0.30, h], "target": [0.0, 0.0, 0.0]})
    return keys


def render_sequence(scene_json: dict, frames: slice | None = None):
    """Rendered frames as a list of (t, BGR image, true world_from_camera), and the scene."""
    from tracking.synth.held import make_renderer
    from tracking.synth.scene import parse_scene

    scene = parse_scene(scene_json)
    r = make_renderer(scene)
    idx = range(scene.frame_count)
    if frames is not None:
        idx = idx[frames]
    out = []
    for i in idx:
        img, pose, t = r.render(i)
        out.append((t, img, pose))
    return out, scene


def run_tracker(tracker, frames, pace: str = "offline") -> dict:
    """Track frames [(t, image, true pose)]; returns times, poses (None when lost), states, ms, metrics.

    pace: "offline" as fast as possible, with `tracker.catch_up()` between frames (mapping keeps the
    pace it would have live, whatever the machine's load); "live" frames handed in at the recording's
    own rate, as a camera would (no catch-up); "flat-out" as fast as possible without catch-up (the
    mapping thread gets only what time is left over: a worst case).
    """
    if pace not in ("offline", "live", "flat-out"):
        raise ValueError(f"pace must be 'offline', 'live' or 'flat-out', not {pace!r}")
    times, poses, states, ms, inl = [], [], [], [], []
    start = time.perf_counter()
    for t, img, _ in frames:
        if pace == "live":
            wait = start + (t - frames[0][0]) - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        t0 = time.perf_counter()
        res = tracker.process(img, t)
        ms.append((time.perf_counter() - t0) * 1000.0)
        if pace == "offline":
            tracker.catch_up()
        times.append(t)
        poses.append(res.world_from_camera)
        states.append(res.state)
        inl.append(res.inliers)
    gt_t = np.array([f[0] for f in frames])
    gt = np.array([f[2] for f in frames])
    ok = np.array([p is not None for p in poses])
    est = np.array([p for p in poses if p is not None]).reshape(-1, 4, 4)
    metrics: TrajectoryMetrics = evaluate(gt_t[ok], est, gt_t, gt)
    err = np.full(len(frames), np.nan)
    if ok.any():
        err[ok] = np.linalg.norm(est[:, :3, 3] - gt[ok][:, :3, 3], axis=1)
    return {"times": gt_t, "poses": poses, "states": states, "ms": np.array(ms), "inliers": np.array(inl),
            "metrics": metrics, "errors": err, "ok": ok}


def load_recording(folder, frames: slice | None = None):
    """Frames [(t, BGR image, true world_from_camera)] of a recording folder with groundtruth.tum,
    and its Session (read through tracking.sources.RecordingSource, so times follow the contract)."""
    from pathlib import Path

    from tracking.errors import SourceError
    from tracking.poses import read_tum
    from tracking.sources import RecordingSource

    folder = Path(folder)
    gt_path = folder / "groundtruth.tum"
    if not gt_path.is_file():
        raise SourceError(f"{folder}: no groundtruth.tum; scoring needs the true poses")
    gt_t, gt = read_tum(gt_path)
    out = []
    with RecordingSource(folder) as source:
        session = source.session
        wanted = set(range(source.frame_count)[frames]) if frames is not None else None
        for frame in source:
            if wanted is not None and frame.index > max(wanted, default=-1):
                break
            if wanted is None or frame.index in wanted:
                j = int(np.argmin(np.abs(gt_t - frame.t)))
                out.append((float(frame.t), frame.image, gt[j]))
    return out, session


def bundled_recording(name: str, frames: slice | None = None):
    """`load_recording` of recordings/NAME in this repository or, for a preset the repository does not bundle,
    of the preset rendered into the recordings cache on first use (tracking.synth.cache: once per run, under a
    lock shared by the xdist workers); fails the test (not skips) when neither exists."""
    import pytest

    from tracking.synth.cache import bundled_folder, cached_recording
    from tracking.synth.presets import EXTRA_TUNING, HELD, PRESETS

    folder = bundled_folder(name)
    if folder is None:
        if name not in PRESETS and name not in EXTRA_TUNING and name not in HELD:
            pytest.fail(f"recordings/{name} with groundtruth.tum is part of the repository and must exist")
        folder = cached_recording(name)
    return load_recording(folder, frames)


# a hand's skin as BGR (0-255), for fingers painted over markers
SKIN_BGR = np.array([120.0, 150.0, 205.0])


def marker_side(quad, side: int):
    """The side `side` (corners side, side+1) of a marker's image quad (4,2 pixels): (its middle (2,), the unit
    vector out of the marker across it, the unit vector along it toward corner side+1, its length in
    pixels, a cell's length: a sixth of it, the cell count across a 4x4 ArUco marker with its border)."""
    quad = np.asarray(quad, float)
    a, b = quad[side], quad[(side + 1) % 4]
    mid = (a + b) / 2
    out = mid - quad.mean(axis=0)
    out /= np.linalg.norm(out)
    length = float(np.linalg.norm(b - a))
    return mid, out, (b - a) / length, length, length / 6


def held_recording_folder(name: str):
    """The folder of the held-card recording `name` (tracking.synth.presets.HELD), rendered on first use into
    the recordings cache (tracking.synth.cache: .cache/recordings/, git-ignored) under a name holding a hash of
    its scene and of the renderer, so a changed preset renders anew; parallel workers render it once."""
    from tracking.synth.cache import cached_recording

    return cached_recording(name)


def held_recording(name: str, frames: slice | None = None):
    """`load_recording` of the held-card recording `name` (rendered and cached by `held_recording_folder`)."""
    return load_recording(held_recording_folder(name), frames)


def plain_clip(source_video, path, frames: int, fps: float = 30.0):
    """The first `frames` frames of `source_video` written to `path` as a plain MP4 (no session.json beside it:
    what a user has), returned."""
    import cv2

    cap = cv2.VideoCapture(str(source_video))
    writer = None
    for _ in range(frames):
        ok, f = cap.read()
        assert ok, f"{source_video}: fewer than {frames} frames"
        if writer is None:
            writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (f.shape[1], f.shape[0]))
        writer.write(f)
    writer.release()
    cap.release()
    return path
