"""How well a set of corners holds the camera position (tracking.slam.frame_pose.position_spread). Oracle: the
spread of camera positions cv2.solvePnP gives over many draws of pixel noise."""

import cv2
import numpy as np

from tracking.poses import invert
from tracking.slam.frame_pose import position_spread
from test_slam_flow import look

K = np.array([[540.0, 0, 319.5], [0, 540.0, 239.5], [0, 0, 1]])


def _board(nx, ny, size=0.035, gap=0.008, x0=0.0):
    """Corners (N,3) of an nx x ny grid of square markers on the plane z = 0, metres."""
    pts = []
    for i in range(nx):
        for j in range(ny):
            x, y = x0 + i * (size + gap), j * (size + gap)
            pts += [[x, y, 0], [x + size, y, 0], [x + size, y + size, 0], [x, y + size, 0]]
    return np.array(pts, float)


def _monte_carlo(pose, X, sigma, draws=400, seed=0):
    cw = invert(pose)
    rvec, _ = cv2.Rodrigues(cw[:3, :3])
    uv, _ = cv2.projectPoints(X, rvec, cw[:3, 3], K, None)
    uv = uv.reshape(-1, 2)
    rng = np.random.default_rng(seed)
    centres = []
    for _ in range(draws):
        ok, r, t = cv2.solvePnP(X, uv + rng.normal(0, sigma, uv.shape), K, None, rvec.copy(), cw[:3, 3].copy(),
                                useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        R, _ = cv2.Rodrigues(r)
        centres.append((-R.T @ t).ravel())
    c = np.array(centres)
    return float(np.sqrt(np.trace(np.cov(c.T))))


def test_spread_matches_solvepnp_over_noise():
    pose = look([0.05, -0.3, 0.4], [0.08, 0.06, 0.0])
    for X in (_board(4, 3), _board(3, 1, x0=0.13), _board(1, 1)):
        predicted = position_spread(K, pose, X, 0.5)
        measured = _monte_carlo(pose, X, 0.5)
        assert 0.85 * measured < predicted < 1.15 * measured, (len(X), predicted, measured)   # 0.96-1.02 measured


def test_a_few_markers_in_a_row_hold_the_position_worse_than_the_whole_board():
    pose = look([0.05, -0.3, 0.4], [0.08, 0.06, 0.0])
    whole, row = _board(4, 3), _board(3, 1, x0=0.0)
    per_corner = [position_spread(K, pose, X, 1.0) * np.sqrt(len(X)) for X in (whole, row)]
    assert per_corner[1] > 1.8 * per_corner[0], per_corner
    # too few points, or a point behind the camera: no finite spread
    assert position_spread(K, pose, whole[:2], 1.0) == float("inf")
    assert position_spread(K, np.eye(4), whole + [0, 0, -1.0], 1.0) == float("inf")
