"""The print dialog printing for real and the AR print preview in the live view (pytest-qt, offscreen).

Prints go to OctoPrint's VirtualPrinter behind a pseudo-terminal through real
pyserial (tests/virtual_printer.py). The reference for what the printer did is
the printer itself (`vp.executed`); the reference for the preview is the
G-code's own layer comments and the recording printer_bed, whose first anchor
is the bed marker.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from PySide6.QtCore import QSettings, Qt  # noqa: E402

from virtual_printer import VirtualPrinterPty  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
RECORDING = ROOT / "recordings" / "printer_bed"
TIMEOUT_MS = 60000
FAULTS = ["100:resend", "110:missing_lineno", "115:checksum_mismatch"]
BED_MARKER = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.04}


def quick(gcode: str) -> str:
    """The same job without heat waits and with fast moves, so the virtual printer runs it in seconds
    (M104/M140 stay: the printer heats toward their targets while printing, which the graph shows).
    A 2.5 s dwell at the second layer keeps the job running past the link's 2 s temperature report,
    however fast the machine."""
    lines = [ln for ln in gcode.splitlines() if not re.match(r"\s*M(109|190)\b", ln)]
    out = []
    for ln in lines:
        out.append(re.sub(r"F\d+(\.\d*)?", "F600000", ln))
        if ln.strip() == ";LAYER:1":
            out.append("G4 P2500")
    return "\n".join(out) + "\n"


def layer_comments(gcode: str) -> list[int]:
    return [int(m.group(1)) for m in re.finditer(r"^;LAYER:(\d+)", gcode, re.MULTILINE)]


@pytest.fixture(scope="module")
def bed_profile(tmp_path_factory) -> Path:
    """A printer profile whose bed marker lies 60 mm left of and 60 mm in front of the bed centre, where the
    recording printer_bed's camera looks."""
    from arapp.printing.bed_anchor import bed_from_anchor_measured, save_bed_anchor

    path = tmp_path_factory.mktemp("printer") / "printer.json"
    return save_bed_anchor(path, BED_MARKER, bed_from_anchor_measured((125.0 - 60.0, 105.0 - 60.0)))


@pytest.fixture
def window(qtbot, tmp_path):
    from arapp.gui.main_window import MainWindow

    w = MainWindow(settings=QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat))
    w.full_frames = True
    qtbot.addWidget(w)
    w.show()
    yield w
    dlg = w._print_dialog
    if dlg is not None and dlg.printing:
        dlg.cancel_print()
        qtbot.waitUntil(lambda: not dlg.printing, timeout=TIMEOUT_MS)
    for box in w.open_error_boxes():
        box.close()
    w.close()


def sliced_dialog(qtbot, window, tmp_path, profile, size_mm=10.0):
    """The print dialog of the sphere placed at `size_mm`, sliced for `profile` in 0.3 mm layers."""
    window.open_model(str(MODELS / "sphere.json"))
    qtbot.waitUntil(lambda: window.model is not None, timeout=TIMEOUT_MS)
    window.model_panel.size.setValue(size_mm)
    window.open_print_dialog()
    dlg = window._print_dialog
    dlg.work_dir = tmp_path / "jobs"
    dlg.set_profile_path(str(profile))
    dlg.layer_height.setValue(0.3)
    dlg.infill.setValue(10)
    qtbot.mouseClick(dlg.slice_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dlg.result is not None, timeout=TIMEOUT_MS)
    return dlg


def drawn_toolpaths(window):
    s = window.last_shown
    return None if s is None else s.result.extra.get("toolpaths")


def magenta_pixels(shown) -> int:
    """Pixels of the composite in the highlight colour (CURRENT_COLOUR) that the captured frame lacks."""
    from arapp.engine.toolpath_overlay import CURRENT_COLOUR

    bgr = np.array(CURRENT_COLOUR[2::-1]) * 255
    img = shown.result.image.astype(int)
    near = np.abs(img - bgr).max(axis=2) < 40
    changed = np.abs(img - shown.frame.astype(int)).max(axis=2) > 40
    return int((near & changed).sum())


