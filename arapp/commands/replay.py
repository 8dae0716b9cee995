"""`arapp replay`: run the tracking pipeline headless on a recording and write its outputs."""

import sys
import warnings
from pathlib import Path

# the anchor list of what a replay that tracked nothing found in the video, written into its output folder
FOUND_ANCHORS = "anchors-found.json"
HELP = "replay a recording or a video through tracking and rendering; write poses, CSV, overlay video, report"


def add_arguments(parser):
    parser.add_argument("recording", help="recording folder (session.json + video) or a plain video (mp4, avi, mov, "
                        "webm, mkv)")
    parser.add_argument("--calibration", help="calibration file for a plain video (OpenCV FileStorage YAML/XML/JSON "
                        "or ROS camera_info YAML); default: the estimated camera (said when used)")
    parser.add_argument("--anchors", help="JSON file with the anchors to track (a list as in session.json); default: "
                        "a recording's own, else one aruco DICT_ARUCO_MIP_36h12 id 0 of 0.06 m (what `arapp markers "
                        "aruco` prints)")
    parser.add_argument("--out", help="output folder (created; an existing one has its outputs replaced); default "
                        "out/replay-NAME in the current folder, NAME the recording's or video's name")
    parser.add_argument("--no-video", action="store_true", help="skip overlay.mp4 (faster)")
    parser.add_argument("--model", help="model to draw on the anchor (NURBS JSON or STL/OBJ/PLY/3MF/GLB, or a library "
                        "model's name: vase)")
    parser.add_argument("--size", type=float, help="model size on the anchor in mm (default: the model's own)")
    parser.add_argument("--mode", default="shaded", choices=["shaded", "wireframe", "isolines", "translucent"],
                        help="display mode of the model")
    parser.add_argument("--occlusion", choices=["off", "depth", "plane"],
                        help="hide the model behind real things: depth (the recording's depth stream), plane (the "
                        "anchor's plane: parts below the table top), off; default: depth when the recording has "
                        "depth, else off (docs/occlusion.md)")
    parser.add_argument("--no-slam", action="store_true", help="markers only, no keypoint tracking")
    parser.add_argument("--marker-every", type=int, default=4,
                        help="detect markers every N frames once keypoints carry the pose (1: every frame, "
                        "most accurate, slowest; default 4)")
    parser.add_argument("--frames", type=int, help="stop after this many frames")
    parser.add_argument("--printer", help="printer profile JSON (for --toolpaths)")
    parser.add_argument("--toolpaths", help="G-code whose toolpaths are drawn on the printer bed")
    parser.add_argument("--layer", type=int, help="with --toolpaths: highlight this layer, dim those below")
    parser.add_argument("--scene", metavar="S.arscene", help="start from this saved scene: relocalise against its "
                        "map (the model shows where it was left, even with the marker removed) and show its model "
                        "unless --model is given (docs/scene-format.md)")
    parser.add_argument("--save-scene", metavar="S.arscene", help="save the scene at the end: the map (extended, "
                        "when --scene was loaded), anchors, model and placement; may be the --scene file")


def check_args(args) -> None:
    """Refuse counts no replay can use, naming the flag, before anything is read or written."""
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be 1 or more (frames to replay), got {args.frames}")
    if not 1 <= args.marker_every <= 1000:
        raise ValueError(f"--marker-every must be 1 to 1000 (frames), got {args.marker_every}")
    if args.layer is not None and args.layer < 0:
        raise ValueError(f"--layer must be 0 or more (layers count from 0), got {args.layer}")


def default_out(recording: str) -> str:
    """The output folder of a replay given no --out: out/replay-NAME, NAME the recording folder's or the
    video's name without its extension (`arapp demo` writes to out/demo the same way)."""
    path = Path(recording)
    name = (path.name if path.is_dir() else path.stem) or "recording"
    return str(Path("out") / f"replay-{name}")


def run(args):
    from tracking.sources import SourceWarning

    # a source's warning is said once, with the summary (report["source_error"]), not again by each opening
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SourceWarning)
        return _run(args)


def _run(args):
    from arapp.exchange.staging import staged_folder
    from arapp.geometry.placement import check_size_mm
    from arapp.engine.replay import ReplayOptions, replay, terminal_progress

    check_args(args)
    if (args.scene or args.save_scene) and args.no_slam:
        raise ValueError("--scene and --save-scene need the keypoint map: drop --no-slam")
    if args.save_scene and not args.save_scene.endswith(".arscene"):
        raise ValueError(f"--save-scene {args.save_scene}: scene files end in .arscene")
    if args.size is not None:
        check_size_mm(args.size, "--size")
    placement = None
    if args.size is not None:
        placement = {"size_mm": args.size}
    opts = ReplayOptions(model=args.model, placement=placement, mode=args.mode, video=not args.no_video,
                         slam=not args.no_slam, max_frames=args.frames, printer=args.printer,
                         toolpaths=args.toolpaths, layer=args.layer,
                         tracker_params={"marker_every": args.marker_every} if not args.no_slam else {},
                         calibration=args.calibration, anchors=args.anchors, occlusion=args.occlusion,
                         scene=args.scene, save_scene=args.save_scene)
    chosen = args.out is not None
    if not chosen:
        args.out = default_out(args.recording)
    # Written to a temporary folder moved into place at the end: a failure leaves no (empty) --out behind.
    with staged_folder(args.out) as tmp:
        report = replay(args.recording, tmp, opts, progress=terminal_progress(sys.stderr),  # stderr as now
                        say=lambda line: print(f"replay: {line}", flush=True))
    keys = ["frames", "tracked_fraction", "fps", "ate_rmse_m", "ate_max_m", "rpe_trans_m_per_s", "rpe_rot_deg_per_s"]
    summary = ", ".join(f"{k} {report[k]:.4g}" for k in keys if isinstance(report.get(k), (int, float)))
    print(f"replay: {summary}")
    print(f"replay: wrote {args.out}/poses.tum, tracking.csv, report.json, trajectory.png"
          + ("" if args.no_video else ", overlay.mp4") + ("" if chosen else " (--out to choose the folder)"))
    if report.get("source_error"):
        print(f"replay: warning: {report['source_error']}")
    say_why_untracked(args, report)
    return 130 if report.get("interrupted") else 0


def say_why_untracked(args, report) -> None:
    """A replay that tracked nothing says why, and what the video shows instead (arapp/engine/untracked.py):
    an anchor found in it is written to FOUND_ANCHORS in the output folder, for the next run's --anchors."""
    if not report.get("frames") or report.get("tracked_fraction"):
        return
    from arapp.engine.untracked import untracked_lines_for  # discovery's detectors: only for a replay that needs them

    found = Path(args.out) / FOUND_ANCHORS
    for line in untracked_lines_for(args.recording, args.calibration, args.anchors, found_file=found):
        print(f"replay: {line}")
