"""Trajectory accuracy against ground truth: ATE, RPE, jitter (TUM-style metrics).

All poses are `world_from_camera` 4x4 arrays, positions in metres, times in
seconds. No alignment is applied: with markers the world frame is the marker's,
so an estimate must match the ground truth as it stands (docs/domain.md §3).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from tracking.poses import invert, read_tum, rotation_angle


def associate(t_est: np.ndarray, t_gt: np.ndarray, max_dt: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i_est, i_gt) matching each estimate to the ground-truth sample nearest in time.

    Pairs further apart than `max_dt` seconds are dropped; each ground-truth
    sample is used at most once (the nearest estimate wins).
    """
    t_est = np.asarray(t_est, dtype=float).ravel()
    t_gt = np.asarray(t_gt, dtype=float).ravel()
    if t_est.size == 0 or t_gt.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    order = np.argsort(t_gt)
    ts = t_gt[order]
    j = np.clip(np.searchsorted(ts, t_est), 1, max(ts.size - 1, 1))
    left = np.clip(j - 1, 0, ts.size - 1)
    right = np.clip(j, 0, ts.size - 1)
    pick = np.where(np.abs(ts[left] - t_est) <= np.abs(ts[right] - t_est), left, right)
    dt = np.abs(ts[pick] - t_est)
    ok = dt <= max_dt
    i_est = np.nonzero(ok)[0]
    i_gt = order[pick[ok]]
    # one estimate per ground-truth sample: keep the closest in time
    best: dict[int, int] = {}
    for ie, ig in zip(i_est, i_gt):
        if ig not in best or dt[ie] < dt[best[ig]]:
            best[ig] = ie
    keep = sorted(best.items(), key=lambda kv: kv[1])
    return np.array([ie for _, ie in keep], int), np.array([ig for ig, _ in keep], int)


def position_errors(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Euclidean distance (N,) between associated estimated and true camera positions, metres."""
    return np.linalg.norm(np.asarray(est)[:, :3, 3] - np.asarray(gt)[:, :3, 3], axis=1)


def ate(est: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    """Absolute trajectory error (RMSE, max) of positions in metres, no alignment."""
    e = position_errors(est, gt)
    if e.size == 0:
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def rpe(times: np.ndarray, est: np.ndarray, gt: np.ndarray, delta: float = 1.0) -> tuple[float, float]:
    """Relative pose error as drift rates: (RMSE translation m/s, RMSE rotation deg/s).

    For every sample i, the sample j nearest to t_i + delta (seconds) is paired;
    the error of the relative motion `inv(inv(G_i) G_j) inv(E_i) E_j` is divided by
    t_j - t_i. Samples must be associated already (est[k] with gt[k]).
    """
    times = np.asarray(times, dtype=float)
    n = times.size
    if n < 2:
        return float("nan"), float("nan")
    trans, rot = [], []
    for i in range(n):
        j = int(np.searchsorted(times, times[i] + delta))
        if j >= n:
            break
        dt = times[j] - times[i]
        if dt <= 0:
            continue
        rel_gt = invert(gt[i]) @ gt[j]
        rel_est = invert(est[i]) @ est[j]
        E = invert(rel_gt) @ rel_est
        trans.append(np.linalg.norm(E[:3, 3]) / dt)
        rot.append(np.degrees(rotation_angle(E[:3, :3])) / dt)
    if not trans:
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(np.square(trans)))), float(np.sqrt(np.mean(np.square(rot))))


def jitter(times: np.ndarray, est: np.ndarray, gt: np.ndarray, max_gap: float | None = None) -> float:
    """RMS change (metres) of the position error between consecutive frames.

    Only pairs of samples at most `max_gap` seconds apart count (default 1.5 x
    the median frame interval), so a gap in tracking is not read as jitter.
    """
    times = np.asarray(times, dtype=float)
    if times.size < 2:
        return float("nan")
    err = np.asarray(est)[:, :3, 3] - np.asarray(gt)[:, :3, 3]
    dts = np.diff(times)
    if max_gap is None:
        max_gap = 1.5 * float(np.median(dts))
    ok = dts <= max_gap
    if not np.any(ok):
        return float("nan")
    d = np.linalg.norm(np.diff(err, axis=0)[ok], axis=1)
    return float(np.sqrt(np.mean(d**2)))


def extent(gt: np.ndarray) -> float:
    """Size of a trajectory: diagonal of the bounding box of its positions, metres."""
    p = np.asarray(gt)[:, :3, 3]
    if p.shape[0] == 0:
        return 0.0
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


@dataclass
class TrajectoryMetrics:
    """Accuracy of an estimated trajectory against ground truth (metres, seconds, degrees)."""

    frames: int                 # ground-truth samples (frames) considered
    tracked: int                # of those, frames with an estimate
    tracked_fraction: float
    ate_rmse_m: float
    ate_max_m: float
    rpe_trans_m_per_s: float
    rpe_rot_deg_per_s: float
    jitter_m: float
    extent_m: float

    @property
    def ate_fraction_of_extent(self) -> float:
        return self.ate_rmse_m / self.extent_m if self.extent_m > 0 else float("nan")

    def to_dict(self) -> dict:
        return asdict(self)


def evaluate(t_est, est, t_gt, gt, max_dt: float = 0.01, rpe_delta: float = 1.0) -> TrajectoryMetrics:
    """All metrics of an estimated trajectory (times (N,), poses (N,4,4)) against ground truth."""
    est = np.asarray(est, dtype=float).reshape(-1, 4, 4)
    gt = np.asarray(gt, dtype=float).reshape(-1, 4, 4)
    ie, ig = associate(t_est, t_gt, max_dt)
    times = np.asarray(t_gt, dtype=float)[ig]
    order = np.argsort(times)
    ie, ig, times = ie[order], ig[order], times[order]
    E, G = est[ie], gt[ig]
    a_rmse, a_max = ate(E, G)
    r_t, r_r = rpe(times, E, G, rpe_delta)
    all_dt = np.diff(np.sort(np.asarray(t_gt, dtype=float)))
    gap = 1.5 * float(np.median(all_dt)) if all_dt.size else None
    n = len(gt)
    return TrajectoryMetrics(
        frames=n, tracked=len(ie), tracked_fraction=len(ie) / n if n else 0.0,
        ate_rmse_m=a_rmse, ate_max_m=a_max, rpe_trans_m_per_s=r_t, rpe_rot_deg_per_s=r_r,
        jitter_m=jitter(times, E, G, gap), extent_m=extent(gt),
    )


def evaluate_files(estimate: str | Path, groundtruth: str | Path, max_dt: float = 0.01) -> TrajectoryMetrics:
    """Metrics of a TUM trajectory file against a ground-truth TUM file."""
    t_est, est = read_tum(estimate)
    t_gt, gt = read_tum(groundtruth)
    if len(t_gt) == 0:
        raise ValueError(f"{groundtruth}: ground truth has no poses; a TUM file needs one line per frame")
    return evaluate(t_est, est, t_gt, gt, max_dt)