def test_print_to_the_virtual_printer_with_live_highlight(qtbot, window, tmp_path, bed_profile):
    from arapp.printing.gcode import parse_gcode

    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile)
    n_layers = dlg.result.layers
    assert n_layers == round(10.0 / 0.3)
    assert dlg.preview_check.isEnabled() and not dlg.preview_warning.isVisible()
    # the printer runs the same layers, faster (see quick())
    dlg.result = dataclasses.replace(dlg.result, gcode=quick(dlg.result.gcode))
    assert layer_comments(dlg.result.gcode) == list(range(n_layers))
    assert len(parse_gcode(dlg.result.gcode)) == n_layers

    window.replay.loop.setChecked(True)
    window.open_source(str(RECORDING))
    qtbot.waitUntil(lambda: window.last_shown is not None and window.last_shown.result.world_from_camera is not None,
                    timeout=TIMEOUT_MS)

    percents, layer_labels, frames, last_progress = [], [], [], [None]
    dlg.progress_reported.connect(lambda p: percents.append(p.percent))
    dlg.progress_reported.connect(lambda p: last_progress.__setitem__(0, p))
    finished = []
    dlg.print_finished.connect(finished.append)

    def on_progress(p):
        layer_labels.append(dlg.print_layer_label.text())

    dlg.progress_reported.connect(on_progress)

    def on_frame(_i):
        info = drawn_toolpaths(window)
        if info and info.get("current") is not None:
            # what the engine drew, next to the newest layer the link had reported when it was painted
            frames.append((info["current"], dlg.current_layer, magenta_pixels(window.last_shown)))

    window.frame_painted.connect(on_frame)
    with VirtualPrinterPty(simulated_errors=FAULTS) as vp:
        dlg.use_serial.setChecked(True)
        dlg.port.setCurrentText(vp.port)
        qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
        assert dlg.printing and dlg.preview_check.isChecked()  # printing turns the preview on
        assert not dlg.send_button.isEnabled() and dlg.pause_button.isEnabled()
        qtbot.waitUntil(lambda: dlg.current_layer >= 2, timeout=TIMEOUT_MS)
        # meanwhile the slider shows the printed layer
        assert not dlg.layer_slider.isEnabled() and dlg.layer_slider.value() >= 2
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
        executed = list(vp.executed)
    assert finished[0].error is None, finished[0].error
    # the printer ran the whole job, once, in order
    from arapp.printing.link.job import Program

    program = [c.text for c in Program.from_lines(dlg.result.gcode.splitlines()).commands]
    assert [c for c in executed if c in set(program)] == program
    # progress reached 100 %, in the bar and the label
    assert percents[-1] == pytest.approx(100.0)
    assert percents == sorted(percents)
    assert dlg.print_progress.value() == 1000 and dlg.percent_label.text() == "100.0 %"
    # the layer label followed the printer's layers, up to the last
    shown = [int(m.group(1)) for t in layer_labels if (m := re.match(r"layer (\d+) / (\d+)", t))]
    assert shown == sorted(shown) and shown[-1] == n_layers and len(set(shown)) == n_layers
    assert all(t.endswith(f"/ {n_layers}") for t in layer_labels if t)
    # the temperature graph got the printer's readings (hotend and bed, heating toward the G-code's targets)
    assert len(dlg.temps.samples) >= 2  # one every 0.5 s at most while readings stay the same
    last = dlg.temps.samples[-1][1]
    assert set(last) == {"hotend", "bed"}
    assert last["hotend"] == last_progress[0].temperatures["T"] and last["bed"] == last_progress[0].temperatures["B"]
    targets = {name: [d[name][1] for _, d in dlg.temps.samples if name in d] for name in ("hotend", "bed")}
    assert 205.0 in targets["hotend"] and 60.0 in targets["bed"]
    # the engine's highlighted layer advanced with the print, never ahead of what the link reported
    currents = [c for c, _, _ in frames]
    assert len(set(currents)) >= 3, currents
    assert currents == sorted(currents)
    assert all(c <= reported for c, reported, _ in frames)
    assert max(m for _, _, m in frames) > 20  # the highlighted layer is drawn on the bed
    # after the print the preview is back to the slider's choice (all layers, nothing highlighted)
    qtbot.waitUntil(lambda: (drawn_toolpaths(window) or {}).get("gen") == window.toolpaths_gen, timeout=TIMEOUT_MS)
    assert drawn_toolpaths(window)["current"] is None and drawn_toolpaths(window)["layer"] is None
    assert dlg.layer_label.text() == f"all {n_layers} layers"


