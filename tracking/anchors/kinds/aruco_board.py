"""`aruco_board`: an OpenCV GridBoard of ArUco markers; OpenCV's board frame (origin at the first
marker's outer corner, x right, y down, z into the paper)."""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary
from tracking.anchors.kinds.base import AnchorKind, mm
from tracking.poses import make_pose


def grid_board(spec) -> cv2.aruco.GridBoard:
    """The OpenCV GridBoard of an `aruco_board` anchor (ids first_id ...)."""
    d = aruco_dictionary(spec.dictionary)
    ids = np.arange(spec.first_id, spec.first_id + spec.markers_x * spec.markers_y, dtype=np.int32)
    return cv2.aruco.GridBoard((spec.markers_x, spec.markers_y), spec.marker_length, spec.separation, d, ids)


def board_markers(board) -> dict[int, np.ndarray]:
    """ArUco id -> (4,3) corners of an OpenCV board, in its frame."""
    return {int(mid): np.asarray(c, dtype=float).reshape(4, 3) for mid, c in zip(board.getIds().ravel(),
                                                                                  board.getObjPoints())}


class ArucoBoardKind(AnchorKind):
    """markers_x x markers_y markers of side marker_length, `separation` apart, ids first_id, first_id+1, ..."""

    name = "aruco_board"
    required = {"dictionary": str, "markers_x": int, "markers_y": int, "marker_length": float, "separation": float}
    written = ("first_id",)
    positive = ("marker_length",)
    counts = ("markers_x", "markers_y")
    non_negative = ("separation",)
    face = -1.0
    size_fields = "marker_length / square_length"
    layout_fields = "marker_length and separation"
    cli_name = "board"

    def marker_ids(self, spec):
        return list(range(spec.first_id, spec.first_id + spec.markers_x * spec.markers_y))

    def geometry(self, spec):
        board = grid_board(spec)
        return board_markers(board), None, board

    def size(self, spec) -> tuple[float, float]:
        """(width, height) of the marker grid, metres."""
        w = spec.markers_x * spec.marker_length + (spec.markers_x - 1) * spec.separation
        h = spec.markers_y * spec.marker_length + (spec.markers_y - 1) * spec.separation
        return w, h

    def anchor_from_placement(self, spec):
        w, h = self.size(spec)
        return make_pose(np.diag([1.0, -1.0, -1.0]), [w / 2, h / 2, 0.0])

    def extent(self, spec):
        extent = max(spec.markers_x, spec.markers_y) * (spec.marker_length + spec.separation) - spec.separation
        return spec.marker_length, extent

    def describe(self, spec):
        last = spec.first_id + spec.markers_x * spec.markers_y - 1
        return (f"ArUco board {spec.markers_x} x {spec.markers_y}, {spec.dictionary}, ids {spec.first_id}-{last}, "
                f"{mm(spec.marker_length)} markers")

    def caption(self, spec):
        return (f"GridBoard {spec.markers_x}x{spec.markers_y} {spec.dictionary} ids {spec.first_id}.."
                f"{spec.first_id + spec.markers_x * spec.markers_y - 1}, markers {mm(spec.marker_length)}, "
                f"gaps {mm(spec.separation)}")

    def summary(self, spec):
        ids, _ = super().summary(spec)
        return ids, (f"{spec.markers_x}x{spec.markers_y} x {mm(spec.marker_length)}, "
                     f"gap {mm(spec.separation)}")

    def file_stem(self, spec):
        return f"board_{spec.dictionary}_{spec.markers_x}x{spec.markers_y}_{spec.marker_length * 1000:g}mm"

    def cli_block(self, args):
        ml = args.marker_length if args.marker_length is not None else 0.04
        return {"kind": "aruco_board", "dictionary": args.dictionary, "markers_x": args.markers_x,
                "markers_y": args.markers_y, "marker_length": ml, "separation": args.separation,
                "first_id": args.first_id}
