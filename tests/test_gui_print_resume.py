"""A print whose printer dies half way, resumed from the GUI (pytest-qt, offscreen).

The printer is the project's Marlin emulator (tests/marlin_emulator.py) on a pty with real pyserial: the
first one drops the link after a chosen command (the `drop` fault: that command ran, the next did not),
a second one is the printer back. The reference for "nothing runs twice" is the emulators' own lists of
executed commands; the z height the confirmation names is read from the commands the first one ran.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from PySide6.QtCore import Qt

from marlin_emulator import MarlinPty
from test_gui_print import TIMEOUT_MS, bed_profile, quick, sliced_dialog, window  # noqa: F401 - fixtures

_Z = re.compile(r"\bZ(-?\d*\.?\d+)")


def last_z(commands) -> float:
    """The nozzle's height after `commands` (absolute G0/G1 Z words; the sliced G-code moves in G90)."""
    z = None
    for c in commands:
        if c.split()[0] in ("G0", "G1") and (m := _Z.search(c)):
            z = float(m.group(1))
    return z


def test_lost_print_is_resumed_not_restarted(qtbot, window, tmp_path, bed_profile):  # noqa: F811
    from arapp.exchange import write_atomic
    from arapp.printing.link.job import Program

    dlg = sliced_dialog(qtbot, window, tmp_path, bed_profile, size_mm=10.0)
    gcode = quick(dlg.result.gcode)
    dlg.result = dataclasses.replace(dlg.result, gcode=gcode)
    # the job file's G-code is the one printed; renamed into place as the app writes it (rewriting the
    # file in place could be read half-written by the app's checks)
    write_atomic(dlg.job_gcode_path, gcode.encode("utf-8"))
    program = [c.text for c in Program.from_lines(gcode.splitlines()).commands]
    cut = len(program) // 3
    fault = (program[cut], program[: cut + 1].count(program[cut]))
    finished, asked = [], []
    dlg.print_finished.connect(finished.append)

    with MarlinPty(faults={fault: "drop"}) as emu:
        dlg.port.setCurrentText(emu.port)
        qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
        emu.settle()
        first = list(emu.executed)
    ran = [c for c in first if c in set(program)]
    assert ran == program[: cut + 1]  # the emulator ran up to the dropped command, no further
    # plain words, where it stopped, the way on; no CLI command line
    title, message = window.errors[-1]
    assert title == "The connection to the printer was lost"
    assert "press Resume" in message and "--resume" not in message, message
    saved = dlg.session.saved_job
    assert saved is not None and saved.state.commands_done == cut + 1
    assert f"{100.0 * (cut + 1) / len(program):.1f} %" in message
    assert dlg.resume_button.isVisible() and dlg.resume_button.isEnabled() and dlg.send_button.isEnabled()

    # Print again: asked, never started over silently; Cancel leaves everything as it was
    dlg.ask = lambda title, text, choices: asked.append((title, text, choices)) or ""
    with MarlinPty() as emu:
        dlg.port.setCurrentText(emu.port)
        qtbot.mouseClick(dlg.send_button, Qt.MouseButton.LeftButton)
        qtbot.wait(300)
        assert not dlg.printing and emu.executed == [] and asked[-1][2] == ["Resume...", "Start over"]
    assert dlg.session.saved_job is not None

    # the printer is back: Resume, confirmed after reading what it does
    finished.clear()
    dlg.ask = lambda title, text, choices: asked.append((title, text, choices)) or "Resume"
    with MarlinPty() as emu:
        dlg.port.setCurrentText(emu.port)
        qtbot.mouseClick(dlg.resume_button, Qt.MouseButton.LeftButton)
        assert dlg.printing
        qtbot.waitUntil(lambda: bool(finished), timeout=TIMEOUT_MS)
        emu.settle()
        second = list(emu.executed)
    assert finished[0].error is None, finished[0].error
    text = asked[-1][1]
    z = last_z(ran)
    assert f"z {z:.2f} mm" in text and "home X and Y only" in text and f"{cut + 1:,} of {len(program):,}" in text
    # the printer homed X and Y only, then ran exactly the commands the first printer had not
    homes = [c for c in second if c.split()[0] == "G28"]
    assert "G28 X Y" in homes and not any(len(c.split()) == 1 or "Z" in c for c in homes)  # Z never homed
    assert f"G92 Z{z:.3f}" in second
    after = [c for c in second[second.index("G28 X Y") + 1:] if c.split()[0] not in ("M105", "M155")]
    n_left = len(program) - cut - 1
    assert ran + after[-n_left:] == program  # every command once, in order
    between = after[:-n_left]  # the way back above the part: no printing move, a few lines
    assert len(between) <= 8 and not any(c.startswith("G1") and "E" in c and "X" in c for c in between), between
    job = json.loads(Path(dlg.job_gcode_path).with_suffix(".printjob.json").read_text())
    assert job["status"] == "done" and dlg.session.saved_job is None and not dlg.resume_button.isVisible()


def test_saved_job_rules_are_the_clis(tmp_path):
    """The CLI's refusals hold in the app model: a cancelled job is not offered, a changed G-code is refused,
    a halted one is offered with the printer's reason; the stop message drops the CLI's hint."""
    import pytest

    from arapp.app.saved_job import load_saved_job, stop_text
    from arapp.printing.link import JobFileError, JobState, Program
    from arapp.printing.link.job import new_state

    gcode = tmp_path / "part.gcode"
    gcode.write_text("G90\nM82\nG1 Z0.3 F600\nG1 X10 Y10 E1\nG1 X20 Y10 E2\n")
    program = Program.from_file(gcode)
    state = new_state(program, str(gcode))
    for c in program.commands[:4]:
        state.apply(c)
    state.status, state.message = "halted", "Thermal Runaway"
    job = tmp_path / "part.printjob.json"
    state.save(job)
    with pytest.raises(JobFileError, match="USB serial only"):  # no port: it ran through OctoPrint
        load_saved_job(job)
    state.port = "/dev/ttyACM0"
    state.save(job)
    saved = load_saved_job(job)
    assert saved.halted and "Thermal Runaway" in saved.check_text()
    assert "line 5 of 5" in saved.plan_text() and "z 0.30 mm" in saved.executed_text()
    title, text = stop_text(state, saved, f"the printer halted: Thermal Runaway (job state saved to {job}; "
                                          f"resume with --resume {job})")
    assert "--resume" not in text and text.endswith("Details: the printer halted: Thermal Runaway")
    state.status = "cancelled"
    state.save(job)
    with pytest.raises(JobFileError, match="cannot be resumed"):
        load_saved_job(job)
    state.status = "link_lost"
    state.save(job)
    gcode.write_text(gcode.read_text() + "G1 X30 Y10 E3\n")
    with pytest.raises(JobFileError, match="changed since the job was saved") as refused:
        load_saved_job(job)
    # the stop message says why there is nothing to resume, not only that there is not
    _, text = stop_text(state, None, "the connection was lost", why_not=str(refused.value))
    assert "Resume" not in text and "cannot be resumed (" in text and "changed since the job was saved" in text
    assert isinstance(JobState.load(job), JobState)