def test_pause_resume_and_cancel(qtbot, window, tmp_path, bed_profile):
    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=16.0)
    dlg.result = dataclasses.replace(dlg.result, gcode=quick(dlg.result.gcode))
    reports = []
    dlg.progress_reported.connect(reports.append)
    finished = []
    dlg.print_finished.connect(finished.append)
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        dlg.port.setCurrentText(vp.port)
        dlg.start_print()
        qtbot.waitUntil(lambda: bool(reports) and reports[-1].lines_done > 50, timeout=TIMEOUT_MS)
        qtbot.mouseClick(dlg.pause_button, Qt.MouseButton.LeftButton)
        assert dlg.pause_button.text() == "Resume"
        qtbot.waitUntil(lambda: reports[-1].state == "paused", timeout=TIMEOUT_MS)
        qtbot.wait(300)  # the lines in flight land
        done_paused = len(vp.executed)
        qtbot.wait(700)
        assert len(vp.executed) == done_paused  # paused: the printer gets nothing more
        assert reports[-1].percent < 100.0
        qtbot.mouseClick(dlg.pause_button, Qt.MouseButton.LeftButton)
        assert dlg.pause_button.text() == "Pause"
        qtbot.waitUntil(lambda: len(vp.executed) > done_paused + 20, timeout=TIMEOUT_MS)
        qtbot.mouseClick(dlg.cancel_print_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
        executed = list(vp.executed)
    assert finished[0].error is None
    assert dlg.print_label.text() == "Print cancelled"
    assert reports[-1].state == "cancelled" and reports[-1].percent < 100.0
    # the link's safe stop reached the printer: heaters off after the last program line it ran
    assert "M104 S0" in executed[-12:] and "M140 S0" in executed[-12:]
    assert dlg.send_button.isEnabled() and not dlg.pause_button.isEnabled()


def test_printer_halt_shows_the_printers_message_and_the_job_file(qtbot, window, tmp_path, bed_profile):
    import json

    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=10.0)
    dlg.result = dataclasses.replace(dlg.result, gcode=quick(dlg.result.gcode))
    Path(dlg.job_gcode_path).write_text(dlg.result.gcode)  # the job's G-code file is what is printed
    finished = []
    dlg.print_finished.connect(finished.append)
    with VirtualPrinterPty(simulated_errors=[], inject={60: "trigger_fatal_error_marlin"}) as vp:
        dlg.port.setCurrentText(vp.port)
        dlg.start_print()
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
    title, message = window.errors[-1]
    assert title == "The printer halted itself"
    assert "Thermal Runaway, system stopped! Heater_ID: bed" in message  # the printer's own words
    job = Path(dlg.job_gcode_path).with_suffix(".printjob.json")
    # plain words and the GUI's own way on (Resume), not the CLI's command line
    assert "--resume" not in message and "press Resume" in message
    assert dlg.resume_button.isVisible() and dlg.session.saved_job.halted
    assert "Thermal Runaway" in dlg.session.saved_job.check_text()  # the confirmation says why it halted
    saved = json.loads(job.read_text())
    assert saved["status"] == "halted" and saved["gcode"] == dlg.job_gcode_path
    box = window.open_error_boxes()[0]
    assert box.isVisible() and box.text() == message
    assert dlg.send_button.isEnabled() and not dlg.printing


