"""`charuco`: an OpenCV CharucoBoard (chessboard with ArUco markers in its white squares); OpenCV's
board frame (origin at the board's top-left outer corner, x right, y down, z into the paper).

`"legacy": true` names a board printed in the pattern of OpenCV before 4.6 (and of the tools that copied
it): with an even number of rows its chessboard starts with a white square where today's starts black, so
the markers sit in other squares and today's detector finds them but no corner."""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary
from tracking.anchors.kinds.aruco_board import board_markers
from tracking.anchors.kinds.base import AnchorKind, mm
from tracking.errors import SessionError
from tracking.poses import make_pose


def charuco_board(spec) -> cv2.aruco.CharucoBoard:
    """The OpenCV CharucoBoard of a `charuco` anchor (ids first_id ...)."""
    if spec.marker_length >= spec.square_length:
        raise SessionError(
            f"charuco anchor: marker_length {spec.marker_length} must be smaller than square_length "
            f"{spec.square_length}")
    d = aruco_dictionary(spec.dictionary)
    n = (spec.squares_x * spec.squares_y) // 2
    ids = np.arange(spec.first_id, spec.first_id + n, dtype=np.int32)
    board = cv2.aruco.CharucoBoard((spec.squares_x, spec.squares_y), spec.square_length, spec.marker_length, d, ids)
    board.setLegacyPattern(is_legacy(spec))
    return board


def is_legacy(spec) -> bool:
    """Whether a `charuco` anchor's board has the pattern of OpenCV before 4.6 (its "legacy" field)."""
    return bool(spec.params.get("legacy", False))


class CharucoKind(AnchorKind):
    """squares_x x squares_y squares of side square_length, markers of side marker_length, ids first_id ..."""

    name = "charuco"
    required = {"dictionary": str, "squares_x": int, "squares_y": int, "square_length": float,
                "marker_length": float}
    optional = {"first_id": int, "polarity": str, "legacy": bool}
    written = ("first_id",)
    positive = ("square_length", "marker_length")
    counts = ("squares_x", "squares_y")
    detector = "charuco"
    face = -1.0
    size_fields = "marker_length / square_length"
    layout_fields = "square_length and marker_length"
    cli_name = "charuco"

    def marker_ids(self, spec):
        return list(range(spec.first_id, spec.first_id + (spec.squares_x * spec.squares_y) // 2))

    def geometry(self, spec):
        board = charuco_board(spec)
        chess = np.asarray(board.getChessboardCorners(), dtype=float).reshape(-1, 3)
        return board_markers(board), chess, board

    def anchor_from_placement(self, spec):
        w, h = spec.squares_x * spec.square_length, spec.squares_y * spec.square_length
        return make_pose(np.diag([1.0, -1.0, -1.0]), [w / 2, h / 2, 0.0])

    def extent(self, spec):
        return spec.marker_length, max(spec.squares_x, spec.squares_y) * spec.square_length

    def layout(self, spec, markers, margin):
        patches, _, margin = super().layout(spec, markers, margin)
        # the black chessboard squares: those without a marker
        sq, black = spec.square_length, []
        centres = np.array([c[:, :2].mean(axis=0) for c in markers.values()])
        for j in range(spec.squares_y):
            for i in range(spec.squares_x):
                lo = np.array([i * sq, j * sq])
                inside = np.all((centres > lo) & (centres < lo + sq), axis=1)
                if not inside.any():
                    black.append(np.array([lo, lo + [sq, 0], lo + [sq, sq], lo + [0, sq]]))
        return patches, black, margin

    def describe(self, spec):
        return (f"ChArUco board {spec.squares_x} x {spec.squares_y}, {spec.dictionary}, "
                f"{mm(spec.square_length)} squares" + (", legacy pattern" if is_legacy(spec) else ""))

    def caption(self, spec):
        return (f"ChArUco {spec.squares_x}x{spec.squares_y} {spec.dictionary} first id {spec.first_id}, squares "
                f"{mm(spec.square_length)}, markers {mm(spec.marker_length)}")

    def summary(self, spec):
        ids, _ = super().summary(spec)
        return ids, (f"{spec.squares_x}x{spec.squares_y} x {mm(spec.square_length)}, "
                     f"markers {mm(spec.marker_length)}")

    def file_stem(self, spec):
        return f"charuco_{spec.dictionary}_{spec.squares_x}x{spec.squares_y}_{spec.square_length * 1000:g}mm"

    def cli_block(self, args):
        ml = args.marker_length if args.marker_length is not None else 0.022
        return {"kind": "charuco", "dictionary": args.dictionary, "squares_x": args.squares_x,
                "squares_y": args.squares_y, "square_length": args.square_length, "marker_length": ml,
                "first_id": args.first_id}
