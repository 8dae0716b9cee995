"""Trajectory metrics against hand-built trajectories whose errors are known by construction."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tracking.evaluation import associate, ate, evaluate, evaluate_files, extent, jitter, rpe
from tracking.poses import make_pose, write_tum


def circle(n=90, fps=30.0, r=0.4):
    t = np.arange(n) / fps
    poses = []
    for a in np.linspace(0, np.pi, n):
        R = Rotation.from_euler("z", a).as_matrix()
        poses.append(make_pose(R, [r * np.cos(a), r * np.sin(a), 0.5]))
    return t, np.array(poses)


def test_associate_nearest_within_tolerance():
    t_gt = np.arange(10) / 10.0
    t_est = np.array([0.003, 0.198, 0.5, 0.77, 0.9004])
    ie, ig = associate(t_est, t_gt, max_dt=0.01)
    assert ie.tolist() == [0, 1, 2, 4]          # 0.77 is 0.03 s from any sample
    assert ig.tolist() == [0, 2, 5, 9]


def test_ate_of_constant_offset_is_the_offset_and_rpe_is_zero():
    t, gt = circle()
    est = gt.copy()
    est[:, :3, 3] += [0.003, -0.004, 0.0]          # 5 mm everywhere
    rmse, mx = ate(est, gt)
    assert rmse == pytest.approx(0.005) and mx == pytest.approx(0.005)
    # a world-frame offset of positions changes relative motion only by rotation of the offset
    tr, rr = rpe(t, gt, gt)
    assert tr == pytest.approx(0.0, abs=1e-12) and rr == pytest.approx(0.0, abs=1e-4)  # arccos near 1


def test_rpe_measures_drift_rate():
    t, gt = circle(n=91)
    est = gt.copy()
    drift = 0.01  # metres per second along the world x axis
    est[:, 0, 3] += drift * t
    tr, _ = rpe(t, est, gt, delta=1.0)
    # relative error over 1 s is the 1 cm drift (expressed in the rotating camera frame: same length)
    assert tr == pytest.approx(drift, rel=1e-6)
    rot = gt.copy()
    for i in range(len(t)):  # about z, the axis the circle turns about, so the rates simply add
        rot[i, :3, :3] = rot[i, :3, :3] @ Rotation.from_euler("z", np.radians(2.0) * t[i]).as_matrix()
    _, rr = rpe(t, rot, gt, delta=1.0)
    assert rr == pytest.approx(2.0, rel=1e-6)


def test_jitter_is_rms_of_frame_to_frame_error_change_and_ignores_gaps():
    t, gt = circle(n=40)
    rng = np.random.default_rng(0)
    e = rng.normal(0, 0.002, (40, 3))
    est = gt.copy()
    est[:, :3, 3] += e
    ref = np.sqrt(np.mean(np.sum(np.diff(e, axis=0) ** 2, axis=1)))
    assert jitter(t, est, gt) == pytest.approx(ref)
    keep = np.r_[0:20, 25:40]                      # a gap: 20 -> 25 must not count
    d = [np.linalg.norm(e[i + 1] - e[i]) for i in list(range(19)) + list(range(25, 39))]
    assert jitter(t[keep], est[keep], gt[keep], max_gap=1.5 / 30) == pytest.approx(np.sqrt(np.mean(np.square(d))))


def test_evaluate_files_roundtrip(tmp_path):
    t, gt = circle()
    est = gt[::2].copy()
    est[:, 2, 3] += 0.002
    write_tum(tmp_path / "gt.tum", t, gt)
    write_tum(tmp_path / "est.tum", t[::2] + 0.001, est)
    m = evaluate_files(tmp_path / "est.tum", tmp_path / "gt.tum")
    assert m.frames == 90 and m.tracked == 45
    assert m.tracked_fraction == pytest.approx(0.5)
    assert m.ate_rmse_m == pytest.approx(0.002, abs=1e-7)
    assert m.extent_m == pytest.approx(extent(gt))
    assert m.extent_m == pytest.approx(np.hypot(0.8, 0.4), rel=1e-3)


def test_evaluate_without_estimates_reports_nothing_tracked():
    t, gt = circle(n=10)
    m = evaluate(np.zeros(0), np.zeros((0, 4, 4)), t, gt)
    assert m.tracked == 0 and m.tracked_fraction == 0.0 and np.isnan(m.ate_rmse_m)
