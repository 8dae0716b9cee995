"""`arapp printer`: printer profile tasks (the bed anchor)."""

from tracking.anchors.defaults import DEFAULT_DICTIONARY

HELP = "printer profile tasks: enter the bed anchor (where the marker lies on the bed)"


def add_arguments(parser):
    sub = parser.add_subparsers(dest="printer_command", metavar="TASK", required=True)
    p = sub.add_parser("bed-anchor", help="save where the bed marker lies, measured or touched with the nozzle",
                       description="Save the bed anchor in a printer profile. Either give the marker centre "
                       "(--center X Y, --rotation DEG) or the bed X/Y read (M114) with the nozzle on the "
                       "marker's bottom-left and bottom-right corners (--touched X1 Y1 X2 Y2).")
    p.add_argument("--printer", required=True, help="printer profile JSON to update (must exist unless --create)")
    p.add_argument("--create", action="store_true",
                   help="create the profile from the generic printer when the file does not exist")
    p.add_argument("--dictionary", default=DEFAULT_DICTIONARY,
                   help=f"ArUco dictionary of the bed marker (default {DEFAULT_DICTIONARY}, as `arapp markers` prints)")
    p.add_argument("--id", type=int, default=42, help="marker id")
    p.add_argument("--length", type=float, default=0.04, help="marker side in metres")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument("--center", nargs=2, type=float, metavar=("X", "Y"), help="marker centre on the bed, mm")
    how.add_argument("--touched", nargs=4, type=float, metavar=("X1", "Y1", "X2", "Y2"),
                     help="nozzle X/Y on the bottom-left, then the bottom-right marker corner, mm")
    p.add_argument("--rotation", type=float, default=0.0, help="with --center: marker turn about z, degrees")


def run(args):
    import math
    from pathlib import Path

    from arapp.printing.bed_anchor import bed_from_anchor_measured, bed_from_anchor_touched, save_bed_anchor
    from arapp.printing.profile import ProfileError, load_profile

    path = Path(args.printer)
    if path.suffix.lower() != ".json":
        raise ProfileError(f"--printer {path}: give the profile's JSON file (name.json)")
    if path.exists():
        profile = load_profile(path)  # a broken profile is reported (file and key) before anything is written
    elif args.create:
        if not path.parent.is_dir():
            raise ProfileError(f"--printer {path}: folder {path.parent} does not exist")
        profile = load_profile(None)
    else:
        raise ProfileError(f"--printer {path}: no such printer profile; check the path, or add --create to start "
                           "one from the generic printer")
    if not (0 < args.length <= 1.0) or not math.isfinite(args.length):
        raise ValueError(f"--length must be above 0 and at most 1 (metres, the marker side), got {args.length!r}")
    numbers = list(args.touched or []) + list(args.center or []) + [args.rotation]
    if not all(math.isfinite(x) for x in numbers):
        raise ValueError("--center, --touched and --rotation must be finite numbers (mm, degrees)")
    if args.touched:
        T = bed_from_anchor_touched(args.touched[:2], args.touched[2:], args.length)
    else:
        T = bed_from_anchor_measured(args.center, args.rotation)
    x, y = float(T[0, 3]), float(T[1, 3])
    if not (0 <= x <= profile.bed.width and 0 <= y <= profile.bed.depth):
        raise ValueError(f"the marker centre would be at bed ({x:.1f}, {y:.1f}) mm, off the "
                         f"{profile.bed.width:g} x {profile.bed.depth:g} mm bed of {path}; check the coordinates")
    anchor = {"kind": "aruco", "dictionary": args.dictionary, "id": args.id, "length": args.length}
    path = save_bed_anchor(path, anchor, T)
    print(f"printer: bed anchor saved in {path}: marker centre at bed ({T[0, 3]:.1f}, {T[1, 3]:.1f}) mm, "
          f"turned {math.degrees(math.atan2(T[1, 0], T[0, 0])):.1f} deg")
    return 0
