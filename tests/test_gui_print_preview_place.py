"""The AR print preview stands where the model is placed when no bed marker says otherwise
(pytest-qt, offscreen, the in-process engine). Recording printer_bed (its marker is the session's anchor);
the printer is a preset without a bed marker. Oracle: the placed model's bounding box projected with
cv2.projectPoints at the frame's pose; the toolpaths' perimeter pixels must fall inside it."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PySide6.QtCore import Qt

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "recordings" / "printer_bed"
TIMEOUT_MS = 60000


@pytest.fixture()
def window(threads_window):
    threads_window.full_frames = True
    return threads_window


def model_box_polygon(window, shown) -> np.ndarray:
    """The placed model's bounding box (8 corners) projected by cv2.projectPoints: its convex hull (pixels)."""
    from arapp.geometry.placement import world_from_placement

    s = window.session
    model = s.model
    model.placement = s.placement
    lo, hi = model.mesh().bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    T = world_from_placement(s.source_info.anchors[0]) @ model.placement_matrix("m")
    world = corners @ T[:3, :3].T + T[:3, 3]
    cfw = np.linalg.inv(shown.result.world_from_camera)
    rvec, _ = cv2.Rodrigues(cfw[:3, :3])
    cam = s.source_info.camera
    uv, _ = cv2.projectPoints(world, rvec, cfw[:3, 3], cam.K, cam.dist)
    return cv2.convexHull(uv.reshape(-1, 2).astype(np.float32)).reshape(-1, 2)


def test_preview_without_bed_marker_stands_on_the_model(qtbot, window, tmp_path):
    from arapp.store import user_config
    from arapp.engine.toolpath_overlay import KIND_COLOURS

    user_config.remember("printer", {"profile": "preset:prusa_mk3s", "link": "serial", "port": "", "baud": 115200,
                                     "url": ""})
    window.open_model(str(ROOT / "models" / "vase.json"))
    qtbot.waitUntil(lambda: window.model is not None, timeout=TIMEOUT_MS)
    window.model_panel.size.setValue(30.0)
    window.replay.loop.setChecked(True)
    window.open_source(str(RECORDING))
    qtbot.waitUntil(lambda: window.last_shown is not None and window.last_shown.result.world_from_camera is not None,
                    timeout=TIMEOUT_MS)
    window.open_print_dialog()
    dlg = window._print_dialog
    dlg.work_dir = tmp_path / "jobs"
    assert dlg.profile_key() == "preset:prusa_mk3s"
    dlg.layer_height.setValue(0.3)
    dlg.infill.setValue(10)
    qtbot.mouseClick(dlg.slice_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dlg.result is not None, timeout=TIMEOUT_MS)
    assert dlg.preview_check.isEnabled()  # no bed marker: still previewed, on the model
    dlg.preview_check.setChecked(True)
    qtbot.waitUntil(lambda: (window.toolpaths_info or {}).get("gen") == window.toolpaths_gen
                    and (window.last_shown.result.extra.get("toolpaths") or {}).get("gen") == window.toolpaths_gen,
                    timeout=TIMEOUT_MS)
    info = window.toolpaths_info
    assert info["placed_by"] == "model" and "no bed marker" in info["placed_text"]
    assert dlg.placement_note.isVisible() and "where the model is placed" in dlg.placement_note.text()
    window.session.pause()
    qtbot.wait(300)
    # the paused frame: posed, with this preview drawn on it
    qtbot.waitUntil(lambda: window.last_shown.result.world_from_camera is not None
                    and (window.last_shown.result.extra.get("toolpaths") or {}).get("gen") == window.toolpaths_gen,
                    timeout=TIMEOUT_MS)
    shown = window.last_shown
    img = shown.result.image.astype(int)
    orange = np.array(KIND_COLOURS["perimeter"][2::-1]) * 255
    drawn = (np.abs(img - orange).max(axis=2) < 40) & (np.abs(img - shown.frame.astype(int)).max(axis=2) > 40)
    ys, xs = np.nonzero(drawn)
    assert len(xs) > 200
    hull = model_box_polygon(window, shown)
    inside = np.array([cv2.pointPolygonTest(hull.reshape(-1, 1, 2), (float(x), float(y)), True)
                       for x, y in zip(xs, ys)])
    assert (inside >= -2.0).mean() >= 0.98, (inside >= -2.0).mean()  # the stack stands in the model's box
    # and covers it: the toolpaths' extent spans most of the box's width in the image
    assert np.ptp(xs) >= 0.6 * np.ptp(hull[:, 0])
