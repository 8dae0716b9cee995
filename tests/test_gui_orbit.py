"""The 3D orbit view (pytest-qt, offscreen GL): with a model loaded and no source the view area shows the
model, its pixels inside the bounding box projected with cv2.projectPoints at the orbit camera's pose
and the background outside it; a drag turns it and the wheel zooms."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt

from gui_helpers import grab_rgb

MODELS = Path(__file__).resolve().parents[1] / "models"
TIMEOUT_MS = 30000


@pytest.fixture()
def window(threads_window):
    threads_window.resize(1100, 700)
    return threads_window


def projected_box(orbit_view, vertices) -> np.ndarray:
    """Filled convex hull (widget pixels) of the model's bounding-box corners by cv2.projectPoints."""
    from arapp.app.orbit import camera_from_model, virtual_camera

    pic = orbit_view.picture()
    cam = virtual_camera(pic.width(), pic.height())
    cfm = camera_from_model(orbit_view.orbit, vertices, cam)
    lo, hi = vertices.min(0), vertices.max(0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rvec, _ = cv2.Rodrigues(cfm[:3, :3])
    uv, _ = cv2.projectPoints(corners, rvec, cfm[:3, 3], cam.K, cam.dist)
    uv = uv.reshape(-1, 2) * (orbit_view.width() / pic.width())  # picture pixels -> widget pixels
    mask = np.zeros((orbit_view.height(), orbit_view.width()), np.uint8)
    cv2.fillConvexPoly(mask, np.round(cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2)).astype(np.int32), 1)
    return mask.astype(bool)


def model_pixels(rgb: np.ndarray) -> np.ndarray:
    from arapp.gui.overlays.orbit_view import BACKGROUND_BGR

    bg = np.array(BACKGROUND_BGR[::-1], int)
    return np.abs(rgb.astype(int) - bg).max(axis=2) > 20


