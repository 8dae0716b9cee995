"""Bad input is refused before it becomes G-code, a file or a traceback (issue 14, item 2).

Each case runs the command line (`arapp.cli.main`, in process) and checks the contract written here:
a non-zero exit, exactly one line on stderr that names what is wrong (the flag, file or field), no
"Traceback", and no output file or folder left behind. The ranges themselves are rules written in
the tests (layer height 0.1 to 0.8 x the nozzle, ...), not read back from the code under test.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from arapp.cli import main

ROOT = Path(__file__).resolve().parents[1]
VASE = ROOT / "models" / "vase.json"


def refused(capsys, argv, *needles) -> str:
    """Run the CLI; assert the contract above; return the one error line."""
    rc = main([str(a) for a in argv])
    _, err = capsys.readouterr()
    assert rc != 0, f"accepted: {argv}"
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line on stderr, got:\n{err}"
    for needle in needles:
        assert needle in lines[0], f"{needle!r} not in {lines[0]!r}"
    return lines[0]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


# -- slicing parameters -------------------------------------------------------------------------------

@pytest.mark.parametrize("flags, needle", [
    (["--size", "1e18"], "--size"),             # was a TypeError traceback
    (["--size", "1e308"], "--size"),            # was "the surface is open" (wrong diagnosis)
    (["--size", "nan"], "--size"),
    (["--size", "0"], "--size"),
    (["--first-layer-height", "100"], "--first-layer-height"),
    (["--z-hop", "1e9"], "--z-hop"),
    (["--retract", "1e9"], "--retract"),
    (["--retract", "-1"], "--retract"),
    (["--layer-height", "5"], "--layer-height"),
    (["--layer-height", "0.0001"], "--layer-height"),   # would slice for hours
    (["--layer-height", "0.35"], "0.4 mm nozzle"),      # above 0.8 x 0.4 mm on the generic printer
    (["--infill", "150"], "--infill"),
    (["--perimeters", "-2"], "--perimeters"),
    (["--thickness", "0"], "--thickness"),
])
def test_slice_refuses_out_of_range_settings(tmp_path, capsys, flags, needle):
    out = tmp_path / "sub" / "part.gcode"
    refused(capsys, ["slice", VASE, "-o", out, *flags], needle)
    assert not out.parent.exists()


def test_layer_height_range_follows_the_nozzle(tmp_path):
    """Rule written here: a nozzle of diameter d prints layers from 0.1 d to 0.8 d; first layers likewise."""
    from arapp.printing import SliceSettings, load_profile
    from arapp.printing.slicer.settings import SettingsError

    generic = json.loads((ROOT / "arapp/printing/profiles/generic.json").read_text())
    for d in (0.25, 0.4, 0.6, 0.8):
        path = tmp_path / f"n{d}.json"
        path.write_text(json.dumps({**generic, "nozzle_diameter": d, "name": f"nozzle {d}"}))
        profile = load_profile(path)
        for h in (0.1 * d, 0.5 * d, 0.8 * d):
            SliceSettings(layer_height=h, first_layer_height=h).check_for(profile)
        for h in (0.8 * d * 1.05, 0.1 * d * 0.9):
            with pytest.raises(SettingsError, match=f"{d:g} mm nozzle"):
                SliceSettings(layer_height=h, first_layer_height=0.5 * d).check_for(profile)
            with pytest.raises(SettingsError, match="first_layer_height"):
                SliceSettings(layer_height=0.5 * d, first_layer_height=h).check_for(profile)


def test_temperatures_are_bounded_by_the_profile(tmp_path):
    from arapp.printing import SliceSettings, load_profile
    from arapp.printing.slicer.settings import SettingsError

    generic = json.loads((ROOT / "arapp/printing/profiles/generic.json").read_text())
    path = tmp_path / "cool.json"
    path.write_text(json.dumps({**generic, "max_hotend_temperature": 240, "max_bed_temperature": 70}))
    profile = load_profile(path)
    SliceSettings(hotend_temperature=240, bed_temperature=70).check_for(profile)
    with pytest.raises(SettingsError, match="hotend temperature 250"):
        SliceSettings(hotend_temperature=250).check_for(profile)
    with pytest.raises(SettingsError, match="bed temperature 100"):
        SliceSettings(material="ABS").check_for(profile)  # ABS's default bed is 100 °C
    with pytest.raises(SettingsError, match="hotend temperature 100"):
        SliceSettings(hotend_temperature=100).check_for(profile)  # nothing melts


def test_print_slices_with_the_same_checks(tmp_path, capsys):
    # `arapp print MODEL` slices first, through the same settings_from_args.
    refused(capsys, ["print", VASE, "--port", "/dev/null", "--z-hop", "1e9", "-o", tmp_path / "p.gcode"], "--z-hop")
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("key, value", [("nozzle_diameter", 4.0), ("filament_diameter", 17.5),
                                        ("max_hotend_temperature", 5000), ("bed", {"width": 1e9, "depth": 200,
                                                                                    "height": 200})])
def test_profile_values_out_of_range_name_file_and_key(tmp_path, capsys, key, value):
    generic = json.loads((ROOT / "arapp/printing/profiles/generic.json").read_text())
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({**generic, key: value}))
    refused(capsys, ["slice", VASE, "-o", tmp_path / "x.gcode", "--printer", path], str(path), key)


# -- model export ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("flags, needle", [(["--size", "1e20"], "size"), (["--size", "-3"], "size"),
                                           (["--thickness", "1e9"], "thickness"),
                                           (["--tolerance", "1e9"], "tolerance")])
def test_model_export_refuses_sizes_that_make_no_solid(tmp_path, capsys, flags, needle):
    out = tmp_path / "part.stl"
    refused(capsys, ["model", "export", VASE, "-o", out, *flags], needle)  # was a 0-volume STL, exit 0
    assert leftovers(tmp_path) == []


def test_coincident_control_points_name_the_file_and_field(tmp_path, capsys):
    flat = tmp_path / "flat.json"
    flat.write_text(json.dumps({"format": "arapp-model", "version": 1, "surfaces": [
        {"type": "nurbs", "control_points": [[[1, 1, 1], [1, 1, 1]], [[1, 1, 1], [1, 1, 1]]],
         "degree_u": 1, "degree_v": 1}]}))
    for argv in (["model", "info", flat], ["slice", flat, "-o", tmp_path / "f.gcode"]):
        refused(capsys, argv, str(flat), "surfaces[0].control_points")  # was "tolerance: must be positive"


# -- camera calibration files and calibrate -------------------------------------------------------------

def _video(path: Path, n: int = 5) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    for i in range(n):
        w.write(np.full((48, 64, 3), 20 * i, np.uint8))
    w.release()
    return path


@pytest.mark.parametrize("text, needle", [
    ("%YAML:1.0\ncamera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [ 1, 0, 2\n", "line 6"),
    ("camera_matrix: [1, 2\nfoo: : :\n", "line 2"),
    ("%YAML:1.0\nimage_width: 64\nimage_height: 48\ncamera_matrix: [1, 2, 3]\n", "camera_matrix"),
    ("%YAML:1.0\nimage_width: 64\ncamera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n"
     "  data: [ 50, 0, 32, 0, 50, 24, 0, 0, 1 ]\n", "image_height"),
    ("%YAML:1.0\nimage_width: 64\nimage_height: 48\ncamera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n"
     "  dt: d\n  data: [ -50, 0, 32, 0, 50, 24, 0, 0, 1 ]\n", "fx"),
])
def test_broken_camera_yaml_names_file_and_field(tmp_path, capsys, text, needle):
    yaml = tmp_path / "cam.yaml"
    yaml.write_text(text)
    out = tmp_path / "rec"
    # was a SystemError traceback from cv2.FileStorage
    refused(capsys, ["record", "--source", _video(tmp_path / "clip.avi"), "--calibration", yaml, "--out", out],
            str(yaml), needle)
    assert not out.exists()


def test_calibrate_refuses_min_views_below_three_and_reports_no_board(tmp_path, capsys):
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(3)
    for i in range(3):
        cv2.imwrite(str(photos / f"p{i}.png"), (rng.random((120, 160)) * 255).astype(np.uint8))
    out = tmp_path / "cam.yaml"
    refused(capsys, ["calibrate", "--images", photos, "--min-views", "0", "-o", out], "--min-views")  # was an OpenCV assertion
    refused(capsys, ["calibrate", "--images", photos, "--min-views", "3", "-o", out], "0 usable views")
    refused(capsys, ["calibrate", "--images", photos, "--marker-length", "0.05", "-o", out], "--marker-length")
    assert not out.exists()


# -- printer profile task -------------------------------------------------------------------------------

def test_bed_anchor_refuses_a_missing_profile_unless_asked_to_create_it(tmp_path, capsys):
    missing = tmp_path / "nonexistent.json"
    refused(capsys, ["printer", "bed-anchor", "--printer", missing, "--center", "10", "10"], str(missing), "--create")
    assert not missing.exists()  # was silently created
    refused(capsys, ["printer", "bed-anchor", "--printer", tmp_path / "no" / "dir.json", "--create",
                     "--center", "10", "10"], "does not exist")
    refused(capsys, ["printer", "bed-anchor", "--printer", missing, "--create", "--center", "900", "10"], "off the")
    assert main(["printer", "bed-anchor", "--printer", str(missing), "--create", "--center", "10", "10"]) == 0
    assert json.loads(missing.read_text())["bed_anchor"]["bed_from_anchor"][0][3] == 10.0


# -- counts and output folders --------------------------------------------------------------------------

def test_negative_counts_are_refused_and_leave_nothing(tmp_path, capsys):
    rec = ROOT / "recordings" / "board_orbit"
    refused(capsys, ["replay", rec, "--out", tmp_path / "r", "--frames", "-5"], "--frames")
    refused(capsys, ["replay", rec, "--out", tmp_path / "r", "--frames", "0"], "--frames")
    refused(capsys, ["synth", "board_orbit", "--out", tmp_path / "s", "--frames", "-3"], "--frames")
    refused(capsys, ["record", "--source", _video(tmp_path / "clip.avi"), "--out", tmp_path / "rec",
                     "--seconds", "-1"], "--seconds")
    assert leftovers(tmp_path) == ["clip.avi"]


def test_a_failed_replay_leaves_no_output_folder(tmp_path, capsys):
    flat = tmp_path / "flat.json"
    flat.write_text(json.dumps({"format": "arapp-model", "version": 1, "surfaces": [
        {"type": "nurbs", "control_points": [[[0, 0, 0], [0, 0, 0]], [[0, 0, 0], [0, 0, 0]]]}]}))
    out = tmp_path / "deep" / "out"
    refused(capsys, ["replay", ROOT / "recordings" / "board_orbit", "--out", out, "--model", flat], "flat.json")
    refused(capsys, ["replay", tmp_path / "missing", "--out", out], "missing")
    assert leftovers(tmp_path) == ["flat.json"]  # neither out nor its parent "deep" (was: empty folders)


def test_a_successful_replay_fills_an_existing_folder(tmp_path, capsys):
    rec = tmp_path / "rec"
    shutil.copytree(ROOT / "recordings" / "board_orbit", rec)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["replay", str(rec), "--out", str(out), "--no-video", "--no-slam", "--frames", "3"]) == 0
    assert {"notes.txt", "poses.tum", "tracking.csv", "report.json"} <= set(leftovers(out))
    assert [p for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging folder left
