"""Where a model sits on the world anchor.

Frames:
- *model frame*: the model file's coordinates, in its stated units.
- *placement frame*: origin at the world anchor's centre, x right and y up as
  the anchor is printed, z out of the paper toward the viewer; millimetres (or
  metres where a function says so). For an `aruco` or `qr` anchor this is the
  anchor frame itself; for an `aruco_board` or `charuco` board (OpenCV's
  frame: origin at the first marker's outer corner, y down, z into the paper)
  it is the board centre with y and z flipped.
- *world frame*: the first anchor's frame (docs/recording-format.md), metres.

The placement itself (size of the model's largest extent in millimetres,
offset, rotation) is `arapp.geometry.Placement`, stored with the model and
applied by `Model.placement_matrix`; the printed part uses the same matrix,
so what is printed is what was seen.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import trimesh

from arapp.geometry.model import Model, Placement
from tracking.slam.flow import lift_to_plane
from tracking.session import AnchorSpec

__all__ = ["Placement", "placement_from_any", "placement_from_model", "world_from_placement", "world_from_model",
           "placement_point_at_pixel", "dragged_placement"]


def placement_from_any(value, default: Placement | None = None) -> Placement:
    """A Placement from a Placement, a dict (size_mm, offset, rotation_deg; missing keys from `default`), or None."""
    return Placement.from_any(value, default)


def world_from_placement(anchor: AnchorSpec) -> np.ndarray:
    """4x4 transform from the placement frame (anchor centre, z out of the paper, metres) to the world."""
    anchor_from_placement = anchor.anchor_kind.anchor_from_placement(anchor)
    return np.asarray(anchor.world_from_anchor, dtype=float) @ anchor_from_placement


def world_from_model(anchor: AnchorSpec, model) -> np.ndarray:
    """4x4 similarity from the model's coordinates to the world (metres), as placed on `anchor`."""
    return world_from_placement(anchor) @ model.placement_matrix("m")


def placement_from_model(bounds: np.ndarray, placement, unit: str = "mm") -> np.ndarray:
    """4x4 similarity from a mesh with these (2, 3) bounds to the placement frame, as `Model.placement_matrix`."""
    box = trimesh.creation.box(bounds=np.asarray(bounds, dtype=float))
    return Model("placed", placement=placement_from_any(placement), source_mesh=box).placement_matrix(unit)


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
