"""Anchor kinds as plug-ins: one module per kind, one table.

`KINDS` maps the session.json `kind` string to an `AnchorKind` (base.py): its
fields and checks, geometry, detector family, drawing and words. session.py,
the detector, the renderer, printable sheets, placement, diagnosis and the
user guidance all dispatch through it. A new kind is one module beside these,
imported below, and one `register(...)` line (docs/architecture.md shows one);
a kind defined elsewhere calls `register` itself before its sessions are read.
"""

from tracking.anchors.defaults import DEFAULT_DICTIONARY
from tracking.anchors.kinds.aruco import ArucoKind
from tracking.anchors.kinds.aruco_board import ArucoBoardKind
from tracking.anchors.kinds.base import AnchorKind, square_corners
from tracking.anchors.kinds.charuco import CharucoKind
from tracking.anchors.kinds.qr import QRKind
from tracking.anchors.kinds.registry import KINDS, kind_named, kind_names, register
from tracking.anchors.kinds.spec import AnchorSpec

register(ArucoKind())
register(ArucoBoardKind())
register(CharucoKind())
register(QRKind())

__all__ = ["AnchorKind", "AnchorSpec", "KINDS", "DEFAULT_DICTIONARY", "register", "kind_named", "kind_names",
           "square_corners"]
