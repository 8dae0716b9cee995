"""Entering the bed anchor once: where the marker lies on the printer's bed (docs/printer-profile.md).

Two ways, both giving `bed_from_anchor` (anchor frame taken in millimetres ->
bed frame, millimetres):
- measured: the marker centre's bed coordinates and its turn about the bed's z;
- touched: jog the nozzle onto the marker's bottom-left and bottom-right
  corners (as printed: corners 3 and 2 in OpenCV's order) and read the
  printer's X/Y there (M114). The two points fix the centre and the turn; the
  distance between them must match the marker's side.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from arapp.printing.profile import GENERIC_PATH, parse_profile


def bed_from_anchor_measured(center_xy_mm, rotation_deg: float = 0.0, z_mm: float = 0.0) -> np.ndarray:
    """4x4 `bed_from_anchor` of a marker lying flat with its centre at `center_xy_mm`, turned by rotation_deg."""
    a = math.radians(rotation_deg)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = [float(center_xy_mm[0]), float(center_xy_mm[1]), float(z_mm)]
    return T


def bed_from_anchor_touched(bottom_left_mm, bottom_right_mm, side_m: float, tolerance_mm: float = 2.0,
                            z_mm: float = 0.0) -> np.ndarray:
    """4x4 `bed_from_anchor` from the bed X/Y of the marker's bottom-left and bottom-right corners.

    side_m: the marker's side (the anchor's `length`, metres). Raises ValueError
    when the touched points are further from one side's length apart than
    tolerance_mm (a wrong corner or a wrong length in the profile).
    """
    p3 = np.asarray(bottom_left_mm, dtype=float)[:2]
    p2 = np.asarray(bottom_right_mm, dtype=float)[:2]
    side_mm = 1000.0 * side_m
    d = p2 - p3
    dist = float(np.hypot(*d))
    if abs(dist - side_mm) > tolerance_mm:
        raise ValueError(
            f"the touched corners are {dist:.1f} mm apart but the marker's side is {side_mm:.1f} mm; "
            "touch the bottom-left then the bottom-right corner of the marker (as printed), "
            "or correct the marker length in the profile"
        )
    x_axis = d / dist
    y_axis = np.array([-x_axis[1], x_axis[0]])
    centre = (p2 + p3) / 2 + y_axis * side_mm / 2
    return bed_from_anchor_measured(centre, math.degrees(math.atan2(x_axis[1], x_axis[0])), z_mm)


def save_bed_anchor(profile_path: str | Path, anchor: dict, bed_from_anchor: np.ndarray) -> Path:
    """Write the bed anchor into a printer profile JSON (created from the generic one when missing)."""
    path = Path(profile_path)
    data = json.loads(path.read_text()) if path.exists() else json.loads(Path(GENERIC_PATH).read_text())
    block = dict(anchor)
    block["bed_from_anchor"] = np.round(np.asarray(bed_from_anchor, dtype=float), 6).tolist()
    data["bed_anchor"] = block
    parse_profile(json.loads(json.dumps(data)), str(path))  # refuse to write an invalid profile
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(path)  # atomic: a crash never leaves half a profile
    return path
