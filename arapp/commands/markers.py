"""`arapp markers`: printable anchor sheets (PNG + PDF at true scale) with their session `anchors` block."""

from tracking.anchors.defaults import DEFAULT_DICTIONARY

HELP = "write printable ArUco markers, GridBoards, ChArUco boards or QR codes (PDF + PNG, true scale) and their anchors JSON"

__all__ = ["HELP", "DEFAULT_DICTIONARY", "add_arguments", "run"]


def _printable_kinds() -> dict:
    """`arapp markers KIND` name -> the registered AnchorKind that prints it."""
    # imported here, not at the top: the kinds import OpenCV, and cli.py builds every command's parser
    # for `arapp --help`, which stays fast
    from tracking.anchors.kinds import KINDS

    return {k.cli_name: k for k in KINDS.values() if k.cli_name}


class _PrintableKindNames:
    """argparse `choices` read from the kinds table when first needed (`arapp markers` runs or shows help)."""

    def __contains__(self, name) -> bool:
        return name in _printable_kinds()

    def __iter__(self):
        return iter(_printable_kinds())


def add_arguments(parser):
    parser.add_argument("kind", choices=_PrintableKindNames(), metavar="KIND",
                        help="what to print: aruco, board, charuco, qr (or another registered anchor kind)")
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
    from tracking.recording.schema import parse_anchor

    kind = _printable_kinds()[args.kind]
    block = kind.cli_block(args)
    spec = parse_anchor(block, "anchor")
    paths = write_sheet(spec, args.output, args.name or kind.file_stem(spec), args.dpi, args.page)
    for p in paths:
        print(f"wrote {p}")
    print("anchors block for session.json:")
    print(json.dumps({"anchors": [spec.to_dict()]}, indent=2))
    return 0