@pytest.mark.parametrize("engine", ["process", "threads"])
def test_preview_layer_slider_scrubs_the_bed_overlay(qtbot, window, tmp_path, bed_profile, engine):
    from arapp.printing.gcode import parse_gcode
    from arapp.engine.toolpath_overlay import KIND_COLOURS

    window.engine_kind = engine  # the child-process pipeline, and the in-process fallback
    window.open_source(str(RECORDING))
    qtbot.waitUntil(lambda: window.source_info is not None, timeout=TIMEOUT_MS)
    window.replay.loop.setChecked(True)
    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=24.0)
    layers = parse_gcode(Path(dlg.job_gcode_path).read_text())
    assert Path(dlg.job_gcode_path).read_text() == dlg.result.gcode
    assert dlg.layer_slider.maximum() == len(layers) and dlg.layer_label.text() == f"all {len(layers)} layers"
    dlg.preview_check.setChecked(True)
    qtbot.waitUntil(lambda: (drawn_toolpaths(window) or {}).get("gen") == window.toolpaths_gen, timeout=TIMEOUT_MS)
    assert drawn_toolpaths(window)["layers"] == len(layers) and drawn_toolpaths(window)["layer"] is None
    mid = len(layers) // 2
    for k in (mid, 3, mid):  # back and forth
        dlg.layer_slider.setValue(k)
        assert dlg.layer_label.text() == f"layer {k + 1} / {len(layers)}, z {layers[k].z:.2f} mm"
        qtbot.waitUntil(lambda: (drawn_toolpaths(window) or {}).get("gen") == window.toolpaths_gen,
                        timeout=TIMEOUT_MS)
        info = drawn_toolpaths(window)
        assert info["layer"] == k and info["z"] == pytest.approx(layers[k].z)
    # the perimeters drawn lie where that layer's G-code projects with the frame's pose
    qtbot.waitUntil(lambda: window.last_shown.result.world_from_camera is not None, timeout=TIMEOUT_MS)
    window.session.pause()
    qtbot.wait(300)
    shown = window.last_shown
    assert perimeter_pixels_on_gcode(shown, layers[mid], bed_profile, KIND_COLOURS["perimeter"]) > 0.9
    assert outline_pixels(shown) > 200  # the bed outline, green: inside the build area
    # off: the toolpaths and the bed outline are gone (the model on the marker stays)
    dlg.preview_check.setChecked(False)
    qtbot.waitUntil(lambda: (drawn_toolpaths(window) or {}).get("gen") == window.toolpaths_gen, timeout=TIMEOUT_MS)
    assert drawn_toolpaths(window)["layers"] == 0
    assert outline_pixels(window.last_shown) < 5
    assert perimeter_pixels(window.last_shown, KIND_COLOURS["perimeter"]).sum() < 5


def outline_pixels(shown) -> int:
    from arapp.engine.toolpath_overlay import BED_OUTLINE_COLOUR

    return int(perimeter_pixels(shown, BED_OUTLINE_COLOUR).sum())


def perimeter_pixels(shown, rgba, tol=40) -> np.ndarray:
    """Mask of overlay pixels of colour `rgba` (the composite differs from the captured frame there)."""
    bgr = np.array(rgba[2::-1]) * 255
    img = shown.result.image.astype(int)
    return (np.abs(img - bgr).max(axis=2) < tol) & (np.abs(img - shown.frame.astype(int)).max(axis=2) > 30)


