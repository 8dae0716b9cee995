"""The desktop app, offscreen (pytest-qt): replay, overlay registration, models, edits, print dialog,
error dialogs, the screenshot flag.

A short synthetic recording with known camera poses is written once per
session by tracking.recording.writer; overlay pixels are checked against
cv2.projectPoints of the model's own vertices at the tracker's pose.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from gui_helpers import N_FRAMES, TIMEOUT_MS, camera_poses, close_main_window, open_main_window, write_arc_recording
from PySide6.QtCore import Qt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"


@pytest.fixture(scope="session")
def recording(tmp_path_factory) -> Path:
    return write_arc_recording(tmp_path_factory.mktemp("gui") / "arc")


@pytest.fixture
def window(qtbot, tmp_path):
    w = open_main_window(qtbot, tmp_path)
    w.full_frames = True  # the checks compare full-size composited frames with the frames as captured
    w.show()
    yield w
    close_main_window(w)


def wait_model(qtbot, w, name: str) -> None:
    qtbot.waitUntil(lambda: w.model is not None and Path(w.model_path).name == name, timeout=TIMEOUT_MS)


def wait_frames(qtbot, w, n: int) -> None:
    start = w.frames_painted
    qtbot.waitUntil(lambda: w.frames_painted >= start + n, timeout=TIMEOUT_MS)


def overlay_mask(shown) -> np.ndarray:
    """Pixels the overlay changed: composited frame against the frame as captured."""
    diff = np.abs(shown.result.image.astype(np.int16) - shown.frame.astype(np.int16)).max(axis=2)
    return diff > 12


def projected_mask(w, shown, model=None) -> tuple[np.ndarray, np.ndarray]:
    """Filled silhouette of the displayed mesh by cv2.projectPoints at the pose the frame was drawn with,
    and the projected vertices (`model`: the model as placed, default the window's)."""
    from arapp.geometry.placement import world_from_model
    from tracking.poses import invert

    info = w.source_info
    mesh = w.mesh_lines[0]
    wfm = world_from_model(info.anchors[0], w.model if model is None else model)
    cfm = invert(shown.result.world_from_camera) @ wfm  # a similarity (model units -> metres)
    in_camera = np.asarray(mesh.vertices, float) @ cfm[:3, :3].T + cfm[:3, 3]
    assert in_camera[:, 2].min() > 0.05
    pts, _ = cv2.projectPoints(in_camera, np.zeros(3), np.zeros(3), info.camera.K, info.camera.dist)
    pts = pts.reshape(-1, 2)
    mask = np.zeros(shown.frame.shape[:2], np.uint8)
    tri = np.round(pts[np.asarray(mesh.faces)] * 16).astype(np.int32)
    for t in tri:
        cv2.fillConvexPoly(mask, t, 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool), pts


def shows_current_model(w, faces: int) -> bool:
    """The newest painted frame was drawn with the window's latest model request, of that many triangles."""
    s = w.last_shown
    return s is not None and s.result.extra["model_gen"] == w.model_gen and s.result.extra["mesh_faces"] == faces


def assert_fits_view(w) -> None:
    """The painted image has the recording's aspect and fills the view along one side."""
    q = w.view.image()
    assert q is not None
    assert abs(q.width() / q.height() - 640 / 480) < 0.01
    vw, vh = w.view.width(), w.view.height()
    assert q.width() <= vw + 1 and q.height() <= vh + 1
    assert q.width() >= vw - 2 or q.height() >= vh - 2


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum()) / max(float((a | b).sum()), 1.0)


def test_play_recording_to_the_end(qtbot, window, recording):
    ended = []
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.engine is not None and window.source_info is not None, timeout=TIMEOUT_MS)
    window.engine.ended.connect(lambda: ended.append(True))
    assert window.source_info.seekable and window.source_info.frame_count == N_FRAMES
    qtbot.waitUntil(lambda: bool(ended), timeout=TIMEOUT_MS)
    # latest frame wins, but the last frame is never replaced, so it is the one on screen
    qtbot.waitUntil(lambda: window.last_shown is not None and window.last_shown.result.index == N_FRAMES - 1,
                    timeout=TIMEOUT_MS)
    assert window.frames_painted >= 2
    assert window.last_shown.result.state in ("marker", "slam")
    assert window.replay.slider.value() == N_FRAMES - 1
    assert window.replay.play_button.text() == "Play"
    assert_fits_view(window)
    assert all(lat > 0 for lat in window.latencies_ms)


