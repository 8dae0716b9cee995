"""`arapp printer`: printer profile tasks (the bed anchor)."""

HELP = "printer profile tasks: enter the bed anchor (where the marker lies on the bed)"


def add_arguments(parser):
    sub = parser.add_subparsers(dest="printer_command", metavar="TASK", required=True)
    p = sub.add_parser("bed-anchor", help="save where the bed marker lies, measured or touched with the nozzle",
                       description="Save the bed anchor in a printer profile. Either give the marker centre "
                       "(--center X Y, --rotation DEG) or the bed X/Y read (M114) with the nozzle on the "
                       "marker's bottom-left and bottom-right corners (--touched X1 Y1 X2 Y2).")
    p.add_argument("--printer", required=True, help="printer profile JSON to update (created if missing)")
    p.add_argument("--dictionary", default="DICT_4X4_50", help="ArUco dictionary of the bed marker")
    p.add_argument("--id", type=int, default=42, help="marker id")
    p.add_argument("--length", type=float, default=0.04, help="marker side in metres")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument("--center", nargs=2, type=float, metavar=("X", "Y"), help="marker centre on the bed, mm")
    how.add_argument("--touched", nargs=4, type=float, metavar=("X1", "Y1", "X2", "Y2"),
                     help="nozzle X/Y on the bottom-left, then the bottom-right marker corner, mm")
    p.add_argument("--rotation", type=float, default=0.0, help="with --center: marker turn about z, degrees")


def run(args):
    import math

    from arapp.printing.bed_anchor import bed_from_anchor_measured, bed_from_anchor_touched, save_bed_anchor

    if args.touched:
        T = bed_from_anchor_touched(args.touched[:2], args.touched[2:], args.length)
    else:
        T = bed_from_anchor_measured(args.center, args.rotation)
    anchor = {"kind": "aruco", "dictionary": args.dictionary, "id": args.id, "length": args.length}
    path = save_bed_anchor(args.printer, anchor, T)
    print(f"printer: bed anchor saved in {path}: marker centre at bed ({T[0, 3]:.1f}, {T[1, 3]:.1f}) mm, "
          f"turned {math.degrees(math.atan2(T[1, 0], T[0, 0])):.1f} deg")
    return 0
