"""`arapp scan`: reconstruct an object standing on the marker board as a watertight mesh (and a NURBS model)."""

from __future__ import annotations

import importlib.util
import signal
import sys
import threading
import time
from pathlib import Path

HELP = "reconstruct an object standing on the marker board from a recording or a camera (scan to print)"

EXTRA_MESSAGE = ("arapp scan needs the optional scan engines (scikit-image); install them with "
                 "`.venv/bin/pip install -e '.[scan]'` (make test does)")


def add_arguments(parser):
    parser.add_argument("recording", nargs="?", help="recording folder (arapp-recording/1) or plain video (mp4, avi, "
                        "mov, webm, mkv) circling the object")
    parser.add_argument("--source", help="scan live from a camera instead: v4l2:0, depthai, a video file ...")
    parser.add_argument("--calibration", help="calibration file for a video or a V4L2 camera (OpenCV FileStorage or "
                        "ROS camera_info YAML); default: the estimated camera (said when used)")
    parser.add_argument("--anchors", help="JSON file with the anchors list (as in session.json); default: a "
                        "recording's own, else one aruco DICT_ARUCO_MIP_36h12 id 0 of 0.06 m (what `arapp markers aruco` prints)")
    parser.add_argument("--seconds", type=float, default=None, help="with a live --source (required there): capture "
                        "for S seconds while circling the object; with a video: stop after S seconds of it")
    parser.add_argument("-o", "--output", required=True, help="mesh to write: .ply, .stl or .obj")
    parser.add_argument("--print", dest="print_mm", action="store_true",
                        help="write millimetres in the print frame (up = +z, the paper at z = 0) instead of "
                             "metres in the recording's world frame")
    parser.add_argument("--nurbs", metavar="MODEL.json", help="also fit an editable NURBS model (surface of "
                        "revolution, else a bicubic patch) and write it as an arapp model JSON")
    parser.add_argument("--max-views", type=int, default=20, help="views used for dense matching (default 20)")
    parser.add_argument("--voxel-mm", type=float, default=None, help="TSDF voxel, mm (default: object size / 90)")
    parser.add_argument("--no-refine", action="store_true", help="skip the SIFT bundle adjustment")
    parser.add_argument("--max-frames", type=int, default=None, help="use at most N frames of the recording")


def _progress():
    state = {"stage": None, "t": 0.0}
    tty = sys.stderr.isatty()

    def show(stage, done, total):
        now = time.monotonic()
        last = total and done >= total
        if stage == state["stage"] and not last and now - state["t"] < (0.1 if tty else 2.0):
            return
        if stage != state["stage"] and state["stage"] is not None and tty:
            print(file=sys.stderr)
        state["stage"], state["t"] = stage, now
        text = f"scan: {stage} {done}/{total}" if total else f"scan: {stage} {done}"
        if tty:
            print("\r" + text, end="\n" if last else "", file=sys.stderr, flush=True)
        else:
            print(text, file=sys.stderr, flush=True)

    return show


class _TimedSource:
    """Frames of a source for `seconds` seconds: of the clock for a live camera, of the frames' own
    timestamps for a recording or video."""

    def __init__(self, src, seconds):
        self.src, self.seconds = src, seconds
        self.frame_count = 0

    def __iter__(self):
        t0 = time.monotonic()
        live = getattr(self.src, "live", False)
        for f in self.src:
            if self.seconds is not None and (time.monotonic() - t0 if live else f.t) > self.seconds:
                break
            yield f


def run(args) -> int:
    if importlib.util.find_spec("skimage") is None:
        print(EXTRA_MESSAGE, file=sys.stderr)
        return 3
    from arapp.scan.pipeline import ScanOptions, print_frame, scan, write_mesh
    from arapp.scan.views import ScanCancelled

    out = Path(args.output)
    if out.suffix.lower() not in (".ply", ".stl", ".obj"):
        raise ValueError(f"-o {out}: unsupported mesh type {out.suffix or '(none)'}; use .ply, .stl or .obj")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"-o {out}: folder {out.parent} does not exist; create it first")
    if args.nurbs and not Path(args.nurbs).parent.is_dir():
        raise FileNotFoundError(f"--nurbs {args.nurbs}: folder does not exist; create it first")
    if (args.recording is None) == (args.source is None):
        raise ValueError("give either a RECORDING folder or --source SPEC (not both)")
    if args.max_views < 3:
        raise ValueError(f"--max-views must be at least 3, got {args.max_views}")
    options = ScanOptions(max_views=args.max_views, refine=not args.no_refine,
                          voxel=args.voxel_mm / 1000.0 if args.voxel_mm else None, max_frames=args.max_frames)
    if args.seconds is not None and not 0 < args.seconds <= 86400:
        raise ValueError(f"--seconds must be above 0 (and at most 86400), got {args.seconds}")
    cancel = threading.Event()
    from arapp.engine.input_source import open_input

    opened = open_input(args.recording or args.source, calibration=args.calibration, anchors=args.anchors)
    if opened.source.live and args.seconds is None:
        opened.close()
        raise ValueError("--source needs --seconds S: how long to capture while circling the object")
    for line in opened.notes:
        print(f"scan: {line}", flush=True)
    # a recording or video ends by itself; --seconds cuts it (live: by the clock, files: by their time)
    source = opened.source if args.seconds is None else _TimedSource(opened.source, args.seconds)
    camera, anchors = opened.camera, opened.anchors
    # SIGTERM stops like Ctrl-C: nothing is written until the mesh is complete (temp file + rename)
    old = signal.signal(signal.SIGTERM, lambda *a: cancel.set())
    try:
        result = scan(source, camera, anchors, options, progress=_progress(), cancel=cancel)
    except ScanCancelled:
        print("arapp scan: cancelled; nothing written", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, old)
        (getattr(source, "src", source)).close()
    transform = print_frame(anchors) if args.print_mm else None
    write_mesh(result.mesh, out, transform)
    m = result.mesh
    ext = m.extents * 1000
    print(f"{out}: {len(m.faces)} triangles, watertight {m.is_watertight}, volume {m.volume * 1e6:.1f} cm^3, "
          f"extent {ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} mm "
          f"(file in {'millimetres, print frame' if args.print_mm else 'metres, world frame'}); "
          f"{len(result.views)} views of {result.frames_tracked} tracked frames")
    print("timings: " + ", ".join(f"{k} {v:.1f}" for k, v in result.timings.items()))
    if args.nurbs:
        from arapp.scan.nurbs_fit import fit_model, write_model

        fit = fit_model(result.mesh, anchors)
        write_model(fit, args.nurbs)
        print(f"{args.nurbs}: {fit.kind} fit, error rms {fit.rms_mm:.2f} mm, max {fit.max_mm:.2f} mm")
    return 0