def test_replay_controls_step_and_seek(qtbot, window, recording):
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.source_info is not None, timeout=TIMEOUT_MS)
    wait_frames(qtbot, window, 1)
    window.toggle_play()  # pause
    assert not window.engine.playing
    window.seek(10)
    qtbot.waitUntil(lambda: window.last_shown.result.index == 10, timeout=TIMEOUT_MS)
    window.step()
    qtbot.waitUntil(lambda: window.last_shown.result.index == 11, timeout=TIMEOUT_MS)
    assert abs(window.last_shown.result.t - 11 / 30.0) < 1e-3
    qtbot.wait(200)
    assert window.last_shown.result.index == 11  # paused: nothing moves on by itself


@pytest.mark.parametrize("engine", ["process", "threads"])
def test_overlay_pixels_where_the_model_projects(qtbot, window, recording, engine):
    window.engine_kind = engine  # the shipped child-process pipeline, and the in-process fallback
    window.open_model(str(MODELS / "sphere.json"))
    wait_model(qtbot, window, "sphere.json")
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.source_info is not None, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: window.last_shown is not None and window.last_shown.result.world_from_camera is not None
                    and overlay_mask(window.last_shown).sum() > 200, timeout=TIMEOUT_MS)
    window.session.pause()
    qtbot.wait(300)  # a frame in flight lands
    shown = window.last_shown
    assert shown.result.world_from_camera is not None
    # the tracker's pose agrees with the true camera pose of that frame
    truth = camera_poses(N_FRAMES)[shown.result.index]
    assert np.linalg.norm(shown.result.world_from_camera[:3, 3] - truth[:3, 3]) < 0.01
    drawn = overlay_mask(shown)
    expected, pts = projected_mask(window, shown)
    assert expected.sum() > 500
    assert iou(drawn, expected) > 0.9
    ys, xs = np.nonzero(drawn)
    ye, xe = np.nonzero(expected)
    assert np.hypot(xs.mean() - xe.mean(), ys.mean() - ye.mean()) < 2.0
    # what is painted is the composited frame, scaled to the view in the worker
    q = window.view.image()
    from PySide6.QtGui import QImage

    rgb = q.convertToFormat(QImage.Format.Format_BGR888)
    painted = np.frombuffer(rgb.constBits(), np.uint8).reshape(rgb.height(), rgb.bytesPerLine())
    painted = painted[:, : 3 * q.width()].reshape(q.height(), q.width(), 3)
    expected_view = cv2.resize(shown.result.image, (q.width(), q.height()), interpolation=cv2.INTER_AREA)
    assert np.abs(painted.astype(int) - expected_view.astype(int)).mean() < 1.0
    assert_fits_view(window)


def test_switch_models(qtbot, window, recording):
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.source_info is not None, timeout=TIMEOUT_MS)
    window.replay.loop.setChecked(True)
    window.open_model(str(MODELS / "sphere.json"))
    wait_model(qtbot, window, "sphere.json")
    sphere_mesh = window.mesh_lines[0]
    window.open_model(str(MODELS / "torus.json"))
    wait_model(qtbot, window, "torus.json")
    torus_mesh = window.mesh_lines[0]
    assert window.model.name in window.model_panel.current.text()
    assert len(torus_mesh.faces) != len(sphere_mesh.faces)
    qtbot.waitUntil(lambda: shows_current_model(window, len(torus_mesh.faces)), timeout=TIMEOUT_MS)

    def torus_drawn():
        s = window.last_shown
        if s is None or s.result.world_from_camera is None or not shows_current_model(window, len(torus_mesh.faces)):
            return False
        return iou(overlay_mask(s), projected_mask(window, s)[0]) > 0.85

    qtbot.waitUntil(torus_drawn, timeout=TIMEOUT_MS)


