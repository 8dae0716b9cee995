"""Scan mode in the window, offscreen (pytest-qt): a synthetic scan recording (a textured vase on a GridBoard,
tests/scan_scene.py) is played with scanning on; the coverage rises, Reconstruct runs in the background with
progress, and the mesh becomes the window's model, placed where the true vase stands (oracle: the vase's true
mesh, world frame, metres).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt
from scipy.spatial import cKDTree

pytest.importorskip("skimage", reason="arapp[scan] extra not installed")

pytestmark = pytest.mark.slow
N_FRAMES = 40


@pytest.fixture(scope="module")
def vase_recording():
    from scan_scene import vase_truth
    from test_scan_session import shared_vase_recording

    return shared_vase_recording(), vase_truth()


def test_scan_fills_the_dome_and_the_mesh_becomes_the_model(qtbot, tmp_path, vase_recording):
    from arapp.app.scan_session import ScanSettings
    from arapp.gui.main_window import MainWindow
    from arapp.geometry.placement import world_from_placement

    folder, truth = vase_recording
    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    w = MainWindow(settings=settings)
    w.full_frames = True   # frames as captured travel with each processed frame
    qtbot.addWidget(w)
    w.show()
    scan, panel = w.scan_session, w.scan_panel
    scan.work_dir = tmp_path / "scans"
    scan.settings = ScanSettings(max_views=20, refine=False, voxel=0.002)
    coverage = []
    scan.events.changed.connect(lambda: coverage.append(scan.coverage))
    w.session.events.source_opened.connect(lambda info: qtbot.mouseClick(panel.start_button, Qt.MouseButton.LeftButton))
    w.session.set_speed(0.5)   # circling slowly: every frame reaches the screen on a busy machine
    w.open_source(str(folder))
    qtbot.waitUntil(lambda: w.last_shown is not None and w.last_shown.result.index >= N_FRAMES - 1, timeout=60000)
    assert panel.start_button.text() == "Stop scan"
    assert w.scan_overlay.isVisible()
    assert coverage == sorted(coverage) and coverage[-1] >= 0.3
    assert panel.coverage_bar.value() == round(scan.coverage * 100)
    print(f"{len(scan.views)} views captured, coverage {scan.coverage:.2f}")
    assert len(scan.views) >= 20
    stages = []
    scan.events.progress.connect(lambda s, d, n: stages.append(s))
    assert panel.reconstruct_button.isEnabled()
    qtbot.mouseClick(panel.reconstruct_button, Qt.MouseButton.LeftButton)
    assert panel.cancel_button.isEnabled() and scan.state == "reconstructing"
    qtbot.waitUntil(lambda: scan.state != "reconstructing", timeout=90000)
    assert w.errors == [] and scan.state == "done", w.errors
    assert "tracking" in stages
    qtbot.waitUntil(lambda: w.model is not None and w.model_path == str(scan.result_path), timeout=10000)
    mesh = w.model.source_mesh.copy()
    mesh.apply_transform(world_from_placement(w.source_info.anchors[0]) @ w.model.placement_matrix("m"))
    d = cKDTree(truth.mesh.sample(20000)).query(mesh.sample(20000))[0] * 1000
    print(f"GUI scan vs truth: median {np.median(d):.2f} mm, p90 {np.percentile(d, 90):.2f} mm; {scan.stats}")
    assert np.median(d) < 2.0
    # drawn over the real object: the frames go on (looped) and the composite covers the true vase's silhouette
    w.session.set_loop(True)
    w.session.toggle_play() if not w.session.playing else None
    qtbot.waitUntil(lambda: w.last_shown.result.extra.get("model_gen") == w.model_gen
                    and w.last_shown.result.extra.get("mesh_faces", 0) > 0, timeout=30000)
    shown = w.last_shown
    cam, pose = w.source_info.camera, shown.result.world_from_camera
    cfw = np.linalg.inv(pose)
    pts, _ = cv2.projectPoints(np.asarray(truth.mesh.vertices) @ cfw[:3, :3].T + cfw[:3, 3], np.zeros(3),
                               np.zeros(3), cam.K, cam.dist)
    silhouette = np.zeros(shown.frame.shape[:2], np.uint8)
    cv2.fillPoly(silhouette, [cv2.convexHull(pts.reshape(-1, 2).astype(np.int32))], 1)
    inner = cv2.erode(silhouette, np.ones((7, 7), np.uint8)).astype(bool)
    changed = np.abs(shown.result.image.astype(np.int16) - shown.frame.astype(np.int16)).max(axis=2) > 12
    print(f"model drawn over {changed[inner].mean():.3f} of the true vase's silhouette (frame {shown.result.index})")
    assert changed[inner].mean() > 0.8
    assert panel.use_button.isEnabled()
    qtbot.mouseClick(panel.use_button, Qt.MouseButton.LeftButton)
    assert scan.state == "idle" and not w.scan_overlay.isVisible()
    assert Path(w.model_path).exists() and w.model is not None
    w.close()


def test_start_scan_reopens_a_source_that_does_not_send_frames_as_captured(qtbot, tmp_path, vase_recording):
    from arapp.gui.main_window import MainWindow

    folder, _ = vase_recording
    w = MainWindow(settings=QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat))
    w.engine_kind = "process"
    assert not w.full_frames
    qtbot.addWidget(w)
    w.show()
    w.open_source(str(folder))
    qtbot.waitUntil(lambda: w.last_shown is not None, timeout=30000)
    assert w.last_shown.frame is None          # the process engine sends only the composite
    qtbot.mouseClick(w.scan_panel.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: w.scan_session.state == "scanning" and len(w.scan_session.views) > 0, timeout=30000)
    assert w.full_frames and w.last_shown.frame is not None
    w.close()
