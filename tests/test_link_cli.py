"""`arapp print` over USB serial to OctoPrint's VirtualPrinter on a pty (real pyserial)."""

from __future__ import annotations

import json

from arapp.cli import main
from arapp.commands.print_ import format_progress
from arapp.printing.link.base import Progress

from test_link_serial import expected_commands, make_gcode, program_commands
from virtual_printer import VirtualPrinterPty


def test_print_gcode_then_resume_after_drop(tmp_path, capsys):
    gcode = ["M140 S21", "M104 S21"] + make_gcode(150)
    path = tmp_path / "part.gcode"
    path.write_text("\n".join(gcode) + "\n")
    expected = expected_commands(gcode)
    job = tmp_path / "part.gcode.job.json"

    with VirtualPrinterPty(simulated_errors=[], inject={90: "drop_connection"}) as vp:
        rc = main(["print", str(path), "--port", vp.port, "--timeout", "2"])
        first = program_commands(vp.executed, gcode)
    err = capsys.readouterr().err
    assert rc == 2 and "was lost" in err and f"--resume {job}" in err
    saved = json.loads(job.read_text())
    assert saved["status"] == "link_lost" and saved["gcode"] == str(path.resolve())

    with VirtualPrinterPty(simulated_errors=[]) as vp:
        rc = main(["print", "--resume", str(job), "--port", vp.port, "--timeout", "2"])
        second = list(vp.executed)
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "done" in out.out
    done = saved["commands_done"]
    assert first == expected[: len(first)] and done <= len(first) <= done + 1
    resumed = second[second.index("G28 X Y") + 1 :]
    assert program_commands(resumed, gcode)[-(len(expected) - done):] == expected[done:]
    assert json.loads(job.read_text())["status"] == "done"


def test_print_reports_the_printers_halt(tmp_path, capsys):
    path = tmp_path / "part.gcode"
    path.write_text("\n".join(make_gcode(100)) + "\n")
    with VirtualPrinterPty(simulated_errors=[], inject={30: "trigger_fatal_error_marlin"}) as vp:
        rc = main(["print", str(path), "--port", vp.port, "--timeout", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and "Thermal Runaway, system stopped! Heater_ID: bed" in err


def test_progress_line_shows_lines_layer_eta_temperatures():
    line = format_progress(Progress(state="printing", lines_done=500, lines_total=2000, layer=4, layer_count=40,
                                    percent=25.0, eta_s=3725.0,
                                    temperatures={"T": (209.6, 210.0), "B": (59.9, 60.0)}))
    assert "25.0%" in line and "lines 500/2000" in line and "layer 5/40" in line
    assert "ETA 1:02:05" in line and "T 209.6/210" in line and "B 59.9/60" in line


def test_print_model_slices_then_streams(tmp_path, capsys):
    """`arapp print MODEL`: the built-in slicer's G-code, streamed exactly once."""
    import trimesh

    stl = tmp_path / "cube.stl"
    trimesh.creation.box((10.0, 10.0, 2.0)).export(stl)
    out = tmp_path / "cube.gcode"
    # Ambient above the targets: the printer's heat waits return at once.
    with VirtualPrinterPty(simulated_errors=[], settings={"ambientTemperature": 260.0}) as vp:
        rc = main(["print", str(stl), "--port", vp.port, "--timeout", "2", "-o", str(out),
                   "--layer-height", "0.25"])
        executed = list(vp.executed)
    err = capsys.readouterr().err
    assert rc == 0, err
    gcode = out.read_text().splitlines()
    assert any(line.startswith(";LAYER:") for line in gcode)
    ran = [c for c in executed if not c.startswith(("M110", "M115", "M155"))]
    assert ran == expected_commands(gcode)
