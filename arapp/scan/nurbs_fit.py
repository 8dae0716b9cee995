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

from arapp.geometry import basis
from arapp.scan.fusion import board_frame


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


def fit_patch(mesh: trimesh.Trimesh, anchors, n_u: int = 12, n_v: int = 8) -> NurbsFit:
    """A least-squares bicubic B-spline patch wrapped around the scan: u around the vertical axis through
    the scan's centroid (angle, the seam at u = 0/1 shares its control column), v up the height. Vertices
    are parameterised by (angle / 2 pi, height / H); the caps are left open (export thickens the wall)."""
    fr = board_frame(anchors)
    L = fr.to_local(np.asarray(mesh.vertices)) * 1000.0
    H = float(L[:, 2].max())
    c = L[:, :2].mean(axis=0)
    N = np.asarray(mesh.vertex_normals) @ fr.R
    side = np.abs(N[:, 2]) < 0.7
    P = L[side] - [c[0], c[1], 0.0]
    u = (np.arctan2(P[:, 1], P[:, 0]) / (2 * np.pi)) % 1.0
    v = np.clip(P[:, 2] / H, 0, 1)
    ku, kv = basis.clamped_uniform_knots(n_u, 3), basis.clamped_uniform_knots(n_v, 3)
    Bu, Bv = basis.basis_matrix(ku, 3, n_u, u), basis.basis_matrix(kv, 3, n_v, v)
    A = (Bu[:, :, None] * Bv[:, None, :]).reshape(len(P), n_u * n_v)
    # the seam: the last control column is the first one (a closed, position-continuous wrap)
    tie = np.zeros((n_u * n_v, (n_u - 1) * n_v))
    for i in range(n_u):
        for j in range(n_v):
            tie[i * n_v + j, (i % (n_u - 1)) * n_v + j] = 1.0
    ctrl = np.linalg.lstsq(A @ tie, P, rcond=None)[0]
    net = (tie @ ctrl).reshape(n_u, n_v, 3) + [c[0], c[1], 0.0]
    err = np.linalg.norm(A @ (tie @ ctrl) - P, axis=1)
    rms, mx = float(np.sqrt(np.mean(err ** 2))), float(err.max())
    model = {
        "format": "arapp-model", "version": 1, "name": "scan (bicubic patch)", "units": "mm",
        "description": (f"Fitted by arapp scan --nurbs: a {n_u} x {n_v} bicubic patch wrapped around the scan's "
                        f"side; fit error rms {rms:.2f} mm, max {mx:.2f} mm. z up from the paper."),
        "color": [0.75, 0.7, 0.6, 1.0],
        "placement": {"size_mm": round(float(max(np.ptp(net[..., 0]), np.ptp(net[..., 1]), H)), 3)},
        "surfaces": [{"type": "nurbs", "name": "side", "control_points": net.tolist(),
                      "knots_u": ku.tolist(), "knots_v": kv.tolist()}],
    }
    axis_world = fr.to_world(np.array([[c[0] / 1000.0, c[1] / 1000.0, 0.0]]))[0]
    return NurbsFit("bicubic patch", model, rms, mx, axis_world, H, np.zeros(0))


def fit_model(mesh: trimesh.Trimesh, anchors, round_tolerance: float = 0.02) -> NurbsFit:
    """A surface of revolution where the shape allows (fit error RMS within `round_tolerance` of the scan's
    size), else the bicubic patch, whichever fits better."""
    rev = fit_revolution(mesh, anchors)
    if rev.rms_mm <= round_tolerance * max(rev.height_mm, 2 * float(rev.profile_r_mm.max())):
        return rev
    patch = fit_patch(mesh, anchors)
    return patch if patch.rms_mm < rev.rms_mm else rev


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
