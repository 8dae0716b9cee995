"""`arapp record`: record a source into a recording folder (arapp-recording/1)."""

HELP = "record a camera or video into a recording folder (video, frames.csv, session.json, depth/ from depth cameras)"


def add_arguments(parser):
    parser.add_argument("--source", required=True, help="v4l2:0, v4l2:/dev/video2, depthai[:<id>], or a video file")
    parser.add_argument("--out", required=True, help="recording folder to create, e.g. recordings/my_desk")
    parser.add_argument("--calibration", help="calibration file for a V4L2 camera or a video file (OpenCV FileStorage "
                        "or ROS camera_info YAML); default: one the GUI's wizard stored, else the estimated camera "
                        "(said, and noted in session.json)")
    parser.add_argument("--anchors", help="JSON file with the anchors list (as in session.json); "
                        "default: the source recording's anchors, else one aruco DICT_ARUCO_MIP_36h12 id 0 of 0.06 m (what `arapp markers aruco` prints)")
    parser.add_argument("--seconds", type=float, help="stop after this many seconds (default: until Ctrl-C or the end)")
    parser.add_argument("--width", type=int, help="requested camera width")
    parser.add_argument("--height", type=int, help="requested camera height")
    parser.add_argument("--fps", type=float, help="requested camera frame rate")
    parser.add_argument("--codec", default="MJPG", choices=["MJPG", "FFV1"],
                        help="MJPG (.avi, intra-frame) or FFV1 (.mkv, lossless)")
    parser.add_argument("--no-depth", action="store_true",
                        help="leave out the depth stream a depth camera (OAK-D) or recording gives "
                             "(default: recorded as depth/, 16-bit PNG in millimetres)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing recording")


def run(args):
    import warnings
    from pathlib import Path

    from tracking.recording.writer import record
    from tracking.sources import SourceWarning

    from arapp.exchange.staging import staged_folder
    from arapp.engine.input_source import describe_anchors, open_input

    for flag, value in (("--seconds", args.seconds), ("--fps", args.fps)):
        if value is not None and not 0 < value <= 86400:
            raise ValueError(f"{flag} must be above 0 (and at most 86400), got {value}")
    for flag, value in (("--width", args.width), ("--height", args.height)):
        if value is not None and not 0 < value <= 16384:
            raise ValueError(f"{flag} must be 1 to 16384 pixels, got {value}")
    out = Path(args.out)
    if out.exists() and any(out.iterdir()) and not args.force:
        raise FileExistsError(f"{out}: already holds files (a recording?); use --force to overwrite it")
    # the camera and anchors are settled (and a bad file refused) before any file is created
    with open_input(args.source, calibration=args.calibration, anchors=args.anchors, width=args.width,
                    height=args.height, fps=args.fps, default_anchor_note=False) as opened:
        for line in opened.notes:
            print(f"record: {line}", flush=True)
        # Recorded into a temporary folder that replaces --out at the end: a failure leaves nothing behind. A
        # source's warning is said once, by record() at the end.
        with staged_folder(out, replace=True) as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore", SourceWarning)
            session = record(opened.source, tmp, anchors=opened.anchor_blocks, seconds=args.seconds, force=True,
                             fourcc=args.codec, depth=not args.no_depth, name=out)
    n_depth = len(list((out / "depth").glob("*.png"))) if (out / "depth").is_dir() else 0
    depth = f", depth for {n_depth} frames (depth/, 16-bit PNG, mm)" if n_depth else ""
    print(f"{out}: {session.video}, {session.camera.width}x{session.camera.height} @ {session.fps:.1f} fps{depth}")
    if opened.default_anchors:
        print(f"record: no --anchors: wrote the default anchor into {out / 'session.json'}: "
              f"{describe_anchors(session.anchors)} (what `arapp markers aruco` prints); if the video shows "
              "another, edit its anchors there or record again with --anchors anchors.json")
    say_why_untracked(out, opened.default_anchors)
    return 0


def say_why_untracked(folder, default_anchors: bool) -> None:
    """A recording in which its anchors give no pose says why, and what it shows instead (arapp/engine/untracked.py)."""
    from tracking.recording.schema import load_session

    from arapp.engine.untracked import untracked_lines  # discovery's detectors: only loaded after a recording

    session = load_session(folder)
    for line in untracked_lines(session.video_path, session.anchors, default_anchors, camera=session.camera):
        print(f"record: {line}")
