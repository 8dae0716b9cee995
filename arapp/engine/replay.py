"""Headless replay of a recording through the pipeline, writing what docs/recording-format.md lists.

Outputs in `out_dir`: poses.tum, tracking.csv, overlay.mp4 (unless no_video),
report.json and trajectory.png. Every per-frame line is flushed as it is
made, so an interrupted replay leaves consistent partial files and its report
says `"interrupted": true`.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from arapp.engine.input_source import open_input
from arapp.engine.pipeline import Pipeline, load_display_model
from arapp.engine.scene_run import SceneRun
from arapp.geometry.placement import Placement
from arapp.engine.toolpath_overlay import toolpath_overlay
from tracking.evaluation import evaluate
from tracking.poses import read_tum, tum_line


@dataclass
class ReplayOptions:
    model: str | None = None
    placement: dict | None = None  # some of size_mm, offset, rotation_deg; the rest stays the model's
    mode: str = "shaded"
    video: bool = True
    slam: bool = True
    max_frames: int | None = None
    printer: str | None = None
    toolpaths: str | None = None
    layer: int | None = None
    tracker_params: dict = field(default_factory=dict)
    calibration: str | None = None  # calibration file for a plain video (default: the estimated camera)
    anchors: str | None = None  # anchors JSON (default: a recording's own, else the recorder's default)
    occlusion: str | None = None  # "off", "depth", "plane"; None: depth when the recording has depth, else off
    scene: str | None = None  # scene file to start from (arapp.exchange.scene): its map, and its model if none given
    save_scene: str | None = None  # scene file to write at the end (the map as the run left it)


def replay(recording: str | Path, out_dir: str | Path, options: ReplayOptions | None = None,
           progress: Callable[[int, int], None] | None = None, cancel=None,
           say: Callable[[str], None] | None = None) -> dict:
    """Run the pipeline over every frame of `recording` (a recording folder or a plain video, opened by
    arapp.engine.input_source.open_input); return the report dict (also written to report.json).

    progress(done, total) is called after each frame; `cancel` is an optional
    threading.Event that stops the replay early (outputs stay consistent); say(line) is given each
    note on how the input was opened (the estimated camera, the default anchor).
    """
    options = options or ReplayOptions()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    source, camera, pipeline, scene_run = _set_up(recording, options, say)
    total = source.frame_count or 0  # 0: a video whose container gives no frame count
    if options.max_frames is not None:
        total = min(total, options.max_frames) if total else options.max_frames
    run = _Run()
    video = _LazyVideo(out / "overlay.mp4", source, camera.width, camera.height) if options.video else None
    t_start = time.perf_counter()
    with open(out / "poses.tum", "w") as poses_f, open(out / "tracking.csv", "w") as csv_f:
        poses_f.write("# t tx ty tz qx qy qz qw\n")
        csv_f.write("frame,t,state,markers,inliers,ms\n")
        try:
            _run_frames(source, pipeline, scene_run, options, (poses_f, csv_f, video), run, progress, cancel, total)
        except KeyboardInterrupt:
            run.interrupted = True
        finally:
            if video is not None:
                video.release()
            saved = _save_scene(scene_run, pipeline, options, say) if scene_run is not None else None
            pipeline.close()
            error = getattr(source, "error", None)
            source.close()
    wall = time.perf_counter() - t_start
    report = _report(recording, out, run.n, run.states, wall, run.interrupted, error,
                     run.times[-1] if run.times else None)
    if scene_run is not None:
        report["scene"] = {**scene_run.summary(), **(saved or {})}
        for line in scene_run.notes if say is not None else ():
            say(line)
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


@dataclass
class _Run:
    """What the frame loop saw: frames processed, their times and tracking states, whether it was stopped."""

    n: int = 0
    times: list = field(default_factory=list)
    states: list = field(default_factory=list)
    interrupted: bool = False


class _LazyVideo:
    """The overlay video, opened on the first frame written (no file when no frame comes), at the source's
    frame rate then."""

    def __init__(self, path: Path, source, width: int, height: int):
        self.path, self.source, self.size = path, source, (width, height)
        self.writer = None

    def write(self, image) -> None:
        if self.writer is None:
            self.writer = _open_writer(self.path, self.source.fps, *self.size)
        self.writer.write(image)

    def release(self) -> None:
        if self.writer is not None:
            self.writer.release()


def _set_up(recording, options: ReplayOptions, say):
    """(source, camera, pipeline, scene run or None): the input opened, the pipeline built with the
    options' model, placement, scene and toolpaths; everything opened is closed again on failure."""
    model = load_display_model(options.model) if options.model else None
    opened = open_input(recording, calibration=options.calibration, anchors=options.anchors)
    source, camera, anchors = opened.source, opened.camera, opened.anchors
    if options.occlusion == "depth" and not getattr(source, "has_depth", False):
        source.close()
        raise ValueError(f"--occlusion depth: {recording} has no depth stream (docs/recording-format.md, Depth); "
                         "use --occlusion plane (the anchor's plane) or off")
    for line in opened.notes if say is not None else ():
        say(line)
    # the options' placement dict becomes the model's Placement here, once
    placement = Placement.from_any(options.placement, model.placement) if model is not None else None
    pipeline = Pipeline(camera, anchors, model=model, placement=placement, mode=options.mode,
                        slam=options.slam, draw=options.video, tracker_params=options.tracker_params,
                        occlusion=options.occlusion)
    scene_run = None
    if options.scene or options.save_scene:
        try:
            scene_run = _start_scene(pipeline, camera, anchors, options, say)
        except BaseException:
            pipeline.close()
            source.close()
            raise
    if options.toolpaths:
        line_sets, world_from_bed = toolpath_overlay(options.toolpaths, options.printer, anchors, options.layer)
        pipeline.set_toolpaths(line_sets, world_from_bed)
    return source, camera, pipeline, scene_run


