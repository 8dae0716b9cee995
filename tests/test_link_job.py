"""The print job's state and file (arapp.printing.link.job): what a command does to the state, the file's
schema, what a resume and a cancel send. Expected values are written here from Marlin's G-code semantics."""

from __future__ import annotations

import json
import math

import pytest

from arapp.printing.link.job import (
    BED_MARGIN_MM,
    JobFileError,
    JobState,
    Program,
    cancel_commands,
    check_job_fields,
    check_resumable,
    is_heating,
    new_state,
    resume_commands,
)
from arapp.printing.link.job import Command

SHA = "ab" * 32


class _Bed:
    width, depth, height = 200.0, 180.0, 150.0


class _Profile:
    bed = _Bed()
    max_hotend_temperature = 260.0
    max_bed_temperature = 100.0


def fields(**kw) -> dict:
    data = dict(JobState(gcode_sha256=SHA, source_lines=100, next_line=10).__dict__)
    data.update(kw)
    return data


def run(state: JobState, *texts: str) -> JobState:
    for i, text in enumerate(texts):
        state.apply(Command(i, text, 0))
    return state


# -- apply --------------------------------------------------------------------------------------
def test_absolute_and_relative_moves():
    s = run(JobState(), "G28", "G1 X10 Y20 Z0.3 E1.5 F1800")
    assert (s.x, s.y, s.z, s.e, s.f) == (10.0, 20.0, 0.3, 1.5, 1800.0)
    run(s, "G91", "G1 X-2 Y3 Z0.2 E0.5")
    assert (s.x, s.y, s.z, s.e) == (8.0, 23.0, pytest.approx(0.5), 2.0)
    assert not s.absolute_xyz and not s.absolute_e
    run(s, "G90", "G0 X1")
    assert s.x == 1.0 and s.absolute_xyz and s.absolute_e


def test_extrusion_modes_and_g92():
    s = run(JobState(), "M83", "G1 E2", "G1 E3")
    assert s.e == 5.0 and not s.absolute_e and s.absolute_xyz
    run(s, "M82", "G1 E7")
    assert s.e == 7.0
    run(s, "G92 E0 Z5")
    assert (s.e, s.z) == (0.0, 5.0)


def test_home_selected_axes():
    s = run(JobState(x=5.0, y=6.0, z=7.0), "G28 X")
    assert (s.x, s.y, s.z) == (0.0, 6.0, 7.0)
    run(s, "G28")
    assert (s.x, s.y, s.z) == (0.0, 0.0, 0.0)


def test_heaters_fan_and_counters():
    s = run(JobState(), "M104 S200", "M140 S55", "M109 S210", "M190 S60", "M106 S128")
    assert (s.hotend_target, s.bed_target, s.fan) == (210.0, 60.0, 128)
    run(s, "M106", "M107")
    assert s.fan == 0
    assert s.commands_done == 7 and s.next_line == 2  # next_line: after the last command's source index (1)


def test_relative_move_with_unknown_position_takes_the_value():
    s = run(JobState(), "G91", "G1 X5")
    assert s.x == 5.0


def test_read_temperatures():
    s = JobState()
    s.read_temperatures({"T0": (200.5, 210.0), "B": (59.0, 60.0)})
    assert (s.hotend, s.bed) == (200.5, 59.0)
    s.read_temperatures({"T": (201.0, None)})
    assert (s.hotend, s.bed) == (201.0, 59.0)


# -- program -----------------------------------------------------------------------------------
def test_program_position_and_sha():
    p = Program.from_lines(["; c", "G28", "", "G1 X1 ; m", ";LAYER_CHANGE", "G1 X2"])
    assert [c.index for c in p.commands] == [1, 3, 5] and p.source_lines == 6
    assert [p.position_of(i) for i in (0, 1, 2, 3, 4, 5, 6)] == [0, 0, 1, 1, 2, 2, 3]
    assert p.commands[2].layer == 0 and p.layer_count == 1
    import hashlib

    raw = "".join(f"{line}\n" for line in ["; c", "G28", "", "G1 X1 ; m", ";LAYER_CHANGE", "G1 X2"])
    assert p.sha256 == hashlib.sha256(raw.encode()).hexdigest()
    with pytest.raises(ValueError, match="line 2"):
        Program.from_lines(["G28", "M117 a*b"])


def test_new_state_and_program_check(tmp_path):
    p = Program.from_lines(["G28", "G1 X1"])
    s = new_state(p, "part.gcode")
    assert (s.gcode, s.gcode_sha256, s.source_lines, s.commands_total) == ("part.gcode", p.sha256, 2, 2)
    s.check_program(p, "part.gcode")
    with pytest.raises(JobFileError, match="changed"):
        s.check_program(Program.from_lines(["G28"]), "part.gcode")


