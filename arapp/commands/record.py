"""`arapp record`: record a source into a recording folder (arapp-recording/1)."""

HELP = "record a camera or video into a recording folder (video, frames.csv, session.json, depth/ from depth cameras)"


def add_arguments(parser):
    parser.add_argument("--source", required=True, help="v4l2:0, v4l2:/dev/video2, depthai[:<id>], or a video file")
    parser.add_argument("--out", required=True, help="recording folder to create, e.g. recordings/my_desk")
    parser.add_argument("--calibration", help="OpenCV calibration YAML (needed for V4L2 cameras and video files)")
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
    from pathlib import Path

    from tracking.recorder import record
    from tracking.session import read_anchor_blocks
    from tracking.sources import open_source

    from arapp.exchange.staging import staged_folder

    for flag, value in (("--seconds", args.seconds), ("--fps", args.fps)):
        if value is not None and not 0 < value <= 86400:
            raise ValueError(f"{flag} must be above 0 (and at most 86400), got {value}")
    for flag, value in (("--width", args.width), ("--height", args.height)):
        if value is not None and not 0 < value <= 16384:
            raise ValueError(f"{flag} must be 1 to 16384 pixels, got {value}")
    anchors = read_anchor_blocks(args.anchors) if args.anchors else None
    out = Path(args.out)
    if out.exists() and any(out.iterdir()) and not args.force:
        raise FileExistsError(f"{out}: already holds files (a recording?); use --force to overwrite it")
    with open_source(args.source, calibration=args.calibration, width=args.width, height=args.height,
                     fps=args.fps) as src:
        src.camera  # noqa: B018 - fail before creating files if the source has no calibration
        # Recorded into a temporary folder that replaces --out at the end: a failure leaves nothing behind.
        with staged_folder(out, replace=True) as tmp:
            session = record(src, tmp, anchors=anchors, seconds=args.seconds, force=True, fourcc=args.codec,
                             depth=not args.no_depth)
    n_depth = len(list((out / "depth").glob("*.png"))) if (out / "depth").is_dir() else 0
    depth = f", depth for {n_depth} frames (depth/, 16-bit PNG, mm)" if n_depth else ""
    print(f"{out}: {session.video}, {session.camera.width}x{session.camera.height} @ {session.fps:.1f} fps{depth}")
    return 0