def _run_frames(source, pipeline: Pipeline, scene_run, options: ReplayOptions, outputs, run: _Run,
                progress, cancel, total: int) -> None:
    """Process the source's frames into outputs = (poses.tum file, tracking.csv file, video or None),
    counting in `run`, until the end, `options.max_frames` or `cancel`."""
    poses_f, csv_f, video = outputs
    for frame in source:
        if options.max_frames is not None and run.n >= options.max_frames:
            break
        if cancel is not None and cancel.is_set():
            run.interrupted = True
            break
        res = pipeline.process(frame.image, frame.t, frame.index, depth=getattr(frame, "depth", None))
        if scene_run is not None:
            scene_run.observe(frame.image, frame.t, res.world_from_camera, res.state)
        if res.world_from_camera is not None:
            poses_f.write(tum_line(frame.t, res.world_from_camera))
            poses_f.flush()
        csv_f.write(f"{frame.index},{frame.t:.6f},{res.state},{res.markers},{res.inliers},{res.ms_track:.3f}\n")
        csv_f.flush()
        if video is not None:
            video.write(res.image)
        run.times.append(frame.t)
        run.states.append(res.state)
        run.n += 1
        # faster than real time: let mapping take the time a live frame interval gives it
        pipeline.tracker.catch_up()
        if progress is not None:
            progress(run.n, total)


def _start_scene(pipeline: Pipeline, camera, anchors, options: ReplayOptions, say):
    """The run's SceneRun: `options.scene` loaded into the tracker (SceneError when unusable), and its first
    model shown when the replay names none."""
    run = SceneRun.start(pipeline.tracker, camera, [a.to_dict() for a in anchors], load=options.scene)
    if options.scene and say is not None:
        s = run.summary()
        say(f"scene {options.scene}: {s['loaded_keyframes']} keyframes, {s['loaded_points']} map points")
    if options.scene and options.model is None and run.models:
        entry = run.models[0]
        model = load_display_model(entry["path"])
        pipeline.set_model(model, Placement.from_any(entry.get("placement") or None, model.placement))
        options.model, options.placement = entry["path"], entry.get("placement") or None
    return run


def _save_scene(run, pipeline: Pipeline, options: ReplayOptions, say) -> dict | None:
    """Write `options.save_scene` (the map as the run left it, the model and placement shown)."""
    if not options.save_scene:
        return None
    # the placement shown (the model file's, with the options' or the scene's keys over it)
    shown = pipeline.model.placement if pipeline.model is not None else None
    models = ([{"path": str(options.model), "placement": asdict(shown) if shown is not None else {}}]
              if options.model else [])
    path = run.save(options.save_scene, models)
    m = pipeline.tracker.map
    if say is not None:
        say(f"saved scene {path}: {len(m.keyframes)} keyframes, {len(m.points)} map points, "
            f"{path.stat().st_size / 1e6:.2f} MB")
    return {"saved": str(path), "saved_keyframes": len(m.keyframes), "saved_points": len(m.points),
            "saved_bytes": path.stat().st_size}