def test_model_without_source_shows_in_the_orbit_view(qtbot, window):
    w = window
    assert not w.orbit_view.isVisible()  # nothing loaded: the welcome view
    w.open_model(str(MODELS / "vase.json"))
    qtbot.waitUntil(lambda: w.model is not None, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.orbit_view.isVisible() and w.orbit_view.picture() is not None, timeout=TIMEOUT_MS)
    ov = w.orbit_view
    assert w.view.isVisible() and ov.geometry() == w.view.rect()
    assert ov.error is None
    verts = np.asarray(w.mesh_lines[0].vertices, float)

    rgb = grab_rgb(ov)
    seen = model_pixels(rgb)
    seen[-40:] = False  # the caption along the bottom edge
    box = projected_box(ov, verts)
    grown = cv2.dilate(box.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert seen.sum() > 0.25 * box.sum()             # the model fills a good share of its box
    assert (seen & ~grown).sum() <= 0.002 * seen.size  # and nothing is drawn outside it

    # a drag turns it (a different picture, still inside the new box); the wheel zooms in
    before, pic = ov.orbit, ov.picture()
    qtbot.mousePress(ov, Qt.MouseButton.LeftButton, pos=QPoint(200, 200))
    qtbot.mouseMove(ov, QPoint(300, 230))
    qtbot.mouseRelease(ov, Qt.MouseButton.LeftButton, pos=QPoint(300, 230))
    assert ov.orbit.azimuth_deg != before.azimuth_deg and ov.orbit.elevation_deg != before.elevation_deg
    # drawn on the view's render thread: painted when it comes
    qtbot.waitUntil(lambda: ov.picture() is not pic, timeout=TIMEOUT_MS)
    qtbot.wait(50)
    turned = model_pixels(grab_rgb(ov))
    turned[-40:] = False
    assert (turned != seen).mean() > 0.01
    box2 = cv2.dilate(projected_box(ov, verts).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert (turned & ~box2).sum() <= 0.002 * turned.size
    area, pic = turned.sum(), ov.picture()
    ov.orbit = ov.orbit.zoomed(3)
    ov.model_changed()
    qtbot.waitUntil(lambda: ov.picture() is not pic, timeout=TIMEOUT_MS)
    qtbot.wait(50)
    zoomed = model_pixels(grab_rgb(ov))
    zoomed[-40:] = False
    assert zoomed.sum() > 1.5 * area


def test_inset_while_the_marker_is_lost_and_gone_once_a_source_has_no_model(qtbot, window, tmp_path):
    """A plain video of a desk with no marker: the camera picture stays, the model turns in an inset."""
    path = tmp_path / "desk.avi"
    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    base = np.random.default_rng(0).integers(90, 160, (240, 320, 3), dtype=np.uint8)
    for _ in range(30):
        wr.write(base)
    wr.release()
    w = window
    w.open_source(f"file:{path}")
    qtbot.waitUntil(lambda: w.session.last_shown is not None, timeout=TIMEOUT_MS)
    assert not w.orbit_view.isVisible()  # no model: nothing to show in 3D
    w.open_model(str(MODELS / "vase.json"))
    qtbot.waitUntil(lambda: w.orbit_view.isVisible(), timeout=TIMEOUT_MS)
    ov, view = w.orbit_view, w.view.rect()
    assert ov.wanted() == "inset"
    assert ov.width() < 0.5 * view.width() and ov.geometry().right() <= view.right()
    assert ov.geometry().bottom() <= view.bottom()
    qtbot.waitUntil(lambda: ov.picture() is not None, timeout=TIMEOUT_MS)
    assert model_pixels(grab_rgb(ov))[:-30].mean() > 0.03


def test_inset_waits_out_a_moment_without_pose_and_draws_off_the_ui_thread(qtbot, monkeypatch):
    """A frame or two without a pose (a marker lost for a moment) does not flash the inset: it shows once the
    pose has been missing for LOST_DELAY_S, and goes at once when the pose is back. The picture is drawn on
    the view's render thread, never on the UI thread (GL start-up there stalled the live view 30 ms)."""
    import threading
    import time
    from types import SimpleNamespace

    import trimesh
    from PySide6.QtWidgets import QWidget

    from arapp.gui.overlays import orbit_view as ov_mod
    from arapp.render import OverlayRenderer

    drawn_on = []
    draw = OverlayRenderer.draw
    monkeypatch.setattr(OverlayRenderer, "draw",
                        lambda self, *a, **k: drawn_on.append(threading.current_thread()) or draw(self, *a, **k))
    view = QWidget()
    view.resize(800, 600)
    qtbot.addWidget(view)
    view.show()
    posed = SimpleNamespace(result=SimpleNamespace(world_from_camera=np.eye(4)))
    lost = SimpleNamespace(result=SimpleNamespace(world_from_camera=None))
    session = SimpleNamespace(model=object(), mesh_lines=(trimesh.creation.box((0.05, 0.05, 0.05)), None),
                              source_info={"name": "cam"}, engine=object(), last_shown=posed, mode="shaded")
    ov = ov_mod.OrbitView(view, session)
    try:
        ov.place()
        assert not ov.isVisible()
        session.last_shown = lost
        t0 = time.monotonic()
        ov.place()
        assert not ov.isVisible() and ov.wanted() is None  # lost just now
        qtbot.waitUntil(ov.isVisible, timeout=TIMEOUT_MS)  # no new frame needed: its timer places it
        assert time.monotonic() - t0 >= ov_mod.LOST_DELAY_S and ov.wanted() == "inset"
        qtbot.waitUntil(lambda: ov.picture() is not None, timeout=TIMEOUT_MS)
        assert drawn_on and threading.main_thread() not in drawn_on
        session.last_shown = posed
        ov.place()
        assert not ov.isVisible()  # the pose is back: the inset goes at once
        session.last_shown = lost
        ov.place()
        assert not ov.isVisible()  # and a new loss waits again
    finally:
        ov.close_renderer()
