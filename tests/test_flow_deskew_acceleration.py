"""The optical flow's rolling-shutter correction under an accelerating pan (issue 13: fast pans).

A followed point's displacement over the last frame interval is its image velocity halfway along that
path, at t - dt/2 + d for a point on a row read d seconds after the frame time t. Moving the point to
the frame time needs the velocity over the stretch from t + d back to t, i.e. at its middle, t + d/2:
(dt - d)/2 after the path's middle. Carried there by the point's own change of velocity (two path
velocities, dt apart), what is left of the shutter's skew is second order.

Oracle: points on the plane z = 0 under a rolling shutter are made here by projecting them
(Camera.project_world, i.e. cv2.projectPoints) from the pose at each point's own row time (the same
fixed-point rule the synthesiser uses); the correction must give the projection from the centre-row pose.
"""

import numpy as np

from scenes import rolling_shutter_pixels
from test_deskew_acceleration import _pose_at
from test_rolling_shutter import board_under_rolling_shutter
from tracking.slam.flow import _row_time_velocity, deskew

DT = 1 / 30


def _plane_points() -> np.ndarray:
    """A 9 x 7 grid of world points on z = 0 filling most of the view from `_pose_at`'s 0.45 m."""
    x, y = np.meshgrid(np.linspace(-0.2, 0.2, 9), np.linspace(-0.15, 0.15, 7))
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]


def _left_at(t: float) -> tuple[float, float]:
    """(largest skew of the points seen at frame time t, largest error left after the correction), px."""
    cam = board_under_rolling_shutter()[0]
    world = _plane_points()
    seen = [rolling_shutter_pixels(cam, world, _pose_at, t - k * DT) for k in (2, 1, 0)]
    before_velocity = (seen[1] - seen[0]) / DT
    ok = np.ones(len(world), bool)
    velocity = _row_time_velocity(cam, seen[1], seen[2], ok, DT, before_velocity)
    truth = cam.project_world(world, _pose_at(t))
    out = deskew(cam, seen[2], velocity)
    return float(np.abs(seen[2] - truth).max()), float(np.abs(out - truth).max())


def test_flow_points_corrected_to_the_centre_row_time_under_acceleration():
    skew, left = _left_at(3 * DT)
    assert skew > 3.5, skew               # the shutter moved points by pixels (5.4 px measured)
    # measured 0.04 px with the velocity carried to t + d/2; 0.40 px when carried (dt + d)/2 after the
    # path's middle instead (the row offset's sign the wrong way round)
    assert left < 0.12, (skew, left)
