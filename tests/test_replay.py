"""`arapp replay` writes exactly what docs/recording-format.md lists, and the overlay sits where the model projects."""

import csv
import json
import threading

import cv2
import numpy as np
import pytest

from arapp.cli import main
from tracking.poses import read_tum

RECORDING = "recordings/board_orbit"


@pytest.fixture(scope="module")
def replayed(tmp_path_factory, repo_root):
    out = tmp_path_factory.mktemp("replay")
    rc = main(["replay", str(repo_root / RECORDING), "--out", str(out), "--model",
               str(repo_root / "models" / "vase.json"), "--frames", "30"])
    assert rc == 0
    return out


def test_outputs_follow_the_contract(replayed, repo_root):
    assert {p.name for p in replayed.iterdir()} >= {"poses.tum", "tracking.csv", "overlay.mp4", "report.json",
                                                   "trajectory.png"}
    rows = list(csv.DictReader(open(replayed / "tracking.csv")))
    assert list(rows[0].keys()) == ["frame", "t", "state", "markers", "inliers", "ms"]
    assert len(rows) == 30
    assert {r["state"] for r in rows} <= {"marker", "slam", "lost"}
    t, poses = read_tum(replayed / "poses.tum")
    placed = [r for r in rows if r["state"] != "lost"]
    assert len(t) == len(placed)
    assert np.allclose(t, [float(r["t"]) for r in placed], atol=1e-6)
    report = json.loads((replayed / "report.json").read_text())
    for key in ("frames", "tracked_fraction", "fps", "ate_rmse_m", "ate_max_m", "rpe_trans_m_per_s",
                "rpe_rot_deg_per_s"):
        assert key in report
    assert report["frames"] == 30
    # The pose is right: independent check against the recording's ground truth.
    gt_t, gt = read_tum(repo_root / RECORDING / "groundtruth.tum")
    idx = np.searchsorted(gt_t, t - 1e-6)
    err = np.linalg.norm(poses[:, :3, 3] - gt[idx, :3, 3], axis=1)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(report["ate_rmse_m"], rel=1e-6, abs=1e-9)
    assert report["ate_rmse_m"] < 0.005


def test_overlay_video_shows_the_model_where_it_projects(replayed, repo_root):
    from arapp.geometry import load_model
    from arapp.geometry.placement import world_from_model
    from tracking.poses import invert
    from tracking.recording.schema import load_session

    session = load_session(repo_root / RECORDING)
    model = load_model(repo_root / "models" / "vase.json")
    W = world_from_model(session.anchors[0], model)
    gt_t, gt = read_tum(repo_root / RECORDING / "groundtruth.tum")
    src = cv2.VideoCapture(str(repo_root / RECORDING / session.video))
    out = cv2.VideoCapture(str(replayed / "overlay.mp4"))
    verts = model.mesh().vertices
    changed_inside, changed_outside = [], []
    for i in range(0, 30):
        ok1, a = src.read()
        ok2, b = out.read()
        assert ok1 and ok2
        if i % 10:
            continue
        cam_from_model = invert(gt[i]) @ W
        px = session.camera.project((verts @ cam_from_model[:3, :3].T) + cam_from_model[:3, 3])
        mask = np.zeros(a.shape[:2], np.uint8)
        hull = cv2.convexHull(px.astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 255)
        inner = cv2.erode(mask, np.ones((7, 7), np.uint8)) > 0
        outer = cv2.dilate(mask, np.ones((15, 15), np.uint8)) == 0
        outer[:40, :] = False  # the status line
        diff = np.abs(a.astype(int) - b.astype(int)).max(axis=2)
        changed_inside.append(np.mean(diff[inner] > 40))
        changed_outside.append(np.mean(diff[outer] > 40))
    assert min(changed_inside) > 0.9  # the model covers its projection
    assert max(changed_outside) < 0.02  # and nothing else (video compression aside)


def test_cancelled_replay_leaves_consistent_outputs(tmp_path, repo_root):
    from arapp.engine.replay import ReplayOptions, replay

    cancel = threading.Event()

    def progress(done, total):
        if done == 5:
            cancel.set()

    report = replay(repo_root / RECORDING, tmp_path, ReplayOptions(video=False), progress=progress, cancel=cancel)
    assert report["interrupted"] is True and report["frames"] == 5
    rows = list(csv.DictReader(open(tmp_path / "tracking.csv")))
    assert len(rows) == 5
    assert json.loads((tmp_path / "report.json").read_text())["frames"] == 5


def test_replay_of_a_missing_recording_is_a_clear_error(tmp_path, capsys):
    rc = main(["replay", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "nope" in err and "Traceback" not in err
