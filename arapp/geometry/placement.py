"""Where a model sits on the world anchor: the one `Placement` type and the transforms it gives.

Frames:
- *model frame*: the model file's coordinates, in its stated units.
- *placement frame*: origin at the world anchor's centre, x right and y up as
  the anchor is printed, z out of the paper toward the viewer; millimetres (or
  metres where a function says so). For an `aruco` or `qr` anchor this is the
  anchor frame itself; for an `aruco_board` or `charuco` board (OpenCV's
  frame: origin at the first marker's outer corner, y down, z into the paper)
  it is the board centre with y and z flipped.
- *world frame*: the first anchor's frame (docs/recording-format.md), metres.

`Placement` (size of the model's largest extent in millimetres, offset, rotation) is stored with the
model (`Model.placement`) and turned into a matrix by `Placement.matrix` (what `Model.placement_matrix`
gives); the printed part uses the same matrix, so what is printed is what was seen. Placements from
outside (a model file's or a command's dict, None for the default) become a `Placement` in one place,
`Placement.from_any`, at the boundary; everything inside takes a `Placement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from arapp.geometry.errors import ModelError, fmt
from tracking.anchors.kinds import AnchorSpec
from tracking.slam.flow import lift_to_plane

__all__ = ["Placement", "MAX_SIZE_MM", "check_size_mm", "world_from_placement", "world_from_model",
           "placement_point_at_pixel", "dragged_placement"]

MAX_SIZE_MM = 10_000.0  # 10 m: larger than any printer; past it the float maths of placement breaks down


def check_size_mm(size, where: str = "size") -> float:
    """`size` (mm) as a float when it is a usable part size, 0 < size <= MAX_SIZE_MM; else ModelError at `where`."""
    try:
        value = float(size)
    except (TypeError, ValueError):
        raise ModelError(where, f"must be a number of millimetres, got {size!r}") from None
    if not (math.isfinite(value) and 0 < value <= MAX_SIZE_MM):
        raise ModelError(where, f"must be a positive number of millimetres up to {fmt(MAX_SIZE_MM)}, got {size!r}")
    return value


@dataclass
class Placement:
    """Where the model sits on its marker.

    size_mm: largest extent of the model on the marker, millimetres;
    offset: translation in the marker frame (x right, y up the marker, z out
    of it), millimetres, applied last; rotation_deg: rotations about x, y, z
    (applied in that order) before scaling.
    """

    size_mm: float = 50.0
    offset: tuple = (0.0, 0.0, 0.0)
    rotation_deg: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        # A single angle turns the model about the marker normal (z), as the GUI edits it.
        if np.isscalar(self.rotation_deg):
            self.rotation_deg = (0.0, 0.0, float(self.rotation_deg))
        self.size_mm = float(self.size_mm)
        self.offset = tuple(float(x) for x in self.offset)
        self.rotation_deg = tuple(float(x) for x in self.rotation_deg)

    @classmethod
    def from_any(cls, value, default: "Placement | None" = None) -> "Placement":
        """A Placement from a Placement, None (the default), or a dict with some of size_mm, offset (mm)
        and rotation_deg (x, y, z degrees, or one angle about the anchor normal); missing keys from `default`."""
        base = default or cls()
        if value is None:
            return base
        if isinstance(value, Placement):
            return value
        if not isinstance(value, dict):
            raise TypeError(f"a placement must be a Placement or a dict, got {type(value).__name__}")
        unknown = set(value) - {"size_mm", "offset", "rotation_deg"}
        if unknown:
            raise ModelError("placement", f"unknown key(s) {', '.join(sorted(unknown))}; "
                             "use size_mm, offset (mm) and rotation_deg (x, y, z degrees)")
        size = check_size_mm(value.get("size_mm", base.size_mm), "placement.size_mm")
        place = cls(size, value.get("offset", base.offset), value.get("rotation_deg", base.rotation_deg))
        if len(place.offset) != 3 or len(place.rotation_deg) != 3:
            raise ModelError("placement", "offset and rotation_deg need three components (x, y, z)")
        return place

    def rotation(self) -> np.ndarray:
        """3x3 rotation R = Rz @ Ry @ Rx."""
        ax, ay, az = np.radians(self.rotation_deg)
        rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
        ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
        rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
        return rz @ ry @ rx

    def matrix(self, bounds, unit: str = "mm") -> np.ndarray:
        """4x4 map from model units to the placement frame (mm, or m with unit="m") for a model whose
        geometry has these (2, 3) bounds (model units).

        Rotates by rotation_deg, scales so the largest extent is size_mm,
        centres the model over the marker (x, y) standing on it (lowest z = 0),
        then adds offset.
        """
        rot = self.rotation()
        lo, hi = np.asarray(bounds, dtype=float)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        rc = corners @ rot.T
        extent = float((rc.max(axis=0) - rc.min(axis=0)).max())
        scale = self.size_mm / extent if extent > 0 else 1.0
        rlo, rhi = rc.min(axis=0) * scale, rc.max(axis=0) * scale
        shift = -np.array([(rlo[0] + rhi[0]) / 2, (rlo[1] + rhi[1]) / 2, rlo[2]]) + np.asarray(self.offset)
        m = np.eye(4)
        m[:3, :3] = scale * rot
        m[:3, 3] = shift
        if unit == "m":
            m[:3] *= 1e-3
        elif unit != "mm":
            raise ValueError(f"unit must be 'mm' or 'm', got {unit!r}")
        return m


def world_from_placement(anchor: AnchorSpec) -> np.ndarray:
    """4x4 transform from the placement frame (anchor centre, z out of the paper, metres) to the world."""
    anchor_from_placement = anchor.anchor_kind.anchor_from_placement(anchor)
    return np.asarray(anchor.world_from_anchor, dtype=float) @ anchor_from_placement


def world_from_model(anchor: AnchorSpec, model) -> np.ndarray:
    """4x4 similarity from the model's coordinates to the world (metres), as placed on `anchor`."""
    return world_from_placement(anchor) @ model.placement_matrix("m")


