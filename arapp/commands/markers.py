"""`arapp markers`: printable anchor sheets (PNG + PDF at true scale) with their session `anchors` block."""

HELP = "write printable ArUco markers, GridBoards, ChArUco boards or QR codes (PDF + PNG, true scale) and their anchors JSON"

# Markers of a dictionary whose codes are far apart (at least 12 of 36 bits differ, rotations included):
# printed patterns that are not markers (a 4x4 "fragile glass" icon on a parcel decodes as DICT_4X4_50 id
# 17) match one of its codes far less often than in the 4x4 dictionaries. See docs/markers.md.
DEFAULT_DICTIONARY = "DICT_ARUCO_MIP_36h12"


def add_arguments(parser):
    parser.add_argument("kind", choices=["aruco", "board", "charuco", "qr"], help="what to print")
    parser.add_argument("--dictionary", default=DEFAULT_DICTIONARY,
                        help=f"ArUco dictionary (default {DEFAULT_DICTIONARY}: 6x6 bits, codes at least 12 bits apart, "
                        "so packaging icons and other printed squares are not taken for markers as 4x4 ones are; "
                        "any DICT_* name works, and recordings keep the dictionary they state; see docs/markers.md)")
    parser.add_argument("--id", type=int, default=0, help="aruco: marker id (default 0)")
    parser.add_argument("--length", type=float, default=0.06,
                        help="aruco / qr: side in metres, black border / symbol without quiet zone (default 0.06)")
    parser.add_argument("--markers-x", type=int, default=4, help="board: markers along x (default 4)")
    parser.add_argument("--markers-y", type=int, default=3, help="board: markers along y (default 3)")
    parser.add_argument("--marker-length", type=float, default=None,
                        help="board / charuco: marker side in metres (default 0.04 board, 0.022 charuco)")
    parser.add_argument("--separation", type=float, default=0.01, help="board: gap between markers in metres (default 0.01)")
    parser.add_argument("--first-id", type=int, default=0, help="board / charuco: first marker id (default 0)")
    parser.add_argument("--squares-x", type=int, default=7, help="charuco: squares along x (default 7)")
    parser.add_argument("--squares-y", type=int, default=5, help="charuco: squares along y (default 5)")
    parser.add_argument("--square-length", type=float, default=0.03, help="charuco: square side in metres (default 0.03)")
    parser.add_argument("--text", default="arapp anchor 1", help="qr: the text to encode (default 'arapp anchor 1')")
    parser.add_argument("--dpi", type=float, default=300.0, help="resolution of the PNG and PDF (default 300)")
    parser.add_argument("--page", default="A4", help="A3, A4, A5, Letter or WIDTHxHEIGHT in mm (default A4)")
    parser.add_argument("--name", default=None, help="file name stem (default from the anchor)")
    parser.add_argument("-o", "--output", default=".", help="folder to write into (default .)")


def run(args) -> int:
    import json

    from tracking.printables import write_sheet
    from tracking.session import parse_anchor

    if args.kind == "aruco":
        block = {"kind": "aruco", "dictionary": args.dictionary, "id": args.id, "length": args.length}
        name = f"aruco_{args.dictionary}_id{args.id}_{args.length * 1000:g}mm"
    elif args.kind == "board":
        ml = args.marker_length if args.marker_length is not None else 0.04
        block = {"kind": "aruco_board", "dictionary": args.dictionary, "markers_x": args.markers_x,
                 "markers_y": args.markers_y, "marker_length": ml, "separation": args.separation,
                 "first_id": args.first_id}
        name = f"board_{args.dictionary}_{args.markers_x}x{args.markers_y}_{ml * 1000:g}mm"
    elif args.kind == "charuco":
        ml = args.marker_length if args.marker_length is not None else 0.022
        block = {"kind": "charuco", "dictionary": args.dictionary,
                 "squares_x": args.squares_x, "squares_y": args.squares_y, "square_length": args.square_length,
                 "marker_length": ml, "first_id": args.first_id}
        name = f"charuco_{block['dictionary']}_{args.squares_x}x{args.squares_y}_{args.square_length * 1000:g}mm"
    else:
        block = {"kind": "qr", "text": args.text, "length": args.length}
        safe = "".join(c if c.isalnum() else "_" for c in args.text)[:24]
        name = f"qr_{safe}_{args.length * 1000:g}mm"
    spec = parse_anchor(block, "anchor")
    paths = write_sheet(spec, args.output, args.name or name, args.dpi, args.page)
    for p in paths:
        print(f"wrote {p}")
    print("anchors block for session.json:")
    print(json.dumps({"anchors": [spec.to_dict()]}, indent=2))
    return 0
