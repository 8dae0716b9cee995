"""Rolling-shutter correction under an accelerating pan (issue 13: hand-held webcams, fast pans).

The image velocity measured from two frames' corners is the velocity half a frame before the corner's
row time; under acceleration that lag leaves corners off by (acceleration x dt/2 x row time). The tracker
carries the velocity on to the middle of the stretch each corner is moved over (from its row time to the
frame time) with the change between the last two frames' velocity fields.

Oracle: corners under a rolling shutter are made here by projecting the board's corners
(Camera.project_world, i.e. cv2.projectPoints) from the pose at each corner's own row time; the
correction must give the projection from the centre-row pose.
"""

import cv2
import numpy as np

from tracking.anchors.detect import Observation
from scenes import rolling_shutter_pixels
from test_rolling_shutter import board_under_rolling_shutter

W0 = np.array([0.1, 0.3, 0.0])      # rad/s at t = 0
ALPHA = np.array([0.2, 4.0, 0.0])   # rad/s^2: a hand-held pan starting up (0.3 -> 0.57 rad/s in 2 frames)


def _pose_at(t):
    """world_from_camera at time t: looking down at the board from 0.45 m, turning with constant acceleration."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(W0 * t + 0.5 * ALPHA * t * t)[0] @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [0.0, 0.0, 0.45]
    return T


def _left_after(frames: int) -> tuple[float, float]:
    cam, tracker, obj, world, groups = board_under_rolling_shutter()
    for k in range(frames):
        t = k / 30.0
        seen = rolling_shutter_pixels(cam, world, _pose_at, t)
        truth = cam.project_world(world, _pose_at(t))
        out = tracker._deskew([Observation(0, obj, seen, groups, len(groups) // 4)], t)[0]
    return float(np.abs(seen - truth).max()), float(np.abs(out.img - truth).max())


def test_accelerating_pan_corrected_to_the_centre_row_time():
    skew, left = _left_after(3)
    assert skew > 2.5, skew               # the shutter moved corners by pixels (3.3 px measured)
    # measured 0.08 px with the velocity carried on to the middle of each corner's stretch (t + d/2);
    # 0.19 px carried to the frame time t, 0.57 px with the half-frame-old velocity
    assert left < 0.12, (skew, left)