def placement_point_at_pixel(camera, world_from_camera: np.ndarray, anchor: AnchorSpec,
                             pixel) -> np.ndarray | None:
    """The point (x, y) in millimetres of the placement frame's z = 0 plane (the anchor's paper) seen at
    `pixel` (u, v: distorted image pixels of `camera`, centres at integers) from `world_from_camera`,
    or None when that ray does not meet the paper in front of the camera (at the horizon or behind)."""
    placement_from_camera = np.linalg.inv(world_from_placement(anchor)) @ np.asarray(world_from_camera, float)
    X, ok = lift_to_plane(camera, placement_from_camera, np.asarray(pixel, float).reshape(1, 2),
                          max_depth_ratio=1e3, min_grazing_deg=2.0)
    return X[0, :2] * 1000.0 if ok[0] else None


def dragged_placement(start: Placement, grab_mm, now_mm, mode: str = "move") -> Placement:
    """The placement after dragging on the paper from `grab_mm` to `now_mm` (placement-frame x, y in mm,
    see `placement_point_at_pixel`), starting from `start`. mode "move": the model follows the pointer
    in the paper's plane (height kept). mode "turn": the model turns about its own vertical axis (the
    paper's normal through its offset) by the angle the pointer swept around it."""
    g, n = np.asarray(grab_mm, float), np.asarray(now_mm, float)
    ox, oy, oz = start.offset
    if mode == "move":
        return replace(start, offset=(ox + n[0] - g[0], oy + n[1] - g[1], oz))
    if mode != "turn":
        raise ValueError(f"drag mode must be 'move' or 'turn', not {mode!r}")
    a0 = np.arctan2(g[1] - oy, g[0] - ox)
    a1 = np.arctan2(n[1] - oy, n[0] - ox)
    turn = (np.degrees(a1 - a0) + 180.0) % 360.0 - 180.0
    rx, ry, rz = start.rotation_deg
    return replace(start, rotation_deg=(rx, ry, (rz + turn + 180.0) % 360.0 - 180.0))
