"""`arapp calibrate`: camera intrinsics from views of a ChArUco board or a chessboard."""

HELP = "calibrate a camera from ChArUco or chessboard views (a source or a folder of images) into camera.yaml"


def add_arguments(parser):
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--source", help="camera or video to read views from (v4l2:0, depthai, a video file, a recording)")
    src.add_argument("--images", help="folder of still images of the board (png, jpg, bmp, tif)")
    parser.add_argument("--anchors", help="anchors JSON whose charuco anchor is the board (what `arapp markers charuco` "
                        "writes next to the sheet); replaces --board, --squares-*, --*-length and --dictionary")
    parser.add_argument("--calibration", help="a calibration to start from (OpenCV FileStorage or ROS camera_info YAML); "
                        "the distortion terms the views cannot determine keep its values")
    parser.add_argument("--board", choices=["charuco", "chessboard"], default="charuco", help="board kind (default charuco)")
    parser.add_argument("--squares-x", type=int, default=7, help="squares along x (default 7)")
    parser.add_argument("--squares-y", type=int, default=5, help="squares along y (default 5)")
    parser.add_argument("--square-length", type=float, default=0.03, help="square side in metres (default 0.03)")
    parser.add_argument("--marker-length", type=float, default=0.022, help="ChArUco marker side in metres (default 0.022)")
    parser.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco dictionary (default DICT_5X5_100)")
    parser.add_argument("--max-views", type=int, default=40, help="stop collecting after this many kept views (default 40)")
    parser.add_argument("--min-views", type=int, default=8, help="fewest views to solve with (default 8)")
    parser.add_argument("--min-sharpness", type=float, default=30.0,
                        help="Laplacian-variance floor; blurrier views are rejected (default 30)")
    parser.add_argument("--every", type=int, default=5, help="with --source, look at every Nth frame (default 5)")
    parser.add_argument("-o", "--output", required=True, help="calibration YAML to write (OpenCV FileStorage)")


def check_args(args) -> None:
    """Refuse numbers no board or solve can use, naming the flag (before any camera is opened)."""
    from tracking.calibration import MIN_VIEWS
    from tracking.errors import CalibrationError

    def need(ok: bool, flag: str, rule: str, value) -> None:
        if not ok:
            raise CalibrationError(f"{flag} must be {rule}, got {value!r}")

    need(2 <= args.squares_x <= 100, "--squares-x", "2 to 100", args.squares_x)
    need(2 <= args.squares_y <= 100, "--squares-y", "2 to 100", args.squares_y)
    need(0 < args.square_length <= 1.0, "--square-length", "above 0 and at most 1 (metres)", args.square_length)
    if args.board == "charuco":
        need(0 < args.marker_length < args.square_length, "--marker-length",
             f"above 0 and below --square-length ({args.square_length:g} m)", args.marker_length)
    need(MIN_VIEWS <= args.min_views <= 1000, "--min-views", f"{MIN_VIEWS} to 1000 (views of the board)", args.min_views)
    need(args.min_views <= args.max_views <= 1000, "--max-views", f"--min-views ({args.min_views}) to 1000",
         args.max_views)
    need(0 <= args.min_sharpness < 1e6, "--min-sharpness", "0 or more", args.min_sharpness)
    need(1 <= args.every <= 10000, "--every", "1 to 10000 (frames)", args.every)


def run(args) -> int:
    from tracking.calibration import ViewCollector, solve

    check_args(args)
    board = _board(args)
    if args.calibration:
        from tracking.calibration_file import read_calibration_file

        read_calibration_file(args.calibration)  # a bad file is refused before any view is looked at
    col = ViewCollector(board, min_sharpness=args.min_sharpness)
    names = []

    def consider(image, name):
        verdict = col.add(image, name)
        if verdict == "kept":
            names.append(name)
        print(f"{name}: {verdict} ({len(col.views)} kept, coverage {col.coverage * 100:.0f} %)")

    if args.images:
        _views_from_images(args, col, consider)
    else:
        _views_from_source(args, col, consider)
    print("rejected: " + ", ".join(f"{n} {why}" for why, n in col.rejected.items()))
    guess = _guess(args, col) if args.calibration and col.views else None
    res = solve(col.views, col.width, col.height, col.coverage, min_views=args.min_views, guess=guess)
    print(res.report(names))
    if col.coverage < 0.5:
        print(f"warning: the board covered only {col.coverage * 100:.0f} % of the image; views near the edges and "
              "corners give better distortion estimates")
    _write(res, args.output)
    print(f"wrote {args.output}")
    return 0


def _board(args):
    """The calibration target: the first anchor of --anchors, else the board the options describe."""
    from tracking.calibration import BoardSpec

    if args.anchors:
        from tracking.recording.schema import parse_anchors, read_anchor_blocks

        specs = parse_anchors(read_anchor_blocks(args.anchors), where=f"{args.anchors}: anchors")
        board = BoardSpec.from_anchor(specs[0], f"{args.anchors}: anchors[0]")
        print(f"board from {args.anchors}: {specs[0].anchor_kind.describe(specs[0])}")
        return board
    return BoardSpec(args.board, args.squares_x, args.squares_y, args.square_length,
                     args.marker_length if args.board == "charuco" else None, args.dictionary)


def _views_from_images(args, col, consider) -> None:
    """Offer the images of the --images folder, in name order, until --max-views are kept."""
    from pathlib import Path

    import cv2

    from tracking.errors import CalibrationError

    folder = Path(args.images)
    if not folder.is_dir():
        raise CalibrationError(f"--images {folder}: not a folder")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"))
    if not files:
        raise CalibrationError(f"--images {folder}: no png/jpg/bmp/tif images in it")
    for p in files:
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            print(f"{p.name}: unreadable, skipped")
            continue
        consider(img, p.name)
        if len(col.views) >= args.max_views:
            break


def _views_from_source(args, col, consider) -> None:
    """Offer every --every-th frame of --source until --max-views are kept."""
    from tracking.sources import open_source

    with open_source(args.source) as source:
        for frame in source:
            if frame.index % max(args.every, 1):
                continue
            consider(frame.image, f"frame {frame.index}")
            if len(col.views) >= args.max_views:
                break


def _guess(args, col):
    """The --calibration file's camera fitted to the views' size: the solver's starting point."""
    from tracking.camera import Camera
    from tracking.sources.base import _fit_camera

    cam, notes = Camera.load_file(args.calibration, (col.width, col.height))
    for line in notes:
        print(line)
    return _fit_camera(cam, col.width, col.height, args.calibration, "the views")


def _write(res, output: str) -> None:
    """Save the calibration to `output` through a temporary file: never half written under its name."""
    from pathlib import Path

    out = Path(output)
    tmp = out.with_name(f".{out.name}.tmp{out.suffix}")  # OpenCV picks the format by suffix: keep it
    out.parent.mkdir(parents=True, exist_ok=True)
    res.camera.save_yaml(tmp, {"rms_px": res.rms, "views": len(res.used)})
    tmp.replace(out)