def perimeter_pixels_on_gcode(shown, layer, profile_path, rgba) -> float:
    """Fraction of perimeter-coloured overlay pixels within 3 px of the layer's perimeters projected by OpenCV
    at the frame's pose (the tracker's estimate, a few tenths of a millimetre off; exact registration
    against ground truth is tests/test_print_preview.py's job) (bed -> world through the profile's bed_from_anchor; world = the bed marker)."""
    import cv2

    from arapp.printing import load_profile
    from tracking.poses import invert
    from tracking.recording.schema import load_session

    cam = load_session(RECORDING).camera
    bed_from_anchor = load_profile(profile_path).bed_from_anchor
    world_from_bed = np.diag([1e-3, 1e-3, 1e-3, 1.0]) @ np.linalg.inv(bed_from_anchor)
    camera_from_bed = invert(shown.result.world_from_camera) @ world_from_bed
    seg = layer.segments(kinds=("perimeter",))
    pts = np.concatenate([a + (b - a) * np.linspace(0, 1, 50)[:, None] for a, b in seg])
    in_cam = pts @ camera_from_bed[:3, :3].T + camera_from_bed[:3, 3]
    proj, _ = cv2.projectPoints(in_cam, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    proj = proj.reshape(-1, 2)
    ref = np.full((cam.height, cam.width), 255, np.uint8)
    ok = (proj[:, 0] >= 0) & (proj[:, 0] < cam.width) & (proj[:, 1] >= 0) & (proj[:, 1] < cam.height)
    assert ok.mean() > 0.99, "the layer must be in view"
    ref[np.round(proj[ok, 1]).astype(int), np.round(proj[ok, 0]).astype(int)] = 0
    dist = cv2.distanceTransform(ref, cv2.DIST_L2, 5)
    ys, xs = np.nonzero(perimeter_pixels(shown, rgba))
    assert len(xs) > 50
    return float(np.mean(dist[ys, xs] <= 3.0))


def test_build_area_warning_in_the_dialog_and_red_on_the_bed(qtbot, window, tmp_path, bed_profile):
    import json

    from arapp.engine.toolpath_overlay import OUT_OF_BED_COLOUR

    # a purge line in front of the bed (y = -3 mm), as some printers' start G-code does
    data = json.loads(Path(bed_profile).read_text())
    data["start_gcode"] = "G28\nG1 Z0.3 F5000\nG1 X0 Y-3 F1000\nG92 E0\nG1 X60 Y-3 E9 F1000\nG92 E0"
    purge = tmp_path / "purge.json"
    purge.write_text(json.dumps(data))
    window.open_source(str(RECORDING))
    window.replay.loop.setChecked(True)
    dlg = sliced_dialog(qtbot, window, tmp_path, purge, size_mm=10.0)
    assert dlg.preview_warning.isVisible()
    text = dlg.preview_warning.text()
    assert "leave the build area" in text and "250 x 210 x 210 mm" in text and "y -3.0" in text
    dlg.preview_check.setChecked(True)
    qtbot.waitUntil(lambda: (drawn_toolpaths(window) or {}).get("gen") == window.toolpaths_gen
                    and window.last_shown.result.world_from_camera is not None, timeout=TIMEOUT_MS)
    assert drawn_toolpaths(window)["outside"] is True
    # the bed outline turns red: red pixels appear in the composite
    red = np.array(OUT_OF_BED_COLOUR[2::-1]) * 255

    def red_drawn():
        s = window.last_shown
        img = s.result.image.astype(int)
        near = (np.abs(img - red).max(axis=2) < 50) & (np.abs(img - s.frame.astype(int)).max(axis=2) > 40)
        return (drawn_toolpaths(window) or {}).get("outside") and near.sum() > 200

    qtbot.waitUntil(red_drawn, timeout=TIMEOUT_MS)


def test_print_through_octoprint(qtbot, window, tmp_path, bed_profile):
    """The same dialog through OctoPrint's REST API (the stand-in server of test_octoprint_link, whose replies
    are copies of a real OctoPrint 1.11's): the exact G-code is uploaded and started, progress reaches 100 %."""
    from arapp.printing.link.webapi import save_api_key
    from test_octoprint_link import KEY, FakeOctoPrint

    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=8.0)
    key_file = save_api_key(tmp_path / "octoprint.key", KEY)
    finished, reports = [], []
    dlg.print_finished.connect(finished.append)
    dlg.progress_reported.connect(reports.append)
    server = FakeOctoPrint(rate=400000.0)
    try:
        dlg.use_octoprint.setChecked(True)
        dlg.octoprint_url.setText(server.url)
        dlg.api_key_file.setText(str(key_file))
        qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
    finally:
        server.close()
    assert finished[0].error is None, finished[0].error
    assert server.uploads[0]["data"].decode() == dlg.result.gcode
    assert set(server.keys_seen) == {KEY}
    assert reports[-1].state == "done" and reports[-1].percent == 100.0
    assert dlg.print_progress.value() == 1000
    n = dlg.result.layers
    assert dlg.print_layer_label.text() == f"layer {n} / {n}"
    assert dlg.temps.samples and "hotend" in dlg.temps.samples[-1][1]