def _open_writer(path: Path, fps: float, width: int, height: int):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (width, height))
    if not writer.isOpened():
        raise RuntimeError(f"cannot write {path}: OpenCV has no MPEG-4 encoder here; use --no-video")
    return writer


def _report(recording, out: Path, n: int, states: list[str], wall: float, interrupted: bool, error,
            last_t: float | None) -> dict:
    tracked = sum(s != "lost" for s in states)
    report = {
        "recording": str(recording),
        "frames": n,
        "tracked_fraction": tracked / n if n else 0.0,
        "fps": n / wall if wall > 0 else 0.0,
        "states": {s: states.count(s) for s in ("marker", "slam", "lost")},
        "interrupted": interrupted,
    }
    if error:
        report["source_error"] = str(error)
    gt_path = Path(recording) / "groundtruth.tum"
    est_path = out / "poses.tum"
    if gt_path.is_file():
        gt_t, gt_p = read_tum(gt_path)
        est_t, est_p = read_tum(est_path)
        if last_t is not None:  # a partial replay is judged on the frames it covered
            keep = gt_t <= last_t + 1e-6
            gt_t, gt_p = gt_t[keep], gt_p[keep]
        if len(gt_t) and len(est_t):
            m = evaluate(est_t, est_p, gt_t, gt_p).to_dict()
            for key in ("ate_rmse_m", "ate_max_m", "rpe_trans_m_per_s", "rpe_rot_deg_per_s", "jitter_m",
                        "extent_m"):
                value = m.get(key)
                report[key] = None if value is None or not np.isfinite(value) else float(value)
        _plot(out / "trajectory.png", gt_t, gt_p, est_t, est_p)
    else:
        est_t, est_p = read_tum(est_path)
        _plot(out / "trajectory.png", None, None, est_t, est_p)
    return report


def _plot(path: Path, gt_t, gt_p, est_t, est_p) -> None:
    """Top view and height-over-time of the camera trajectory, estimate against ground truth."""
    # here, not at the top: matplotlib is slow to import and only the plot needs it; the backend must be
    # chosen before pyplot is imported
    import matplotlib  # heavy and only for this plot: loaded when a plot is asked for

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    if gt_p is not None and len(gt_p):
        ax1.plot(gt_p[:, 0, 3], gt_p[:, 1, 3], "k-", lw=1, label="ground truth")
        ax2.plot(gt_t, gt_p[:, 2, 3], "k-", lw=1, label="ground truth")
    if len(est_p):
        ax1.plot(est_p[:, 0, 3], est_p[:, 1, 3], "r.", ms=2, label="arapp")
        ax2.plot(est_t, est_p[:, 2, 3], "r.", ms=2, label="arapp")
    ax1.set_xlabel("x (m)")
    ax1.set_ylabel("y (m)")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.set_title("camera position, top view (world frame)")
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("z (m)")
    ax2.set_title("camera height over the anchor")
    for ax in (ax1, ax2):
        if ax.get_legend_handles_labels()[1]:  # a replay that tracked nothing and has no truth plots no line
            ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def terminal_progress(stream=sys.stderr) -> Callable[[int, int], None]:
    """A progress callback drawing `[#####.....] 42/120 frames  12.3 fps` on one terminal line."""
    start = time.perf_counter()
    tty = hasattr(stream, "isatty") and stream.isatty()
    shown = [-1]

    def show(done: int, total: int) -> None:
        if not tty:  # a log file gets a line every 10 %, not a carriage-return storm
            step = int(10 * done / total) if total else done // 100  # no frame count: every 100 frames
            if step == shown[0] and (done < total or not total):
                return
            shown[0] = step
        width = 30
        frac = done / total if total else 0.0
        bar = "#" * int(width * frac) + "." * (width - int(width * frac))
        fps = done / max(time.perf_counter() - start, 1e-9)
        lead = "\r" if tty else ""
        stream.write(f"{lead}[{bar}] {done}/{total or '?'} frames  {fps:5.1f} fps")
        if (total and done >= total) or not tty:
            stream.write("\n")
        stream.flush()

    return show
