"""Back to CAD: an editable NURBS model fitted to a scanned solid.

A surface of revolution about the board's up direction: the axis is the
median centre of circles fitted (least squares, Kasa) to the side's vertices
in height bands; the profile r(h) is a clamped cubic B-spline whose control
heights sit at the Greville abscissae (so the height runs linearly along the
curve) and whose control radii are fitted by least squares to the vertices'
distances from the axis. The model (models/README.md format, millimetres, z up
along the board normal, origin on the paper at the axis) is the profile
revolved with the exact 7-point circle (`arapp.geometry.construct.revolve`)
plus a flat top and bottom disk. The fit error is the vertices' distance to
that surface (radial on the side, vertical on the caps), RMS and max, mm.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh


@dataclass
class NurbsFit:
    kind: str                 # "revolution"
    model: dict               # the arapp model JSON object
    rms_mm: float
    max_mm: float
    axis_world: np.ndarray    # (3,) the axis' foot on the paper, world frame (m)
    height_mm: float
    profile_r_mm: np.ndarray  # control radii, top to bottom


def _circle_centre(xy: np.ndarray) -> np.ndarray:
    """Least-squares circle centre (Kasa): x^2 + y^2 = 2ax + 2by + c."""
    A = np.c_[2 * xy, np.ones(len(xy))]
    sol = np.linalg.lstsq(A, (xy ** 2).sum(axis=1), rcond=None)[0]
    return sol[:2]


def fit_revolution(mesh: trimesh.Trimesh, anchors, n_ctrl: int = 8, max_rms_mm: float | None = None) -> NurbsFit:
    """Fit a surface of revolution about the board normal to `mesh` (world frame, metres); see module doc."""
    from arapp.geometry import basis
    from arapp.scan.fusion import board_frame

    fr = board_frame(anchors)
    L = fr.to_local(np.asarray(mesh.vertices)) * 1000.0      # mm, z up from the paper
    N = np.asarray(mesh.vertex_normals) @ fr.R
    H = float(L[:, 2].max())
    side = (np.abs(N[:, 2]) < 0.7) & (L[:, 2] > 0.05 * H) & (L[:, 2] < 0.95 * H)
    if side.sum() < 50:
        raise RuntimeError("the scan has no side wall to fit a surface of revolution to")
    bands = np.linspace(0.05 * H, 0.95 * H, 10)
    centres = []
    for a, b in zip(bands[:-1], bands[1:]):
        s = side & (L[:, 2] >= a) & (L[:, 2] < b)
        if s.sum() >= 20:
            centres.append(_circle_centre(L[s, :2]))
    c = np.median(np.array(centres), axis=0)
    r = np.linalg.norm(L[:, :2] - c, axis=1)
    h = L[:, 2]
    # the profile runs top (u = 0) to bottom (u = 1) so that the revolved normals face outward
    knots = basis.clamped_uniform_knots(n_ctrl, 3)
    greville = np.array([knots[i + 1:i + 4].mean() for i in range(n_ctrl)])
    B = basis.basis_matrix(knots, 3, n_ctrl, np.clip(1.0 - h[side] / H, 0, 1))
    # a light second-difference penalty keeps the control polygon smooth where few vertices constrain it
    D = np.diff(np.eye(n_ctrl), 2, axis=0) * 0.05 * np.sqrt(side.sum() / n_ctrl)
    ctrl_r = np.linalg.lstsq(np.vstack([B, D]), np.r_[r[side], np.zeros(len(D))], rcond=None)[0]
    ctrl_r = np.maximum(ctrl_r, 0.0)
    ctrl_h = H * (1.0 - greville)
    # error: distance to the nearest part of the model, the side radially, a cap vertically (within its radius)
    Ball = basis.basis_matrix(knots, 3, n_ctrl, np.clip(1.0 - h / H, 0, 1))
    err = np.abs(r - Ball @ ctrl_r)
    err = np.where(r <= ctrl_r[0], np.minimum(err, np.abs(h - H)), err)
    err = np.where(r <= ctrl_r[-1], np.minimum(err, np.abs(h)), err)
    rms, mx = float(np.sqrt(np.mean(err ** 2))), float(err.max())
    if max_rms_mm is not None and rms > max_rms_mm:
        raise RuntimeError(f"the scan is not a surface of revolution (fit error rms {rms:.2f} mm > "
                           f"{max_rms_mm:.2f} mm)")
    profile = {"control_points": [[float(a), float(b)] for a, b in zip(ctrl_r, ctrl_h)],
               "knots": [float(k) for k in knots], "degree": 3}
    size = float(max(2 * ctrl_r.max(), H))
    model = {
        "format": "arapp-model", "version": 1, "name": "scan (surface of revolution)",
        "units": "mm",
        "description": (f"Fitted by arapp scan --nurbs to a scanned solid: profile of {n_ctrl} cubic control "
                        f"points revolved about the board normal, flat top and bottom; fit error rms "
                        f"{rms:.2f} mm, max {mx:.2f} mm. Origin on the paper at the axis, z up."),
        "color": [0.75, 0.7, 0.6, 1.0],
        "placement": {"size_mm": round(size, 3)},
        "surfaces": [
            {"type": "revolve", "name": "side", "profile": profile},
            {"type": "disk", "name": "top", "radius": float(max(ctrl_r[0], 1e-3)), "center": [0, 0, H]},
            {"type": "disk", "name": "bottom", "radius": float(max(ctrl_r[-1], 1e-3)), "facing_up": False},
        ],
    }
    axis_world = fr.to_world(np.array([[c[0] / 1000.0, c[1] / 1000.0, 0.0]]))[0]
    return NurbsFit("revolution", model, rms, mx, axis_world, H, ctrl_r)


def fit_model(mesh: trimesh.Trimesh, anchors) -> NurbsFit:
    """The best editable model arapp can fit: a surface of revolution (the only kind so far)."""
    return fit_revolution(mesh, anchors)


def write_model(fit: NurbsFit, path: str | Path) -> Path:
    """Write the model JSON through a temporary file renamed into place."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(fit.model, indent=2) + "\n")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