def test_gui_command_draws_toolpaths_for_a_screenshot(tmp_path, bed_profile):
    """`arapp gui --source RECORDING --toolpaths GCODE --printer PROFILE --layer N --screenshot`: the picture
    shows the bed outline and the toolpaths; a layer the G-code lacks is an error naming the range."""
    import os
    import subprocess
    import sys

    import cv2
    import trimesh

    from arapp.printing import SliceSettings, load_profile, slice_mesh
    from arapp.engine.toolpath_overlay import BED_OUTLINE_COLOUR, KIND_COLOURS

    profile = load_profile(bed_profile)
    result = slice_mesh(trimesh.creation.box(extents=(24.0, 24.0, 3.0)), SliceSettings(layer_height=0.3), profile)
    gcode = tmp_path / "box.gcode"
    gcode.write_text(result.gcode)
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYOPENGL_PLATFORM="egl",
               XDG_CONFIG_HOME=str(tmp_path / "config"))
    base = [sys.executable, "-m", "arapp", "gui", "--source", str(RECORDING), "--toolpaths", str(gcode),
            "--printer", str(bed_profile), "--frames", "3"]
    out = tmp_path / "shot.png"
    proc = subprocess.run(base + ["--layer", "5", "--screenshot", str(out)], capture_output=True, text=True,
                          timeout=120, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    img = cv2.imread(str(out)).astype(int)
    for rgba in (BED_OUTLINE_COLOUR, KIND_COLOURS["perimeter"]):
        assert (np.abs(img - np.array(rgba[2::-1]) * 255).max(axis=2) < 30).sum() > 100
    bad = subprocess.run(base + ["--layer", str(result.layers)], capture_output=True, text=True, timeout=120,
                         env=env, cwd=ROOT)
    assert bad.returncode != 0 and f"layers 0..{result.layers - 1}" in bad.stderr


def test_old_slices_are_pruned_but_resumable_jobs_kept(tmp_path):
    import os

    from arapp.app.print_session import prune_slices

    paths = []
    for i in range(14):
        p = tmp_path / f"part-{i:02d}.gcode"
        p.write_text("G28\n")
        os.utime(p, (1000 + i, 1000 + i))
        paths.append(p)
    paths[0].with_suffix(".printjob.json").write_text("{}")  # the oldest has a job to resume
    prune_slices(tmp_path, keep=10)
    left = sorted(p.name for p in tmp_path.glob("*.gcode"))
    assert left == sorted([paths[0].name] + [p.name for p in paths[4:]])


def test_the_dialog_slices_with_prusaslicer_too(qtbot, window, tmp_path):
    """The slicer is a choice of the dialog: PrusaSlicer slices the same placed solid (its own G-code header,
    one layer per 0.3 mm of the 10 mm sphere)."""
    from arapp.printing.prusa import find_prusa

    if find_prusa() is None:
        pytest.skip("PrusaSlicer is not installed (make test installs it)")
    window.open_model(str(MODELS / "sphere.json"))
    qtbot.waitUntil(lambda: window.model is not None, timeout=TIMEOUT_MS)
    window.model_panel.size.setValue(10.0)
    window.open_print_dialog()
    dlg = window._print_dialog
    dlg.work_dir = tmp_path / "jobs"
    dlg.slicer.setCurrentText("PrusaSlicer")
    dlg.layer_height.setValue(0.3)
    qtbot.mouseClick(dlg.slice_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dlg.result is not None or bool(window.errors), timeout=TIMEOUT_MS)
    assert not window.errors, window.errors
    assert "generated by PrusaSlicer" in dlg.result.gcode[:2000]
    assert dlg.result.layers == pytest.approx(10.0 / 0.3, abs=1.0)
    assert Path(dlg.job_gcode_path).read_text() == dlg.result.gcode  # the copy the preview and printer read
