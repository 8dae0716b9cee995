"""A hand that slides onto a printed anchor's sheet and off again, as 3D outlines over the desk.

The hand is a set of flat shapes in the anchor's paper plane, lifted a little
(fingertips `tip_height` above the paper, the palm higher): four fingers and a
thumb as capsules (rounded tips), a palm and a forearm. It comes from
`approach_deg` (direction in the anchor frame, 0 = from +x, 90 = from +y, pointing
from the hand toward the anchor) and stops with its foremost fingertip `reach`
metres past the sheet's outermost point along the approach (so reach = the
paper margin puts that fingertip on the marker's black edge). Metres, anchor frame.
"""

from __future__ import annotations

import numpy as np

FINGER_WIDTH = 0.017
FINGER_PITCH = 0.019
FINGER_LENGTHS = (0.062, 0.072, 0.068, 0.055)  # index, middle, ring, little (from the palm edge)
PALM = (0.085, 0.095)  # width across the fingers, length toward the wrist
FOREARM_LENGTH = 0.22


def smooth_presence(t: float, start: float, end: float, ramp: float) -> float:
    """0 outside [start, end], rising to 1 over `ramp` s after start and falling to 0 over `ramp` s before end."""
    if t <= start or t >= end:
        return 0.0
    k = min(1.0, (t - start) / ramp, (end - t) / ramp)
    return float(k * k * (3 - 2 * k))


def _capsule(base: np.ndarray, tip: np.ndarray, radius: float, n_arc: int = 12) -> np.ndarray:
    """Outline (N, 2) of a capsule from `base` to `tip` with a round end at the tip (2D points)."""
    d = tip - base
    d = d / np.linalg.norm(d)
    nrm = np.array([-d[1], d[0]])
    centre = tip - d * radius
    ang = np.linspace(-np.pi / 2, np.pi / 2, n_arc)
    arc = centre + radius * (np.cos(ang)[:, None] * d + np.sin(ang)[:, None] * nrm)
    return np.vstack([base - nrm * radius, arc, base + nrm * radius])


def hand_polygons(paper_corners_xy: np.ndarray, approach_deg: float, reach: float, presence: float,
                  offset: float = 0.0, tip_height: float = 0.004, palm_height: float = 0.025,
                  retreat: float = 0.25) -> list[np.ndarray]:
    """3D polygons (each (N, 3), anchor frame, metres) of the hand at `presence` (0 = away, 1 = in place).

    paper_corners_xy: (4, 2) corners of the anchor's sheet (margin included), anchor frame.
    offset: shift of the hand across the approach direction (metres). retreat: how far back the
    fingertips are at presence 0. z is the height above the paper (the anchor frame's out-of-paper
    direction is +z for aruco/qr; the caller maps it).
    """
    a = np.radians(approach_deg)
    toward = -np.array([np.cos(a), np.sin(a)])  # from the hand toward the anchor
    across = np.array([-toward[1], toward[0]])
    outer = float(np.max(paper_corners_xy @ -toward))  # sheet's outermost point on the hand's side
    centre = paper_corners_xy.mean(axis=0)
    # foremost fingertip (middle finger) position along -toward, then pulled back by (1 - presence)
    tip_s = outer - reach + (1.0 - presence) * retreat
    origin = centre + across * offset + (-toward) * (tip_s - float(centre @ -toward))  # middle fingertip
    palm_front = origin - toward * FINGER_LENGTHS[1]
    polys2d, heights = [], []
    for k, length in enumerate(FINGER_LENGTHS):
        side = (k - 1.5) * FINGER_PITCH
        base = palm_front + across * side - toward * 0.01
        tip = palm_front + across * side + toward * length
        polys2d.append(_capsule(base, tip, FINGER_WIDTH / 2 * (0.85 if k == 3 else 1.0)))
    thumb_base = palm_front - toward * 0.05 + across * (PALM[0] / 2)
    thumb_tip = thumb_base + (toward * 0.6 + across * 0.8) / np.hypot(0.6, 0.8) * 0.05
    polys2d.append(_capsule(thumb_base, thumb_tip, 0.011))
    w, L = PALM
    palm = [palm_front + across * (-w / 2), palm_front + across * (w / 2),
            palm_front + across * (w / 2) - toward * L, palm_front + across * (-w / 2) - toward * L]
    polys2d.append(np.array(palm))
    wrist = palm_front - toward * L
    arm = [wrist + across * (-w * 0.4), wrist + across * (w * 0.4),
           wrist + across * (w * 0.45) - toward * FOREARM_LENGTH, wrist + across * (-w * 0.45) - toward * FOREARM_LENGTH]
    polys2d.append(np.array(arm))
    out = []
    for p in polys2d:
        # height grows from the fingertips toward the wrist (a hand resting its fingertips near the paper)
        back = np.clip((origin - p) @ toward / (FINGER_LENGTHS[1] + L), 0.0, None)
        z = tip_height + (palm_height - tip_height) * np.minimum(back, 1.0) + 0.05 * np.maximum(back - 1.0, 0.0)
        out.append(np.column_stack([p, z]))
    return out
