"""Shared oracle of the scan tests: the written mesh against the synthetic vase's true surface.

Distances are in mm in the print frame (x right, y away, z up from the paper),
sampled on both surfaces with trimesh and matched with scipy's cKDTree.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

WORLD_TO_PRINT_MM = np.diag([1000.0, -1000.0, -1000.0, 1.0])   # GridBoard frame (m, z into the paper) -> print


def compare_to_truth(out, truth_mesh, n: int = 30000):
    """Load the scan at `out` and compare it with `truth_mesh` (metres, board frame).

    Returns (mesh, scan_pts, d_scan, d_true): d_scan is each scan sample's distance to
    the truth (accuracy, clutter), d_true each true sample's distance to the scan (completeness).
    """
    mesh = trimesh.load(out)
    truth = truth_mesh.copy()
    truth.apply_transform(WORLD_TO_PRINT_MM)
    scan_pts, _ = trimesh.sample.sample_surface(mesh, n, seed=0)
    true_pts, _ = trimesh.sample.sample_surface(truth, n, seed=1)
    d_scan = cKDTree(true_pts).query(scan_pts)[0]
    d_true = cKDTree(scan_pts).query(true_pts)[0]
    return mesh, scan_pts, d_scan, d_true
