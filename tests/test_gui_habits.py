"""Saving and habits in the desktop app (pytest-qt, offscreen): undo/redo, export, screenshot, AR video,
controls enabled only when they can act, a failed source, the window title, plain words.

Oracles: the model file (control points read from its JSON), trimesh reading the
exported files back against the model's own vertices mapped by its placement
rule, OpenCV reading the screenshot and the video, the recording's true camera
poses with cv2.projectPoints of the placed model's bounding box (where the AR
video must differ from the raw frames, and where it must not).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

from gui_helpers import N_FRAMES, TIMEOUT_MS, camera_poses, open_main_window, write_arc_recording
from PySide6.QtCore import Qt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    return write_arc_recording(tmp_path_factory.mktemp("habits") / "arc")


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # default captures/ and recordings/ land here
    w = open_main_window(qtbot, tmp_path)
    w.full_frames = True
    w.error_sink = lambda title, message: None  # errors are checked in w.errors, no boxes
    w.show()
    yield w
    w.close()


def load(qtbot, w, name: str) -> None:
    w.open_model(str(MODELS / name))
    qtbot.waitUntil(lambda: w.model is not None and Path(w.model_path).name == name, timeout=TIMEOUT_MS)


def file_point(name: str, i: int, j: int) -> np.ndarray:
    data = json.loads((MODELS / name).read_text())
    return np.array(data["surfaces"][0]["control_points"][i][j], float)


def placed_bounds_mm(model, placement) -> np.ndarray:
    """The model's own tessellated vertices mapped by its placement rule (largest extent = size_mm)."""
    import copy

    m = copy.copy(model)
    m.placement = placement
    v = np.asarray(model.mesh().vertices, float)
    M = m.placement_matrix("mm")
    v = v @ M[:3, :3].T + M[:3, 3]
    return np.array([v.min(axis=0), v.max(axis=0)])


# -- controls that cannot act, a failed source --------------------------------------------------------
def test_controls_disabled_with_nothing_loaded_and_p_opens_no_error(qtbot, window):
    w = window
    assert not w.replay.play_button.isEnabled()
    assert not w.replay.record_button.isEnabled()
    assert not w.play_action.isEnabled() and not w.reset_action.isEnabled()
    assert not w.tracking_panel.reset_button.isEnabled()
    assert not w.print_action.isEnabled() and not w.model_panel.print_button.isEnabled()
    assert not w.model_panel.size.isEnabled() and not w.model_panel.offset[0].isEnabled()
    h = w.habits
    assert not h.undo_action.isEnabled() and not h.export_action.isEnabled()
    assert not h.screenshot_action.isEnabled() and not h.record_ar_action.isEnabled()
    qtbot.keyClick(w, Qt.Key.Key_P)
    qtbot.wait(100)
    assert w.errors == [] and w._print_dialog is None
    load(qtbot, w, "sphere.json")
    assert w.print_action.isEnabled() and w.model_panel.size.isEnabled() and h.export_action.isEnabled()
    assert not w.replay.play_button.isEnabled()  # still no source


def test_failed_source_resets_and_stays_out_of_recent(qtbot, window, tmp_path, recording):
    w = window
    bad = str(tmp_path / "no-such-recording")
    w.open_source(bad)
    qtbot.waitUntil(lambda: len(w.errors) > 0, timeout=TIMEOUT_MS)
    qtbot.waitUntil(lambda: w.engine is None, timeout=5000)
    assert "Opening" not in w.view.message and "opening" not in w.status_source.text()
    assert w.replay.play_button.text() == "Play" and not w.replay.play_button.isEnabled()
    assert bad not in w.session.recent("recent_sources")
    assert "no-such-recording" not in w.windowTitle()
    w.open_source(str(recording))  # a source that opens goes into Recent
    qtbot.waitUntil(lambda: w.source_info is not None, timeout=TIMEOUT_MS)
    assert w.session.recent("recent_sources") == [str(recording)]
    assert w.replay.play_button.isEnabled()