# -- the file ----------------------------------------------------------------------------------
def test_save_and_load_round_trip(tmp_path):
    path = tmp_path / "job.json"
    s = JobState(gcode_sha256=SHA, source_lines=50, next_line=12, x=10.0, y=20.0, z=1.2, hotend_target=210.0,
                 status="link_lost")
    s.save(path)
    assert json.loads(path.read_text())["format"] == "arapp-printjob/1"
    back = JobState.load(path, _Profile())
    assert back.next_line == 12 and (back.x, back.y, back.z) == (10.0, 20.0, 1.2)
    assert not (tmp_path / "job.json.tmp").exists()


@pytest.mark.parametrize("key, value, words", [
    ("x", math.nan, "finite"), ("y", math.inf, "finite"), ("e", "1", "finite"),
    ("x", -BED_MARGIN_MM - 0.1, "bed"), ("x", 200.0 + BED_MARGIN_MM + 0.1, "bed"),
    ("y", 180.0 + BED_MARGIN_MM + 0.1, "bed"), ("z", -0.1, "bed"), ("z", 150.1, "bed"),
    ("hotend_target", 260.5, "260"), ("bed_target", 100.5, "100"), ("hotend_target", -1.0, "0 to"),
    ("next_line", -1, ">= 0"), ("next_line", 101, "source_lines"), ("next_line", 1.5, "whole"),
    ("next_line", True, "whole"), ("layer", -2, ">= -1"), ("fan", 256, "0 to 255"), ("fan", -1, "0 to 255"),
    ("commands_done", 5, "commands_total"), ("gcode_sha256", "AB" * 32, "sha256"),
    ("gcode_sha256", "ab" * 31, "sha256"), ("status", "paused", "one of"), ("gcode", 3, "string"),
    ("f", 0.0, "positive"), ("absolute_e", 1, "true or false"),
])
def test_schema_refuses(key, value, words):
    with pytest.raises(JobFileError) as info:
        check_job_fields(fields(**{key: value}), "job.json", _Profile())
    msg = str(info.value)
    assert msg.startswith("job.json: field ") and f"'{key}'" in msg and words in msg and "\n" not in msg


@pytest.mark.parametrize("key, value", [
    ("x", -BED_MARGIN_MM), ("x", 200.0 + BED_MARGIN_MM), ("z", 0.0), ("z", 150.0), ("hotend_target", 260.0),
    ("bed_target", 100.0), ("next_line", 100), ("fan", 255), ("layer", -1), ("x", None), ("f", None),
])
def test_schema_accepts_the_limits(key, value):
    check_job_fields(fields(**{key: value}), "job.json", _Profile())


def test_every_field_has_a_type():
    """Each field of the file, given a value of no kind it may have (a list), is refused by name."""
    from arapp.printing.link.job import job_schema

    schema = job_schema(_Profile())
    assert set(schema) == set(JobState.__dataclass_fields__)
    for key in schema:
        with pytest.raises(JobFileError, match=f"'{key}' must be"):
            check_job_fields(fields(**{key: [1]}), "job.json", _Profile())
    for key in ("e", "updated", "hotend_target"):
        with pytest.raises(JobFileError, match="finite number"):
            check_job_fields(fields(**{key: None}), "job.json", _Profile())
    for key in ("hotend", "bed", "f"):
        with pytest.raises(JobFileError, match="finite number or null"):
            check_job_fields(fields(**{key: math.nan}), "job.json", _Profile())
    for key in ("source_lines", "commands_total", "layer_count", "baud"):
        with pytest.raises(JobFileError, match=f"'{key}' must be >= 0"):
            check_job_fields(fields(**{key: -1}), "job.json", _Profile())
    with pytest.raises(JobFileError, match="'gcode_sha256'"):
        data = fields()
        del data["gcode_sha256"]
        check_job_fields(data, "job.json", _Profile())
    check_job_fields({"gcode_sha256": SHA}, "job.json", _Profile())  # everything else has a default


def test_schema_limits_come_from_the_profile():
    class Tall(_Profile):
        class bed:
            width, depth, height = 400.0, 300.0, 500.0

        max_hotend_temperature = 400.0
        max_bed_temperature = 150.0

    check_job_fields(fields(x=404.0, y=304.0, z=499.0, hotend_target=399.0, bed_target=149.0), "j", Tall())
    with pytest.raises(JobFileError, match="'y' must be -5 to 185 mm"):
        check_job_fields(fields(y=186.0), "j", _Profile())


def test_schema_without_profile_uses_the_generic_printer():
    check_job_fields(fields(x=240.0, hotend_target=290.0), "job.json")
    with pytest.raises(JobFileError, match="'hotend_target'"):
        check_job_fields(fields(hotend_target=301.0), "job.json")


