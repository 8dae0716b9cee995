"""Where a model sits on the world anchor: size, offset and turn about the anchor's normal.

Frames:
- *model frame*: the model file's coordinates, in its stated units.
- *placement frame*: origin at the world anchor's centre, x right and y up as
  the anchor is printed, z out of the paper toward the viewer; metres. For an
  `aruco` or `qr` anchor this is the anchor frame itself; for an `aruco_board`
  (OpenCV's frame: origin at the first marker's outer corner, y down, z into
  the paper) it is the board centre with y and z flipped.
- *world frame*: the first anchor's frame (RECORDING_FORMAT.md).

A placed model stands on the paper: its lowest point (along the placement
normal) at z = 0, centred over the anchor centre (plus the offset), its
largest horizontal extent scaled to `size_mm`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracking.poses import make_pose
from tracking.session import AnchorSpec


@dataclass
class Placement:
    """Size of the model's largest horizontal extent (mm), offset from the anchor centre (mm, placement
    frame), rotation about the anchor normal (degrees, counter-clockwise seen from above)."""

    size_mm: float = 50.0
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_deg: float = 0.0
    extra: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if not (np.isfinite(self.size_mm) and self.size_mm > 0):
            raise ValueError(f"placement size must be a positive number of millimetres, got {self.size_mm}")
        self.offset_mm = tuple(float(x) for x in self.offset_mm)
        if len(self.offset_mm) != 3:
            raise ValueError("placement offset must have three components (x, y, z) in millimetres")

    @classmethod
    def from_any(cls, value) -> "Placement":
        """From a Placement, a dict with size_mm/offset_mm/rotation_deg (or size/offset/rotation), or None."""
        if value is None:
            return cls()
        if isinstance(value, Placement):
            return value
        if isinstance(value, dict):
            return cls(
                size_mm=float(value.get("size_mm", value.get("size", 50.0))),
                offset_mm=tuple(value.get("offset_mm", value.get("offset", (0.0, 0.0, 0.0)))),
                rotation_deg=float(value.get("rotation_deg", value.get("rotation", 0.0))),
            )
        return cls(
            size_mm=float(getattr(value, "size_mm", 50.0)),
            offset_mm=tuple(getattr(value, "offset_mm", (0.0, 0.0, 0.0))),
            rotation_deg=float(getattr(value, "rotation_deg", 0.0)),
        )


def world_from_placement(anchor: AnchorSpec) -> np.ndarray:
    """4x4 transform from the placement frame (anchor centre, z out of the paper, metres) to the world."""
    if anchor.kind == "aruco_board":
        w = anchor.markers_x * anchor.marker_length + (anchor.markers_x - 1) * anchor.separation
        h = anchor.markers_y * anchor.marker_length + (anchor.markers_y - 1) * anchor.separation
        anchor_from_placement = make_pose(np.diag([1.0, -1.0, -1.0]), [w / 2, h / 2, 0.0])
    elif anchor.kind == "charuco":
        w = anchor.squares_x * anchor.square_length
        h = anchor.squares_y * anchor.square_length
        anchor_from_placement = make_pose(np.diag([1.0, -1.0, -1.0]), [w / 2, h / 2, 0.0])
    else:
        anchor_from_placement = np.eye(4)
    return np.asarray(anchor.world_from_anchor, dtype=float) @ anchor_from_placement


def placement_from_model(bounds: np.ndarray, placement: Placement) -> np.ndarray:
    """4x4 similarity taking model coordinates to the placement frame in millimetres.

    `bounds` is the model's (2, 3) axis-aligned bounding box in model units; the
    model's +z is taken as up. Scale makes the larger of the x and y extents
    equal `placement.size_mm` (the z extent when the model is flat in x and y).
    """
    bounds = np.asarray(bounds, dtype=float)
    extent = bounds[1] - bounds[0]
    horizontal = max(extent[0], extent[1])
    reference = horizontal if horizontal > 1e-12 else extent[2]
    if reference <= 1e-12:
        raise ValueError("the model has no extent; it cannot be scaled to a size")
    s = placement.size_mm / reference
    centre = np.array([(bounds[0, 0] + bounds[1, 0]) / 2, (bounds[0, 1] + bounds[1, 1]) / 2, bounds[0, 2]])
    a = np.radians(placement.rotation_deg)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    M = np.eye(4)
    M[:3, :3] = s * R
    M[:3, 3] = -s * R @ centre + np.asarray(placement.offset_mm)
    return M


def world_from_model(anchor: AnchorSpec, bounds: np.ndarray, placement: Placement) -> np.ndarray:
    """4x4 similarity from model coordinates to the world frame (metres)."""
    mm_to_m = np.diag([1e-3, 1e-3, 1e-3, 1.0])
    return world_from_placement(anchor) @ mm_to_m @ placement_from_model(bounds, placement)