def test_a_source_that_fails_after_another_leaves_no_figures_of_the_first(qtbot, window, tmp_path, recording):
    """The tracking panel and the status bar kept showing the last source's state and frame rate ("marker",
    12 anchors, 4 fps) after a camera that does not exist failed to open."""
    w = window
    w.open_source(str(recording))
    qtbot.waitUntil(lambda: w.tracking_panel.state.text() != "-", timeout=TIMEOUT_MS)
    w.open_source(str(tmp_path / "no-such-recording"))
    qtbot.waitUntil(lambda: len(w.errors) > 0 and w.engine is None, timeout=TIMEOUT_MS)
    qtbot.wait(600)   # the status refresh runs on a timer: it must not bring the old figures back
    assert w.session.last_shown is None
    assert w.tracking_panel.state.text() == "-" and w.tracking_panel.fps.text() == "-"
    assert w.status_state.text() == "" and w.status_fps.text() == ""


# -- undo / redo ----------------------------------------------------------------------------------------
def test_undo_redo_placement_and_control_point_by_keyboard(qtbot, window):
    w = window
    load(qtbot, w, "rational_5x5.json")
    p0 = w.placement
    w.model_panel.size.setValue(80.0)
    assert w.placement.size_mm == 80.0
    xyz0 = file_point("rational_5x5.json", 0, 0)
    w.model_panel.position[2].setValue(float(xyz0[2]) + 2.0)
    qtbot.waitUntil(lambda: np.isclose(w.model.surfaces[0].control_points[0, 0][2], xyz0[2] + 2.0), timeout=TIMEOUT_MS)
    qtbot.keyClick(w, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    qtbot.waitUntil(lambda: np.allclose(w.model.surfaces[0].control_points[0, 0], xyz0), timeout=TIMEOUT_MS)
    assert w.model_panel.position[2].value() == pytest.approx(xyz0[2])  # the field shows the restored point
    assert w.placement.size_mm == 80.0
    qtbot.keyClick(w, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    assert w.placement == p0 and w.model_panel.size.value() == pytest.approx(p0.size_mm)
    assert not w.habits.undo_action.isEnabled() and w.habits.redo_action.isEnabled()
    qtbot.keyClick(w, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    assert w.placement.size_mm == 80.0
    qtbot.keyClick(w, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    qtbot.waitUntil(lambda: np.isclose(w.model.surfaces[0].control_points[0, 0][2], xyz0[2] + 2.0), timeout=TIMEOUT_MS)


# -- export ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".stl", ".3mf", ".obj"])
def test_export_mesh_has_the_placed_models_size(qtbot, window, tmp_path, suffix):
    w = window
    load(qtbot, w, "rational_5x5.json")
    w.model_panel.size.setValue(60.0)
    xyz0 = file_point("rational_5x5.json", 2, 2)
    w.model_panel.u_index.setValue(2)
    w.model_panel.v_index.setValue(2)
    w.model_panel.position[2].setValue(float(xyz0[2]) + 1.5)
    qtbot.waitUntil(lambda: (0, 2, 2) in w.edits and w.session.model is not w.session.base_model, timeout=TIMEOUT_MS)
    qtbot.wait(200)
    target = tmp_path / f"out{suffix}"
    w.habits.ask_path = lambda *a: str(target)
    w.habits.export_action.trigger()
    assert w.errors == [] and target.is_file()
    mesh = trimesh.load(target, force="mesh")
    got = mesh.bounds
    want = placed_bounds_mm(w.model, w.placement)
    # the open surface is closed with a 2 mm wall: each side grows by up to the wall
    assert np.all(np.abs(got - want) <= 2.5), (got, want)
    assert max(mesh.extents) == pytest.approx(60.0, abs=4.0)


def test_export_json_keeps_the_edits(qtbot, window, tmp_path):
    from arapp.geometry import load_model

    w = window
    load(qtbot, w, "rational_5x5.json")
    xyz0 = file_point("rational_5x5.json", 0, 0)
    w.model_panel.position[0].setValue(float(xyz0[0]) - 0.75)
    qtbot.waitUntil(lambda: np.isclose(w.model.surfaces[0].control_points[0, 0][0], xyz0[0] - 0.75), timeout=TIMEOUT_MS)
    target = tmp_path / "edited.json"
    w.habits.ask_path = lambda *a: str(target)
    w.habits.export_action.trigger()
    back = load_model(target)
    assert back.units == "cm" and back.name == "Rational 5x5 net"
    assert np.allclose(back.surfaces[0].control_points[0, 0], xyz0 + [-0.75, 0, 0])
    original = load_model(MODELS / "rational_5x5.json")
    assert np.allclose(back.surfaces[0].control_points[1:], original.surfaces[0].control_points[1:])


# -- screenshot, AR video, title, words -------------------------------------------------------------------
def overlay_px(image: np.ndarray, raw: np.ndarray) -> np.ndarray:
    return np.abs(image.astype(np.int16) - raw.astype(np.int16)).max(axis=2) > 40


def test_screenshot_is_the_composited_view(qtbot, window, recording, tmp_path):
    w = window
    w.engine_kind = "threads"
    load(qtbot, w, "sphere.json")
    w.open_source(str(recording))
    qtbot.waitUntil(lambda: w.last_shown is not None and w.last_shown.result.world_from_camera is not None
                    and overlay_px(w.last_shown.result.image, w.last_shown.frame).sum() > 500, timeout=TIMEOUT_MS)
    w.session.pause()
    qtbot.wait(300)
    shown = w.last_shown
    target = tmp_path / "shot.png"
    w.habits.ask_path = lambda *a: str(target)
    assert w.habits.screenshot_action.isEnabled()
    w.habits.screenshot_action.trigger()
    image = cv2.imread(str(target))
    assert image is not None and image.shape == shown.frame.shape
    assert overlay_px(image, shown.frame).sum() > 500  # the model is in it, not only the camera
    assert np.array_equal(image, shown.result.image)


def projected_box_mask(model, anchor, camera, world_from_camera, shape) -> np.ndarray:
    """The convex hull of the placed model's bounding box corners, projected with cv2.projectPoints."""
    from arapp.geometry.placement import world_from_model
    from tracking.poses import invert

    lo, hi = np.asarray(model.bounds()[0], float), np.asarray(model.bounds()[1], float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    cfm = invert(world_from_camera) @ world_from_model(anchor, model)
    pts, _ = cv2.projectPoints(corners @ cfm[:3, :3].T + cfm[:3, 3], np.zeros(3), np.zeros(3), camera.K, camera.dist)
    mask = np.zeros(shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, cv2.convexHull(pts.reshape(-1, 2).astype(np.int32)), 1)
    return mask.astype(bool)


def test_ar_video_has_the_model_drawn(qtbot, window, recording, tmp_path):
    from tracking.sources import open_source

    w = window  # the shipped child-process engine: the video is written there
    load(qtbot, w, "sphere.json")
    w.replay.loop.setChecked(True)
    w.open_source(str(recording))
    qtbot.waitUntil(lambda: w.source_info is not None and w.habits.record_ar_action.isEnabled(), timeout=TIMEOUT_MS)
    target = tmp_path / "ar.mp4"
    w.habits.ask_path = lambda *a: str(target)
    w.habits.record_ar_action.trigger()
    assert w.session.ar_video_path == target and "recording AR video" in w.windowTitle()
    start = w.frames_painted
    qtbot.waitUntil(lambda: w.frames_painted >= start + 30, timeout=TIMEOUT_MS)
    done = []
    w.session.events.recorded.connect(done.append)
    w.habits.record_ar_action.trigger()
    qtbot.waitUntil(lambda: bool(done), timeout=TIMEOUT_MS)
    assert done == [str(target)] and str(target) not in w.session.recent("recent_sources")

    src = open_source(str(recording))
    raws = [f.image.copy() for f in src]
    src.close()
    info, model = w.source_info, w.model
    cap = cv2.VideoCapture(str(target))
    frames = []
    while True:
        ok, image = cap.read()
        if not ok:
            break
        frames.append(image)
    cap.release()
    assert len(frames) >= 10
    poses = camera_poses(N_FRAMES)
    checked, covered = 0, []
    for image in frames[:: max(1, len(frames) // 12)]:
        assert image.shape == raws[0].shape
        # which recorded frame it is: the raw frame it matches best (the overlay covers a small part)
        k = int(np.argmin([np.abs(image.astype(np.int16) - r.astype(np.int16)).mean() for r in raws]))
        box = projected_box_mask(model, info.anchors[0], info.camera, poses[k], image.shape)
        drawn = overlay_px(image, raws[k])
        assert box.sum() > 1000
        covered.append(drawn[box].mean())
        assert drawn[~cv2.dilate(box.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)].mean() < 0.01  # only there
        checked += 1
    assert checked >= 5
    # the model is drawn inside its projected box; a frame where the looping replay starts over, before the
    # tracker has its first pose again, has no overlay (as on screen), so most frames, not all, must show it
    assert np.mean(np.array(covered) > 0.3) >= 0.75, covered


def test_title_units_and_plain_words(qtbot, window, recording):
    w = window
    assert w.windowTitle() == "arapp"
    load(qtbot, w, "rational_5x5.json")
    assert "Rational 5x5 net" in w.windowTitle() and "DOMAIN" not in w.windowTitle()
    assert w.model_panel.position[0].suffix().strip() == "cm"  # this model's control points are in cm
    assert w.model_panel.size.suffix().strip() == "mm"
    item = next(w.model_panel.library.item(i) for i in range(w.model_panel.library.count())
                if w.model_panel.library.item(i).text() == "rational_5x5")
    assert item.isSelected() and item.font().bold()
    w.model_panel.size.setValue(70.0)
    assert "(edited)" not in w.windowTitle()
    w.open_source(str(recording))
    qtbot.waitUntil(lambda: w.source_info is not None, timeout=TIMEOUT_MS)
    assert w.windowTitle().startswith(w.source_info.name)
    from PySide6.QtWidgets import QLabel

    words = " ".join(lbl.text() for lbl in w.tracking_panel.findChildren(QLabel))
    assert "Inliers" not in words and "Track / render" not in words


# -- print: beside the preview, real size, fit, one format -------------------------------------------------
def rect_in_window(w, widget):
    from PySide6.QtCore import QRect

    return QRect(widget.mapTo(w, widget.rect().topLeft()), widget.size())


def test_print_panel_beside_the_view_with_the_solids_real_size(qtbot, window):
    w = window
    w.resize(1366, 768)
    load(qtbot, w, "rational_5x5.json")
    qtbot.keyClick(w, Qt.Key.Key_P)
    dlg = w._print_dialog
    assert dlg is not None and dlg.isVisible() and w.print_dock.isVisible()
    assert not rect_in_window(w, w.print_dock).intersects(rect_in_window(w, w.view))  # the preview stays visible
    qtbot.waitUntil(lambda: dlg.solid is not None, timeout=TIMEOUT_MS)
    x, y, z = dlg.solid.extents
    assert f"{x:.1f} x {y:.1f} x {z:.1f} mm" in dlg.solid_label.text()
    assert "as placed" not in dlg.model_label.text()
    assert not dlg.fit_button.isVisible() and dlg.slice_button.isEnabled()
    dlg.close()
    assert not w.print_dock.isVisible()


def test_too_big_for_the_bed_is_caught_before_slicing_and_scaled_to_fit(qtbot, window):
    from arapp.printing import load_profile

    w = window
    load(qtbot, w, "sphere.json")
    w.model_panel.size.setValue(400.0)
    w.open_print_dialog()
    dlg = w._print_dialog
    qtbot.waitUntil(lambda: dlg.solid is not None, timeout=TIMEOUT_MS)
    assert dlg.fit_button.isVisible() and not dlg.slice_button.isEnabled()
    assert "larger than the bed" in dlg.fit_label.text() and "--" not in dlg.fit_label.text()  # no CLI flags
    dlg.fit_button.click()
    qtbot.waitUntil(lambda: dlg.solid is not None, timeout=TIMEOUT_MS)
    bed = load_profile(dlg.profile_key()).bed
    ext = dlg.solid.extents
    assert ext[0] <= bed.width and ext[1] <= bed.depth and ext[2] <= bed.height
    assert max(ext) > 0.9 * min(bed.width, bed.depth, bed.height) - 20  # shrunk to fit, not to nothing
    assert w.placement.size_mm == pytest.approx(dlg.placement.size_mm)  # the AR view shows what is printed
    assert not dlg.fit_button.isVisible() and dlg.slice_button.isEnabled()
    dlg.close()


def test_one_time_format():
    from arapp.app.printlink import format_duration_s
    from arapp.printing.gcode import format_duration

    assert format_duration(48 * 60) == "48 min 0 s" and format_duration_s(48 * 60) == "48 min 0 s"
    assert format_duration_s(6 * 60 + 19) == "6 min 19 s"
    assert format_duration(3 * 3600 + 5 * 60 + 9) == "3 h 05 min" and format_duration_s(None) == "?"


def test_temperature_graph_has_a_time_axis_and_readings_off_the_lines(qtbot):
    from PySide6.QtGui import QColor, QImage

    from arapp.gui.print.temperature_graph import TemperatureGraph, time_ticks

    g = TemperatureGraph()
    qtbot.addWidget(g)
    g.resize(420, 150)
    for k in range(121):  # two minutes at the target: the target line and the readings' row
        g.add({"hotend": (200.0, 200.0), "bed": (60.0, 60.0)}, t=float(k))
    img = g.grab().toImage().convertToFormat(QImage.Format.Format_RGB888)
    arr = np.frombuffer(img.constBits(), np.uint8).reshape(img.height(), img.bytesPerLine())[:, : 3 * img.width()]
    arr = arr.reshape(img.height(), img.width(), 3).astype(int)
    hot = QColor(TemperatureGraph.SERIES["hotend"])
    near = np.abs(arr - [hot.red(), hot.green(), hot.blue()]).max(axis=2) < 40
    rows = np.nonzero(near[:, TemperatureGraph.LEFT + 150:].any(axis=1))[0]  # right of the readings' text
    line_y = TemperatureGraph.TOP + (150 - TemperatureGraph.TOP - TemperatureGraph.BOTTOM) * (1 - 200 / (200 * 1.1))
    assert rows.size and abs(rows.mean() - line_y) < 3  # the hotend lines lie where 200 °C is ...
    assert rows.min() > TemperatureGraph.TOP  # ... below the readings, not under them
    bottom = arr[150 - TemperatureGraph.BOTTOM + 2:, TemperatureGraph.LEFT:]
    assert (np.abs(bottom - 250).max(axis=2) > 60).sum() > 30  # the time axis labels are drawn
    assert [t for t, _ in time_ticks(120.0)] == [0.0, 30.0, 60.0, 90.0, 120.0]
    assert time_ticks(300.0)[-1] == (300.0, "-5 min")


def test_bed_preview_draws_the_model_as_a_ghost():
    from arapp.app.session import GHOST_MODE, Session, read_model

    sent = []

    class Engine:
        running = playing = False

        def send(self, c):
            sent.append(c)

        def start(self):
            pass

        def stop(self, wait=0.0):
            pass

    s = Session(lambda *a, **k: Engine())
    notes = []
    s.events.status.connect(lambda text, ms: notes.append(text))
    s.open_source("recording-that-is-never-read")
    model, mesh_lines = read_model(str(MODELS / "sphere.json"))
    s.set_model(model, mesh_lines, str(MODELS / "sphere.json"))
    assert sent[-1].mode == "shaded"
    s.set_toolpaths({"gcode_path": "x.gcode"})
    modes = [c.mode for c in sent if type(c).__name__ == "SetMode"]
    assert modes[-1] == GHOST_MODE and any("see-through" in n for n in notes)
    s.edit_control_point(0, 1, 1, tuple(model.surfaces[0].control_points[1, 1]), 2.0)
    assert [c for c in sent if type(c).__name__ == "SetModel"][-1].mode == GHOST_MODE  # an edit keeps the ghost
    s.set_toolpaths(None)
    assert [c.mode for c in sent if type(c).__name__ == "SetMode"][-1] == GHOST_MODE  # until the bed is clear
    s._toolpaths_shown({"gen": s.toolpaths_gen, "layers": 0})  # the engine: the preview is cleared
    assert [c.mode for c in sent if type(c).__name__ == "SetMode"][-1] == "shaded"


def test_anchors_editor_says_its_lengths_in_mm(qtbot):
    from arapp.gui.panels.tracking import AnchorsDialog

    d = AnchorsDialog([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 40, "length": 0.05}])
    qtbot.addWidget(d)
    assert "50 mm" in d.in_mm.text() and "40" in d.in_mm.text()
    d.text.setPlainText('[{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.12}]')
    assert "120 mm" in d.in_mm.text()
