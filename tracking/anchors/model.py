"""Geometry of the anchors of a session: where every detectable corner lies.

Each anchor has its own plane frame (z = 0 on the paper, see
docs/recording-format.md) and a `world_from_anchor` transform. Lengths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracking.anchors.kinds import AnchorKind, square_corners
from tracking.anchors.kinds.aruco_board import grid_board
from tracking.anchors.kinds.charuco import charuco_board
from tracking.anchors.kinds.qr import normal_text
from tracking.errors import SessionError
from tracking.poses import transform_points
from tracking.anchors.kinds import AnchorSpec

# square_corners, grid_board and charuco_board live with their kinds (tracking/anchors/kinds); named here too
__all__ = ["AnchorModel", "build_models", "square_corners", "grid_board", "charuco_board"]


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
    def anchor_kind(self) -> AnchorKind:
        """The registered kind (tracking/anchors/kinds): detector family, drawing, words."""
        return self.spec.anchor_kind

    @property
    def world_from_anchor(self) -> np.ndarray:
        return np.asarray(self.spec.world_from_anchor, dtype=float)

    def to_world(self, pts: np.ndarray) -> np.ndarray:
        return transform_points(self.world_from_anchor, pts)

    def outline(self) -> np.ndarray:
        """(K,3) anchor-frame points spanning the anchor (for regions of interest)."""
        return self.anchor_kind.outline(self.spec, self.markers, self.chess)


def build_models(anchors: list[AnchorSpec]) -> list[AnchorModel]:
    """Anchor models for a session; raises SessionError when two anchors share a dictionary id or QR text."""
    models = []
    owner: dict[tuple[str, int], int] = {}
    texts: dict[str, int] = {}
    for i, a in enumerate(anchors):
        m = AnchorModel(i, a)
        m.markers, m.chess, m.board = a.anchor_kind.geometry(a)
        if a.anchor_kind.detector == "qr":  # a QR anchor is told apart by its text (line ends normalised)
            key = normal_text(a.text)
            if key in texts:
                raise SessionError(f"anchors[{i}] and anchors[{texts[key]}] are QR codes with the same text "
                                   f"{a.text!r} (line ends and surrounding spaces aside); every anchor must be "
                                   f"unique in view")
            texts[key] = i
        for mid in m.markers:
            key = (a.dictionary, mid)
            if key in owner:
                raise SessionError(
                    f"anchors[{i}] and anchors[{owner[key]}] both use marker id {mid} of {a.dictionary}; "
                    f"every marker must belong to one anchor (change id or first_id)")
            owner[key] = i
        models.append(m)
    return models