def test_edit_weight_changes_the_mesh(qtbot, window, recording):
    from arapp.geometry import load_model

    window.open_source(str(recording))
    window.replay.loop.setChecked(True)
    window.open_model(str(MODELS / "rational_5x5.json"))
    wait_model(qtbot, window, "rational_5x5.json")
    panel = window.model_panel
    assert panel.edit_box.isEnabled()
    before = window.mesh_lines[0]
    panel.surface_index.setValue(0)
    panel.u_index.setValue(2)
    panel.v_index.setValue(2)
    original = load_model(MODELS / "rational_5x5.json").surfaces[0]
    assert panel.weight.value() == pytest.approx(original.weights[2, 2])
    target = original.control_points[2, 2]
    panel.weight.setValue(20.0)
    qtbot.waitUntil(lambda: window.mesh_lines[0] is not before, timeout=TIMEOUT_MS)
    after = window.mesh_lines[0]
    assert window.model.surfaces[0].weights[2, 2] == pytest.approx(20.0)
    # raising a weight pulls the surface toward that control point
    d_before = np.linalg.norm(np.asarray(before.vertices) - target, axis=1).min()
    d_after = np.linalg.norm(np.asarray(after.vertices) - target, axis=1).min()
    assert d_after < d_before
    # and the mesh is that of the edited surface: its vertices lie on it (independent evaluation)
    edited = window.model.surfaces[0]
    (u0, u1), (v0, v1) = edited.domain
    uu, vv = np.meshgrid(np.linspace(u0, u1, 60), np.linspace(v0, v1, 60), indexing="ij")
    dense = edited.evaluate(uu.ravel(), vv.ravel())
    sample = np.asarray(after.vertices)[:: max(1, len(after.vertices) // 200)]
    gap = np.array([np.linalg.norm(dense - p, axis=1).min() for p in sample])
    assert gap.max() < 0.15
    # the live view draws the edited surface: overlay pixels where the edited mesh projects
    qtbot.waitUntil(lambda: shows_current_model(window, len(after.faces)), timeout=TIMEOUT_MS)

    def edited_drawn():
        s = window.last_shown
        if s is None or s.result.world_from_camera is None or not shows_current_model(window, len(after.faces)):
            return False
        return iou(overlay_mask(s), projected_mask(window, s)[0]) > 0.85

    qtbot.waitUntil(edited_drawn, timeout=TIMEOUT_MS)


def test_print_dialog_opens_with_the_placed_model(qtbot, window):
    window.open_model(str(MODELS / "sphere.json"))
    wait_model(qtbot, window, "sphere.json")
    window.model_panel.size.setValue(40.0)
    assert window.placement.size_mm == 40.0
    qtbot.keyClick(window, Qt.Key.Key_P)
    dlg = window._print_dialog
    assert dlg is not None and dlg.isVisible()
    assert dlg.placement.size_mm == 40.0
    qtbot.waitUntil(lambda: dlg.solid is not None, timeout=TIMEOUT_MS)
    from arapp.printing import load_profile

    ext = dlg.solid.extents
    assert ext[0] == pytest.approx(40.0, rel=0.02) and ext[1] == pytest.approx(40.0, rel=0.02)
    assert dlg.solid.bounds[0][2] == pytest.approx(0.0, abs=1e-6)
    cx, cy = load_profile().bed_center
    assert dlg.solid.bounds.mean(axis=0)[:2] == pytest.approx([cx, cy], abs=0.5)
    assert dlg.solid.is_watertight
    dlg.close()


def test_corrupt_model_file_gives_its_dialog(qtbot, window, tmp_path):
    from arapp.geometry import load_model

    bad = tmp_path / "bad.json"
    data = json.loads((MODELS / "rational_5x5.json").read_text())
    text = json.dumps(data).replace("[0, 1, 2, 3, 4, 5, 6, 7]", "[0, 1, 0.5, 3, 4, 5, 6, 7]", 1)
    bad.write_text(text if text != json.dumps(data) else "{ not json")
    with pytest.raises(ValueError) as expected:
        load_model(bad)
    window.open_model(str(bad))
    qtbot.waitUntil(lambda: len(window.errors) > 0, timeout=TIMEOUT_MS)
    title, message = window.errors[-1]
    assert title == "Cannot open the model"
    assert message == str(expected.value)
    boxes = window.open_error_boxes()
    assert len(boxes) == 1 and boxes[0].isVisible() and boxes[0].text() == message
    assert window.model is None  # nothing half-loaded
    boxes[0].accept()
    qtbot.waitUntil(lambda: not window.open_error_boxes(), timeout=5000)


def test_missing_camera_gives_its_dialog(qtbot, window):
    from arapp.engine.sourcespec import open_spec

    spec = "v4l2:/dev/video63"
    with pytest.raises((ValueError, OSError, RuntimeError)) as expected:
        open_spec(spec)
    window.open_source(spec)
    qtbot.waitUntil(lambda: len(window.errors) > 0, timeout=TIMEOUT_MS)
    title, message = window.errors[-1]
    assert title == "Cannot open source"
    assert message == str(expected.value)
    assert window.open_error_boxes()[0].text() == message
    qtbot.waitUntil(lambda: window.engine is None or not window.engine.running, timeout=5000)


def test_shortcuts_and_settings(qtbot, window, recording, tmp_path):
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.source_info is not None, timeout=TIMEOUT_MS)
    wait_frames(qtbot, window, 1)
    assert window.engine.playing
    qtbot.keyClick(window, Qt.Key.Key_Space)
    assert not window.engine.playing
    qtbot.keyClick(window, Qt.Key.Key_Space)
    assert window.engine.playing
    qtbot.keyClick(window, Qt.Key.Key_R)
    qtbot.waitUntil(lambda: window.last_shown.result.extra["resets"] == 1, timeout=TIMEOUT_MS)
    window.model_panel.mode.setCurrentText("wireframe")
    assert window.settings.value("mode") == "wireframe"
    assert window.session.recent("recent_sources")[0] == str(recording)
    qtbot.waitUntil(lambda: window.last_shown.result.extra["mode"] == "wireframe", timeout=TIMEOUT_MS)


def test_screenshot_flag(recording, tmp_path):
    out = tmp_path / "shot.png"
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYOPENGL_PLATFORM="egl",
               XDG_CONFIG_HOME=str(tmp_path / "config"))
    proc = subprocess.run([sys.executable, "-m", "arapp", "gui", "--source", str(recording), "--model",
                           str(MODELS / "sphere.json"), "--frames", "5", "--screenshot", str(out)],
                          capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 300 and img.shape[1] > 600
    assert img.std() > 10  # a real picture, not a blank window


def test_screenshot_flag_reports_a_bad_source(tmp_path):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", XDG_CONFIG_HOME=str(tmp_path / "config"))
    proc = subprocess.run([sys.executable, "-m", "arapp", "gui", "--source", str(tmp_path / "nothing"),
                           "--frames", "3", "--screenshot", str(tmp_path / "x.png")],
                          capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    assert proc.returncode != 0
    assert "nothing" in proc.stderr


def test_print_dialog_slices_saves_and_reports_a_printer_error(qtbot, window, tmp_path):
    from arapp.printing import read_stats

    window.open_model(str(MODELS / "sphere.json"))
    wait_model(qtbot, window, "sphere.json")
    window.model_panel.size.setValue(20.0)
    window.open_print_dialog()
    dlg = window._print_dialog
    dlg.work_dir = tmp_path / "jobs"
    dlg.layer_height.setValue(0.3)
    dlg.infill.setValue(10)
    progress = []
    dlg.slice_progress.valueChanged.connect(progress.append)
    qtbot.mouseClick(dlg.slice_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dlg.result is not None, timeout=TIMEOUT_MS)
    assert progress[-1] == 1000 and len(progress) >= 2
    assert dlg.result.layers == round(20.0 / 0.3)  # a 20 mm sphere in 0.3 mm layers
    assert dlg.send_button.isEnabled() and dlg.save_button.isEnabled()
    out = dlg.save_gcode(str(tmp_path / "sphere.gcode"))
    text = Path(out).read_text()
    assert text == dlg.result.gcode and read_stats(text)
    # a printer that is not there: the link's own message in a dialog, no crash
    dlg.use_serial.setChecked(True)
    dlg.port.setCurrentText(str(tmp_path / "ttyNOPE"))
    qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: any(t == "Printer error" for t, _ in window.errors), timeout=TIMEOUT_MS)
    message = [m for t, m in window.errors if t == "Printer error"][-1]
    assert "ttyNOPE" in message
    qtbot.waitUntil(lambda: dlg.send_button.isEnabled(), timeout=5000)
    # a target the dialog cannot make (a baud rate that is not a number): told to the user, nothing started
    dlg.baud.setCurrentText("fast")
    qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
    assert any(t == "Printer error" and "baud rate" in m for t, m in window.errors) and not dlg.printing
    dlg.close()


def test_source_picker_lists_cameras_and_opens_a_recent_source(qtbot, window, recording):
    from arapp.gui.source_dialog import SourceDialog
    from arapp.engine.sourcespec import list_devices
    from tracking.sources import list_depthai, list_v4l2

    expected = [d["spec"] for d in list_v4l2()] + [d["spec"] for d in list_depthai()]
    assert [spec for spec, _ in list_devices()] == expected
    dlg = SourceDialog([str(recording)], window)
    qtbot.addWidget(dlg)
    listed = []
    dlg.devices_listed.connect(listed.append)
    qtbot.waitUntil(lambda: bool(listed), timeout=TIMEOUT_MS)
    assert dlg.devices.count() == len(expected)
    if not expected:
        assert "No V4L2 or DepthAI camera" in dlg.status.text()
    chosen = []
    dlg.source_chosen.connect(chosen.append)
    dlg.recent.setCurrentRow(0)
    dlg._pick(dlg.recent.currentItem())
    assert chosen == [str(recording)]


def test_drag_and_drop_opens_models_and_recordings(qtbot, window, recording):
    from PySide6.QtCore import QMimeData, QPointF, QUrl
    from PySide6.QtGui import QDropEvent

    def drop(path):
        mime = QMimeData()
        mime.setUrls([QUrl.fromLocalFile(str(path))])
        event = QDropEvent(QPointF(10, 10), Qt.DropAction.CopyAction, mime, Qt.MouseButton.NoButton,
                           Qt.KeyboardModifier.NoModifier)
        window.dropEvent(event)

    drop(MODELS / "torus.json")
    wait_model(qtbot, window, "torus.json")
    drop(recording / "session.json")
    qtbot.waitUntil(lambda: window.source_info is not None and window.source_info.frame_count == N_FRAMES,
                    timeout=TIMEOUT_MS)


def test_no_control_point_is_ringed_until_one_is_picked(qtbot, window):
    """A model just opened shows its first control point in the fields, but rings none in the view (the
    panel used to announce that first point as picked, and every frame was drawn with a ring on it)."""
    window.open_model(str(MODELS / "rational_5x5.json"))
    wait_model(qtbot, window, "rational_5x5.json")
    panel = window.model_panel
    assert panel.selected() == (0, 0, 0) and window.session.highlight is None
    panel.u_index.setValue(2)
    assert window.session.highlight == (0, 2, 0)
    panel.u_index.setValue(0)   # back to the first point: picked now, so ringed
    assert window.session.highlight == (0, 0, 0)
    window.open_model(str(MODELS / "vase.json"))   # another model: nothing picked on it yet
    wait_model(qtbot, window, "vase.json")
    assert window.session.highlight is None


def test_selected_control_point_is_ringed_in_the_view(qtbot, window, recording):
    from arapp.geometry.placement import world_from_model
    from tracking.poses import invert

    window.open_source(str(recording))
    window.replay.loop.setChecked(True)
    window.open_model(str(MODELS / "rational_5x5.json"))
    wait_model(qtbot, window, "rational_5x5.json")
    qtbot.waitUntil(lambda: shows_current_model(window, len(window.mesh_lines[0].faces))
                    and window.last_shown.result.world_from_camera is not None, timeout=TIMEOUT_MS)
    window.session.pause()
    panel = window.model_panel
    panel.u_index.setValue(4)
    panel.v_index.setValue(4)
    from PySide6.QtGui import QColor

    def ring_colour():
        """The painted view's colour where the corner control point projects in the frame shown."""
        shown = window.last_shown
        info = window.source_info
        p = np.append(window.model.surfaces[0].control_points[4, 4], 1.0)
        cam = (invert(shown.result.world_from_camera) @ world_from_model(info.anchors[0], window.model) @ p)[:3]
        uv = info.camera.project(cam[None, :]).reshape(-1)
        q = window.view.image()
        s = q.width() / info.camera.width
        colour = QColor(q.pixel(int(round(uv[0] * s)), int(round(uv[1] * s))))
        return (colour.red(), colour.green(), colour.blue()), shown, uv

    # the paused frame is drawn again with the ring (BGR 0, 240, 255) once the selection reaches the engine
    # (under load that takes a moment)
    qtbot.waitUntil(lambda: ring_colour()[0] == pytest.approx((255, 240, 0), abs=40), timeout=10000)
    colour, shown, uv = ring_colour()
    assert colour == pytest.approx((255, 240, 0), abs=40)
    # and the full-size composite the pipeline made is untouched by the ring
    assert not np.all(shown.result.image[int(uv[1]), int(uv[0])] == (0, 240, 255))


def test_dragging_on_the_view_places_the_model(qtbot, window, recording):
    """Drag moves the model on the marker under the pointer, Shift+drag turns it, the wheel scales it;
    the fields follow and the view draws it there."""
    from PySide6.QtCore import QPoint, QPointF
    from PySide6.QtGui import QWheelEvent

    from arapp.geometry.placement import world_from_placement

    window.open_source(str(recording))
    window.open_model(str(MODELS / "sphere.json"))
    wait_model(qtbot, window, "sphere.json")
    qtbot.waitUntil(lambda: window.last_shown is not None and window.last_shown.result.world_from_camera is not None
                    and overlay_mask(window.last_shown).sum() > 200, timeout=TIMEOUT_MS)
    window.session.pause()
    qtbot.wait(300)
    shown = window.last_shown
    info = window.source_info
    T = world_from_placement(info.anchors[0])
    start = window.placement
    view = window.view

    def widget_pos(x_mm, y_mm) -> QPoint:
        """Where the paper point (x, y) mm of the placement frame shows in the view (cv2.projectPoints)."""
        X = (T @ np.array([x_mm / 1000, y_mm / 1000, 0.0, 1.0]))[:3]
        cw = np.linalg.inv(shown.result.world_from_camera)
        uv, _ = cv2.projectPoints(X[None], cv2.Rodrigues(cw[:3, :3])[0], cw[:3, 3], info.camera.K, info.camera.dist)
        u, v = uv.ravel()
        rect = view.image_rect()
        return QPoint(round(rect.x() + (u + 0.5) / info.camera.width * rect.width()),
                      round(rect.y() + (v + 0.5) / info.camera.height * rect.height()))

    latencies = len(window.latencies_ms)
    # drag from the model's foot 25 mm along the marker's x: the offset follows the pointer
    qtbot.mousePress(view, Qt.MouseButton.LeftButton, pos=widget_pos(0, 0))
    qtbot.mouseMove(view, widget_pos(12, 0))
    qtbot.mouseMove(view, widget_pos(25, 0))
    qtbot.mouseRelease(view, Qt.MouseButton.LeftButton, pos=widget_pos(25, 0))
    # a widget pixel is about 0.5 mm on the paper here
    assert window.placement.offset[0] == pytest.approx(start.offset[0] + 25.0, abs=1.5)
    assert window.placement.offset[1] == pytest.approx(start.offset[1], abs=1.5)
    assert window.model_panel.offset[0].value() == pytest.approx(window.placement.offset[0], abs=0.06)
    # the drawn model moved with it: the overlay's centre is where the new foot projects (within a few px)
    qtbot.waitUntil(lambda: window.last_shown is not shown, timeout=TIMEOUT_MS)
    qtbot.wait(300)
    import dataclasses

    placed = dataclasses.replace(window.model, placement=window.placement)
    drawn = overlay_mask(window.last_shown)
    expected, _ = projected_mask(window, window.last_shown, placed)
    assert iou(drawn, expected) > 0.85
    # the paused frame drawn again is not a capture-to-paint latency
    assert len(window.latencies_ms) == latencies
    # Shift+drag a quarter turn around the model
    x0 = window.placement.offset[0]
    rz0 = window.placement.rotation_deg[2]
    qtbot.mousePress(view, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ShiftModifier, widget_pos(x0 + 30, 0))
    qtbot.mouseMove(view, widget_pos(x0, 30))
    qtbot.mouseRelease(view, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ShiftModifier, widget_pos(x0, 30))
    assert window.placement.rotation_deg[2] == pytest.approx(rz0 + 90.0, abs=3.0)
    assert window.placement.offset[0] == pytest.approx(x0, abs=1e-9)
    # two wheel notches away from the user: 1.1^2 times the size
    size0 = window.placement.size_mm
    pos = QPointF(widget_pos(x0, 0))
    ev = QWheelEvent(pos, view.mapToGlobal(pos), QPoint(0, 0), QPoint(0, 240), Qt.MouseButton.NoButton,
                     Qt.KeyboardModifier.NoModifier, Qt.ScrollPhase.NoScrollPhase, False)
    view.wheelEvent(ev)
    assert window.placement.size_mm == pytest.approx(size0 * 1.21, rel=1e-6)
    assert window.model_panel.size.value() == pytest.approx(size0 * 1.21, abs=0.06)