def test_load_refuses_unknown_keys_and_other_formats(tmp_path):
    path = tmp_path / "job.json"
    path.write_text(json.dumps({"format": "arapp-printjob/1", **fields(), "extra": 1}))
    with pytest.raises(JobFileError, match="unknown key"):
        JobState.load(path)
    path.write_text(json.dumps({"format": "other"}))
    with pytest.raises(JobFileError, match="'format'"):
        JobState.load(path)
    path.write_text("{")
    with pytest.raises(JobFileError, match="cannot read"):
        JobState.load(path)


def test_resumable():
    for status in ("link_lost", "reset", "failed", "printing"):
        check_resumable(JobState(status=status), "j")
    for status in ("cancelled", "done"):
        with pytest.raises(JobFileError, match="cannot be resumed"):
            check_resumable(JobState(status=status), "j")
    halted = JobState(status="halted", message="Thermal Runaway")
    with pytest.raises(JobFileError, match="Thermal Runaway.*--after-halt"):
        check_resumable(halted, "j")
    check_resumable(halted, "j", after_halt=True)


# -- resume and cancel sequences ----------------------------------------------------------------
def test_resume_commands():
    s = JobState(x=10.0, y=20.0, z=1.0, e=3.25, f=1800.0, hotend_target=210.0, bed_target=60.0, fan=255)
    assert resume_commands(s) == [
        "M190 S60", "M109 S210", "G90", "G92 Z1.000", "G1 Z3.000 F600", "G28 X Y", "G1 X10.000 Y20.000 F3000",
        "G1 Z1.000 F600", "M82", "G92 E3.25000", "M106 S255", "G1 F1800",
    ]
    s2 = JobState(x=1.0, y=2.0, z=149.0, absolute_e=False, absolute_xyz=False)
    out = resume_commands(s2, bed_height=150.0)
    assert out[:4] == ["G90", "G92 Z149.000", "G1 Z150.000 F600", "G28 X Y"]
    assert "M83" in out and out[-1] == "G91" and not any(c.startswith(("M190", "M109", "M106")) for c in out)
    with pytest.raises(JobFileError, match="position"):
        resume_commands(JobState(x=1.0, y=2.0))


def test_cancel_commands():
    assert cancel_commands(JobState(z=1.0)) == ["M104 S0", "M140 S0", "M107", "G91", "G1 Z10 F600", "G90", "M84"]
    assert cancel_commands(JobState(z=145.0), bed_height=150.0)[4] == "G1 Z5 F600"
    assert cancel_commands(JobState(z=150.0), bed_height=150.0) == ["M104 S0", "M140 S0", "M107", "M84"]
    assert cancel_commands(JobState(), bed_height=150.0)[4] == "G1 Z10 F600"


def test_is_heating():
    assert is_heating("M104 S200") and is_heating("M190 R60") and is_heating("m109 s1")
    assert not is_heating("M104 S0") and not is_heating("M106 S255") and not is_heating("")
    assert not is_heating("M140")


# -- pinned by mutation testing (docs/mutation-testing.md) ------------------------------------------
def test_arcs_relative_axes_and_homing_each_axis():
    s = run(JobState(), "G90", "G2 X5 Y6 I1 J0", "G3 X7 Y8 I1 J0")
    assert (s.x, s.y) == (7.0, 8.0)
    run(s, "G91", "G1 Y1 Z1")
    assert (s.y, s.z) == (9.0, 1.0) and s.absolute_xyz is False and s.absolute_e is False
    run(s, "G90", "G92 X1 Y2", "M83")
    assert (s.x, s.y, s.absolute_e) == (1.0, 2.0, False)
    for axis in "XYZ":
        s2 = run(JobState(x=5.0, y=5.0, z=5.0), f"G28 {axis}")
        assert getattr(s2, axis.lower()) == 0.0
        assert sum(getattr(s2, a) == 0.0 for a in "xyz") == 1
    s3 = run(JobState(x=5.0, y=5.0, z=5.0), "G28 X Y")
    assert (s3.x, s3.y, s3.z) == (0.0, 0.0, 5.0)
    s4 = run(JobState(), "M104 S190", "M140 S50", "M106")
    assert (s4.hotend_target, s4.bed_target, s4.fan) == (190.0, 50.0, 255)


def test_apply_sets_the_layer():
    s = JobState()
    s.apply(Command(4, "G1 X1", 3))
    assert (s.layer, s.next_line) == (3, 5)


