"""Flow seeds placed as a pan starts (issue 13: fast pans): the rolling-shutter correction of a seed's
pixel needs its image velocity at the seed image's row time, which the path *after* the image (the only
motion a fresh seed has) gives half a frame late: a camera speeding up shears the seeds' placement on the
plane by the change of velocity over that half frame. With the pose of the frame before (the motion
model's last step), the seed's velocity over the interval before is known too, and the two carry it to
the row time (`flow._step_velocity`, `flow._seed_velocity_then`); the followed points' deskew in the next
frame uses the same step (`_row_time_velocity` with the velocity before).

Oracle: world points on the plane z = 0, imaged under a 30 ms rolling shutter by projecting them
(Camera.project_world, i.e. cv2.projectPoints) from the pose at each point's own row time; seeds must
land on those world points, and the followed points must deskew to the centre-row pose's projection.
"""

import cv2
import numpy as np

from scenes import rolling_shutter_pixels
from test_rolling_shutter import board_under_rolling_shutter
from tracking.slam.flow import (Tracks, _row_time_velocity, _seed_velocity_then, _step_velocity, deskew,
                                lift_to_plane)

DT = 1 / 30
ALPHA = 15.0   # rad/s^2: a pan starting from rest, 57 deg/s two frames on


def _pose_at(t: float) -> np.ndarray:
    """world_from_camera at time t: 0.45 m above the plane z = 0 looking down, turning about the camera's y
    axis (a pan) with constant angular acceleration from rest at t = 0."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ cv2.Rodrigues(np.array([0.0, 0.5 * ALPHA * t * t, 0.0]))[0]
    T[:3, 3] = [0.0, 0.0, 0.45]
    return T


def _plane_points() -> np.ndarray:
    x, y = np.meshgrid(np.linspace(-0.2, 0.2, 9), np.linspace(-0.15, 0.15, 7))
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]


def _frames():
    cam = board_under_rolling_shutter()[0]
    world = _plane_points()
    t1 = 2 * DT   # the seed image; the frame before it at DT, the next at 3 DT
    seen1 = rolling_shutter_pixels(cam, world, _pose_at, t1)
    seen2 = rolling_shutter_pixels(cam, world, _pose_at, t1 + DT)
    keep = ((seen1 >= 0) & (seen1 < [cam.width, cam.height])).all(axis=1)
    keep &= ((seen2 >= 0) & (seen2 < [cam.width, cam.height])).all(axis=1)
    return cam, world[keep], seen1[keep], seen2[keep], t1


def _seeds(cam, world, seen1, t1):
    """Fresh seeds in the seed image (no path velocity), placed on the plane with the pixels as seen."""
    X, ok = lift_to_plane(cam, _pose_at(t1), seen1)
    assert ok.all()
    return Tracks(np.zeros((cam.height, cam.width), np.uint8), seen1.astype(np.float32), X, planar=np.ones(len(X), bool))


def test_seeds_placed_on_the_plane_at_their_row_time():
    cam, world, seen1, seen2, t1 = _frames()
    tracks = _seeds(cam, world, seen1, t1)
    after = (seen2 - seen1) / DT
    before_v = _step_velocity(cam, tracks, _pose_at(t1), (_pose_at(t1 - DT), DT), (seen2 - seen1) / DT, DT)
    assert before_v is not None and np.isfinite(before_v).all()
    old, _ = lift_to_plane(cam, _pose_at(t1), deskew(cam, seen1, after))
    new, _ = lift_to_plane(cam, _pose_at(t1), deskew(cam, seen1, _seed_velocity_then(cam, seen1, after, DT, before_v, DT)))
    err_old = 1000 * np.linalg.norm(old - world, axis=1).max()
    err_new = 1000 * np.linalg.norm(new - world, axis=1).max()
    raw = 1000 * np.linalg.norm(tracks.X - world, axis=1).max()
    assert raw > 4.0, raw                  # placed as seen, the shutter moves seeds by millimetres (6.5 mm)
    assert err_old > 1.5, err_old          # deskewed by the path after alone, half a frame late: 2.3 mm
    assert err_new < 0.3, (err_old, err_new)   # with the step before: 0.15 mm


def test_followed_seeds_deskewed_with_the_step_before():
    cam, world, seen1, seen2, t1 = _frames()
    tracks = _seeds(cam, world, seen1, t1)
    ok = np.ones(len(world), bool)
    truth = cam.project_world(world, _pose_at(t1 + DT))
    before_v = _step_velocity(cam, tracks, _pose_at(t1), (_pose_at(t1 - DT), DT), (seen2 - seen1) / DT, DT)
    without = deskew(cam, seen2, _row_time_velocity(cam, seen1, seen2, ok, DT, None))
    with_step = deskew(cam, seen2, _row_time_velocity(cam, seen1, seen2, ok, DT, before_v))
    left_without = np.abs(without - truth).max()
    left_with = np.abs(with_step - truth).max()
    assert np.abs(seen2 - truth).max() > 8.0     # the shutter's skew: 11.6 px
    assert left_without > 1.5, left_without      # no velocity before: 2.4 px left
    assert left_with < 0.35, (left_without, left_with)   # 0.17 px


def test_step_velocity_keeps_measured_paths():
    cam, world, seen1, seen2, t1 = _frames()
    tracks = _seeds(cam, world, seen1, t1)
    measured = np.full((len(world), 2), np.nan)
    measured[::2] = 123.0
    tracks.path_velocity = measured
    after = (seen2 - seen1) / DT
    v = _step_velocity(cam, tracks, _pose_at(t1), (_pose_at(t1 - DT), DT), after, DT)
    assert np.all(v[::2] == 123.0) and np.isfinite(v).all()
    assert _step_velocity(cam, tracks, _pose_at(t1), None, after, DT) is measured
