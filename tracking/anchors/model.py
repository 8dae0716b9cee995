"""Geometry of the anchors of a session: where every detectable corner lies.

Each anchor has its own plane frame (z = 0 on the paper, see
docs/recording-format.md) and a `world_from_anchor` transform. Lengths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary
from tracking.errors import SessionError
from tracking.poses import transform_points
from tracking.session import AnchorSpec


def square_corners(length: float) -> np.ndarray:
    """(4,3) corners of a square of side `length` centred at the origin, OpenCV order TL, TR, BR, BL, y up."""
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def grid_board(spec: AnchorSpec) -> cv2.aruco.GridBoard:
    """The OpenCV GridBoard of an `aruco_board` anchor (ids first_id ...)."""
    d = aruco_dictionary(spec.dictionary)
    ids = np.arange(spec.first_id, spec.first_id + spec.markers_x * spec.markers_y, dtype=np.int32)
    return cv2.aruco.GridBoard((spec.markers_x, spec.markers_y), spec.marker_length, spec.separation, d, ids)


def charuco_board(spec: AnchorSpec) -> cv2.aruco.CharucoBoard:
    """The OpenCV CharucoBoard of a `charuco` anchor (ids first_id ...)."""
    if spec.marker_length >= spec.square_length:
        raise SessionError(
            f"charuco anchor: marker_length {spec.marker_length} must be smaller than square_length "
            f"{spec.square_length}")
    d = aruco_dictionary(spec.dictionary)
    n = (spec.squares_x * spec.squares_y) // 2
    ids = np.arange(spec.first_id, spec.first_id + n, dtype=np.int32)
    return cv2.aruco.CharucoBoard((spec.squares_x, spec.squares_y), spec.square_length, spec.marker_length, d, ids)


@dataclass
class AnchorModel:
    """One anchor's detectable points in its own frame and in the world.

    `markers`: ArUco id -> (4,3) corners in the anchor frame (OpenCV corner order).
    `chess`: for ChArUco, (M,3) chessboard corners in the anchor frame (index = charuco id).
    `world_from_anchor`: 4x4.
    """

    index: int
    spec: AnchorSpec
    markers: dict[int, np.ndarray] = field(default_factory=dict)
    chess: np.ndarray | None = None
    board: object = None

    @property
    def kind(self) -> str:
        return self.spec.kind

    @property
    def world_from_anchor(self) -> np.ndarray:
        return np.asarray(self.spec.world_from_anchor, dtype=float)

    def to_world(self, pts: np.ndarray) -> np.ndarray:
        return transform_points(self.world_from_anchor, pts)

    def outline(self) -> np.ndarray:
        """(K,3) anchor-frame points spanning the anchor (for regions of interest)."""
        if self.kind == "qr":
            return square_corners(self.spec.length)
        pts = [c for c in self.markers.values()]
        if self.chess is not None:
            pts.append(self.chess)
        return np.concatenate(pts, axis=0)


def build_models(anchors: list[AnchorSpec]) -> list[AnchorModel]:
    """Anchor models for a session; raises SessionError when two anchors share a dictionary id or QR text."""
    models = []
    owner: dict[tuple[str, int], int] = {}
    texts: dict[str, int] = {}
    for i, a in enumerate(anchors):
        m = AnchorModel(i, a)
        if a.kind == "aruco":
            m.markers[int(a.id)] = square_corners(a.length)
        elif a.kind == "aruco_board":
            b = grid_board(a)
            m.board = b
            for mid, c in zip(b.getIds().ravel(), b.getObjPoints()):
                m.markers[int(mid)] = np.asarray(c, dtype=float).reshape(4, 3)
        elif a.kind == "charuco":
            b = charuco_board(a)
            m.board = b
            for mid, c in zip(b.getIds().ravel(), b.getObjPoints()):
                m.markers[int(mid)] = np.asarray(c, dtype=float).reshape(4, 3)
            m.chess = np.asarray(b.getChessboardCorners(), dtype=float).reshape(-1, 3)
        elif a.kind == "qr":
            if a.text in texts:
                raise SessionError(f"anchors[{i}] and anchors[{texts[a.text]}] are QR codes with the same text "
                                   f"{a.text!r}; every anchor must be unique in view")
            texts[a.text] = i
        for mid in m.markers:
            key = (a.dictionary, mid)
            if key in owner:
                raise SessionError(
                    f"anchors[{i}] and anchors[{owner[key]}] both use marker id {mid} of {a.dictionary}; "
                    f"every marker must belong to one anchor (change id or first_id)")
            owner[key] = i
        models.append(m)
    return models