def test_program_layer_comments_and_line_ends():
    p = Program.from_lines(["G28\r\n", "M117 ;LAYER:5 in a message\n", ";LAYER:2\n", "G1 X1\n"])
    assert [(c.text, c.layer) for c in p.commands] == [("G28", -1), ("M117", -1), ("G1 X1", 2)]
    assert p.layer_count == 3
    q = Program.from_lines(["G28", "G1 X1"])
    assert q.layer_count == 0
    import hashlib

    assert Program.from_lines(["G28\r\n"]).sha256 == hashlib.sha256(b"G28\n").hexdigest()
    assert Program.from_lines(["M117 é"]).sha256 == hashlib.sha256("M117 é\n".encode()).hexdigest()
    for prefix in ("G", "M", "T"):
        r = Program.from_lines([f"{prefix}1 ;LAYER:7", "G1 X1"])
        assert r.layer_count == 0, prefix  # a command's comment is not a layer change


def test_program_from_file(tmp_path):
    path = tmp_path / "p.gcode"
    path.write_text("G28\n;LAYER:0\nG1 X1\n")
    p = Program.from_file(path)
    assert [(c.text, c.layer) for c in p.commands] == [("G28", -1), ("G1 X1", 0)]


def test_save_writes_readable_json_atomically(tmp_path):
    path = tmp_path / "job.json"
    JobState(gcode_sha256=SHA, message="Grüße").save(path)
    text = path.read_text(encoding="utf-8")
    assert text.endswith("}\n") and '\n  "gcode": ""' in text
    assert [p.name for p in tmp_path.iterdir()] == ["job.json"]
    assert JobState.load(path).message == "Grüße"


def test_load_checks_with_the_given_profile_and_names_the_file(tmp_path):
    path = tmp_path / "job.json"
    JobState(gcode_sha256=SHA, x=190.0, y=10.0, z=1.0).save(path)
    JobState.load(path)  # on the generic 250 mm bed
    with pytest.raises(JobFileError, match=f"{path}: field 'x'"):
        JobState.load(path, type("Small", (_Profile,), {"bed": type("B", (), {"width": 100.0, "depth": 100.0,
                                                                                    "height": 100.0})})())
    data = json.loads(path.read_text())
    data["a"], data["b"] = 1, 2
    path.write_text(json.dumps(data))
    with pytest.raises(JobFileError, match="unknown key\\(s\\) a, b"):
        JobState.load(path)


def test_new_state_defaults():
    p = Program.from_lines([";LAYER:0", "G1 X1", ";LAYER:1", "G1 X2"])
    s = new_state(p)
    assert (s.gcode, s.layer_count, s.commands_total, s.next_line, s.status) == ("", 2, 2, 0, "new")


def test_messages_tell_what_to_do():
    with pytest.raises(JobFileError, match="resume with the original file"):
        JobState(gcode_sha256=SHA).check_program(Program.from_lines(["G28"]), "p.gcode")
    with pytest.raises(JobFileError, match=r"\(no message\); fix the cause, then resume with --after-halt"):
        check_resumable(JobState(status="halted"), "j")
    with pytest.raises(JobFileError, match="stopped before the first move"):
        resume_commands(JobState(x=1.0, z=1.0))
    with pytest.raises(JobFileError):
        resume_commands(JobState(y=1.0, z=1.0))


def test_small_targets_and_lifts():
    s = JobState(x=1.0, y=1.0, z=149.5, bed_target=0.5, hotend_target=0.5)
    out = resume_commands(s, bed_height=150.0)
    assert out[:2] == ["M190 S0.5", "M109 S0.5"] and out[4] == "G1 Z150.000 F600"
    assert cancel_commands(JobState(z=149.5), bed_height=150.0)[4] == "G1 Z0.5 F600"
    assert is_heating("M104 T0 S200")


def test_make_link():
    from arapp.printing.link.factory import OctoPrintTarget, SerialTarget, make_link
    from arapp.printing.link.serial_link import SerialPrinter

    link = make_link(SerialTarget("/dev/ttyUSB9", 250000, window=3, timeout=4.5), profile=_Profile(),
                     job_path="j.json")
    assert isinstance(link, SerialPrinter)
    assert (link.port, link.baud, link.window, link.timeout, link.job_path, link.bed_height) == (
        "/dev/ttyUSB9", 250000, 3, 4.5, "j.json", 150.0)
    assert make_link(SerialTarget("loop://")).bed_height is None
    with pytest.raises(ValueError, match="serial port"):
        make_link(SerialTarget(""))
    with pytest.raises(ValueError, match="OctoPrint URL"):
        make_link(OctoPrintTarget("", "key.txt"))
    with pytest.raises(ValueError, match="--api-key-file"):
        make_link(OctoPrintTarget("http://octopi.local", ""))
    with pytest.raises(TypeError, match="no printer link for a str; known: SerialTarget, OctoPrintTarget"):
        make_link("/dev/ttyUSB0")
