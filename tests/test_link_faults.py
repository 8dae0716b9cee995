"""The fault table of docs/printer-faults.md, each row a scenario on the Marlin emulator.

Oracle: the emulated firmware's own log of what it ran (tests/marlin_emulator.py)
against the job's commands taken by a rule written here (each line without
its `;` comment, blank lines dropped), never the host's parser. Every
scenario checks: every program command ran exactly once across drops,
resumes and cancels, and the heaters are off at the end.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from arapp.cli import main
from arapp.printing.link import LinkError, LinkLost, PrinterHalted, PrinterReset
from arapp.printing.link.job import JobFileError, JobState, Program, resume_commands
from arapp.printing.link.serial_link import SerialPrinter

from marlin_emulator import MarlinPty

HOST = ("M105", "M110", "M115", "M155")
# What a print that stops (not done, not cancelled) must leave: heaters, fan and motors off, no move.
SAFE_STOP = ["M104 S0", "M140 S0", "M107", "M84"]
ROOT = Path(__file__).resolve().parents[1]


def make_job(n: int = 60, per_layer: int = 20, heat: bool = True) -> tuple[list[str], list[str]]:
    """G-code lines and the commands the firmware must run (rule: text before `;`, stripped)."""
    lines = ["; arapp fault test", "G90", "M82"]
    if heat:
        lines += ["M140 S60", "M104 S210", "M190 S60", "M109 S210"]
    lines += ["G28", "G92 E0"]
    for i in range(n):
        if i % per_layer == 0:
            lines += [f";LAYER:{i // per_layer}", f"G1 Z{0.2 * (i // per_layer + 1):.1f} F600"]
        lines.append(f"G1 X{10 + i}.5 Y{20 + i % 7}.0 E{0.05 * (i + 1):.3f} F1800 ; move {i}")
    lines += ["M104 S0", "M140 S0", "M84"]
    expected = [line.split(";")[0].strip() for line in lines if line.split(";")[0].strip()]
    return lines, expected


def move(i: int) -> str:
    """The command text of move i of make_job."""
    return f"G1 X{10 + i}.5 Y{20 + i % 7}.0 E{0.05 * (i + 1):.3f} F1800"


def ran(emu: MarlinPty) -> list[str]:
    """What the firmware ran, without the host's own queries (M105, M110, M115, M155)."""
    emu.settle()
    return [c for c in emu.executed if not c.startswith(HOST)]


def connect(emu: MarlinPty, **kw) -> SerialPrinter:
    kw.setdefault("timeout", 1.0)
    kw.setdefault("boot_wait", 0.5)
    kw.setdefault("connect_timeout", 5.0)
    p = SerialPrinter(emu.port, 115200, **kw)
    p.connect()
    return p


def bounded(fn, *args, seconds: float = 30.0, **kw):
    """fn(*args) on a thread; fails the test (instead of hanging) when it does not end in time."""
    box = {}

    def work():
        try:
            box["value"] = fn(*args, **kw)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    t = threading.Thread(target=work, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"the print did not end within {seconds:g} s (hung)"
    if "error" in box:
        raise box["error"]
    return box["value"]


def write_gcode(tmp_path, lines) -> Path:
    path = tmp_path / "part.gcode"
    path.write_text("\n".join(lines) + "\n")
    return path


def resume_on_fresh_printer(job: Path, gcode: Path, **emu_kw):
    """Resume the saved job on a new emulator; (final state, emulator's commands, preamble)."""
    state = JobState.load(job)
    program = Program.from_file(gcode)
    state.check_program(program, gcode)
    preamble = resume_commands(state)
    with MarlinPty(**emu_kw) as emu:
        p = connect(emu, job_path=job)
        final = bounded(p.print_gcode, [], program=program, state=state, preamble=preamble)
        p.close()
        assert emu.heaters_off()
        return final, ran(emu), preamble


def stopped_safely_by(tmp_path, i: int, fault: str, match: str) -> tuple[JobState, int]:
    """Print make_job() with `fault` at move i; the link must raise PrinterReset (matching `match`)
    having run exactly the moves before i plus SAFE_STOP, heaters and motors off.
    Returns the saved job state and i's index in the expected commands."""
    lines, expected = make_job()
    job = tmp_path / "job.json"
    with MarlinPty(faults={move(i): fault}) as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(PrinterReset, match=match):
            bounded(p.print_gcode, lines)
        p.close()
        k = expected.index(move(i))
        assert ran(emu) == expected[:k] + SAFE_STOP
        assert emu.heaters_off() and not emu.motors_on
    return JobState.load(job), k


# -- 1. one ok lost while the firmware auto-reports temperatures ---------------------------------
def test_lost_ok_during_autoreport_is_noticed():
    lines, expected = make_job()
    with MarlinPty(autoreport=True, faults={move(10): "lose_ok"}) as emu:
        p = connect(emu)
        assert p.capabilities.get("AUTOREPORT_TEMP")
        state = bounded(p.print_gcode, lines, seconds=20)
        p.close()
        assert ran(emu) == expected
        assert emu.heaters_off()
        sent = [line.split()[0] for line in emu.received if line.startswith("N") and "M105" not in line]
    assert state.status == "done" and p.timeouts >= 1
    # Found by a poke (M105) whose `ok T:` accounts for the line: no line of the job went out twice.
    assert p.pokes >= 1 and len(sent) == len(set(sent))


# -- 2. link drops while a resume heats or re-homes; then a second --resume ----------------------
@pytest.mark.parametrize("where", ["M109 S210", "G28 X Y"])
def test_drop_during_resume_preamble_keeps_the_job_position(tmp_path, where):
    lines, expected = make_job()
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "job.json"
    with MarlinPty(faults={move(30): "drop"}) as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(LinkLost):
            bounded(p.print_gcode, lines, gcode_path=str(gcode))
        p.close()
        first = ran(emu)
    saved = JobState.load(job)
    k = expected.index(move(30)) + 1
    assert first == expected[:k] and saved.commands_done == k
    assert lines[saved.next_line - 1].startswith(move(30))

    # First resume: the link drops while the preamble heats (or homes X/Y).
    state = JobState.load(job)
    program = Program.from_file(gcode)
    with MarlinPty(faults={where: "drop"}) as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(LinkLost):
            bounded(p.print_gcode, [], program=program, state=state, preamble=resume_commands(state))
        p.close()
        assert not any(c in expected[k:] for c in ran(emu) if c.startswith("G1 X") and "F1800" in c)
    again = JobState.load(job)
    assert (again.next_line, again.commands_done) == (saved.next_line, saved.commands_done)

    # Second resume: exactly the rest of the job.
    final, second, preamble = resume_on_fresh_printer(job, gcode)
    assert final.status == "done"
    assert second == preamble + expected[k:]
    assert final.commands_done == final.commands_total == len(expected)


# -- 3. link drops just after the host's own M105 poll ------------------------------------------
def test_drop_after_a_host_poll_saves_the_right_line(tmp_path):
    lines, expected = make_job(n=120)
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "job.json"
    with MarlinPty(autoreport=False, faults={("M105", 6): "drop"}, move_s=0.005) as emu:
        p = connect(emu, job_path=job, temp_interval=0.05)
        with pytest.raises(LinkLost):
            bounded(p.print_gcode, lines, gcode_path=str(gcode))
        p.close()
        first = ran(emu)
        emu.settle()
        polls = sum(c == "M105" for c in emu.executed)
    assert polls == 6
    state = JobState.load(job)
    assert 0 < state.commands_done == len(first) < len(expected)
    assert first == expected[: len(first)]
    # next_line is the source line after the last command that ran.
    last_source = max(i for i, line in enumerate(lines) if line.split(";")[0].strip() == first[-1])
    assert state.next_line == last_source + 1
    final, second, preamble = resume_on_fresh_printer(job, gcode)
    assert second == preamble + expected[len(first):]
    assert final.commands_done == final.commands_total and final.status == "done"


# -- 4. cancel, then --resume of the cancelled job ----------------------------------------------
def test_cancelled_job_cannot_be_resumed(tmp_path, capsys):
    lines, expected = make_job(n=200)
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "job.json"
    with MarlinPty(move_s=0.003) as emu:
        p = connect(emu, job_path=job)

        def on_progress(s):
            if s.lines_done >= 40:
                p.cancel()

        state = bounded(p.print_gcode, lines, progress=on_progress, gcode_path=str(gcode))
        p.close()
        done = ran(emu)
        assert emu.heaters_off() and not emu.motors_on
    assert state.status == "cancelled"
    cut = len(done) - 7
    assert done[:cut] == expected[:cut] and done[cut:] == ["M104 S0", "M140 S0", "M107", "G91", "G1 Z10 F600",
                                                            "G90", "M84"]
    with MarlinPty() as emu:
        rc = main(["print", "--resume", str(job), "--port", emu.port, "--timeout", "1"])
        assert ran(emu) == []
    err = capsys.readouterr().err
    assert rc == 2 and "cannot be resumed" in err and len(err.strip().splitlines()) == 1
    from arapp.printing.link.job import check_resumable

    with pytest.raises(JobFileError, match="cancelled"):
        check_resumable(JobState.load(job), job)
    # The link refuses it too (the GUI resumes through it).
    with MarlinPty() as emu:
        p = connect(emu)
        with pytest.raises(LinkError, match="cannot be resumed"):
            p.print_gcode(lines, state=JobState.load(job))
        p.close()
        assert ran(emu) == []


# -- 5. Ctrl-C during `arapp print` ---------------------------------------------------------------
def _ctrl_c_as_in_a_terminal() -> None:
    """In the child before it runs: Ctrl-C at its default, as in a terminal (a suite started in the background,
    `cmd &` or nohup, hands its children SIGINT ignored, and Python then installs no handler for it)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_cancels_cleanly(tmp_path):
    lines, expected = make_job(n=400, per_layer=100)
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "part.gcode.job.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    with MarlinPty(move_s=0.01) as emu:
        proc = subprocess.Popen([sys.executable, "-m", "arapp", "print", str(gcode), "--port", emu.port,
                                 "--timeout", "2"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, preexec_fn=_ctrl_c_as_in_a_terminal)
        deadline = time.monotonic() + 30
        while len(ran(emu)) < 60 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        done = ran(emu)
        assert emu.heaters_off() and not emu.motors_on
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyError" not in err
    assert "cancelling the print" in err
    assert done[-7:] == ["M104 S0", "M140 S0", "M107", "G91", "G1 Z10 F600", "G90", "M84"]
    assert done[:-7] == expected[: len(done) - 7]
    saved = json.loads(job.read_text())
    assert saved["status"] == "cancelled" and "cancelled" in out


# -- 6. board resets without its `start` line, then asks `Resend: 1` ------------------------------
def test_silent_reset_stops_without_replay_and_resumes(tmp_path):
    lines, expected = make_job()
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "job.json"
    with MarlinPty(faults={move(20): "silent_reset"}) as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(PrinterReset) as info:
            bounded(p.print_gcode, lines, gcode_path=str(gcode))
        p.close()
        first = ran(emu)
        assert emu.resets == 1 and emu.heaters_off()
    k = expected.index(move(20))
    assert first == expected[:k] + SAFE_STOP  # nothing twice; heaters and motors off
    assert "reset" in str(info.value) and str(job) in str(info.value)
    state = JobState.load(job)
    assert state.status == "reset" and state.commands_done == k
    final, second, preamble = resume_on_fresh_printer(job, gcode)
    assert second == preamble + expected[k:] and final.status == "done"


# -- 7. a garbled `Resend: 0` --------------------------------------------------------------------
def test_garbled_resend_zero_stops_without_replay(tmp_path):
    state, k = stopped_safely_by(tmp_path, 15, "resend0", match="line 0")
    assert state.commands_done == k


# -- 8. the job file cannot be written -------------------------------------------------------------
def test_unwritable_job_file_refuses_before_printing(tmp_path, capsys):
    lines, _ = make_job()
    gcode = write_gcode(tmp_path, lines)
    with MarlinPty() as emu:
        rc = main(["print", str(gcode), "--port", emu.port, "--job", str(tmp_path / "no" / "such" / "job.json")])
        emu.settle()
        assert emu.executed == []
    err = capsys.readouterr().err
    assert rc == 2 and "cannot write the job file" in err and len(err.strip().splitlines()) == 1
    # The link itself refuses too (the GUI has no CLI check in front of it).
    with MarlinPty() as emu:
        p = connect(emu, job_path=tmp_path / "no" / "job.json")
        with pytest.raises(LinkError, match="nothing was sent"):
            p.print_gcode(lines)
        p.close()
        assert ran(emu) == []


def test_disk_full_mid_print_finishes_and_says_so(tmp_path, monkeypatch):
    lines, expected = make_job(n=80)
    job = tmp_path / "job.json"
    calls = {"n": 0}
    real_save = JobState.save

    def save(self, path):
        calls["n"] += 1
        if calls["n"] > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_save(self, path)

    original = getattr(SerialPrinter, "_save_now_and_then", None)

    def save_at_every_reply(link, state):
        link._last_save = 0.0  # without the 5 s spacing: the test sees saves mid-print
        original(link, state)

    monkeypatch.setattr(JobState, "save", save)
    monkeypatch.setattr(SerialPrinter, "_save_now_and_then", save_at_every_reply, raising=False)
    with MarlinPty(move_s=0.002) as emu:
        p = connect(emu, job_path=job)
        state = bounded(p.print_gcode, lines)
        p.close()
        assert ran(emu) == expected and emu.heaters_off()
    assert state.status == "done" and "No space left" in state.message


# -- 9. a resend request for a line never sent ----------------------------------------------------
def test_resend_for_a_line_never_sent_stops_safely(tmp_path):
    state, k = stopped_safely_by(tmp_path, 12, "resend99999", match="99999")
    assert state.status == "reset" and state.commands_done == k and "99999" in state.message


# -- 10. one error answered by two complete Resend/ok pairs, three times ----------------------------
@pytest.mark.parametrize("window", [1, 4])
def test_doubled_resend_rewinds_once(window):
    lines, expected = make_job(n=100)
    faults = {move(i): "double_resend" for i in (10, 40, 70)}
    with MarlinPty(faults=faults) as emu:
        p = connect(emu, window=window)
        state = bounded(p.print_gcode, lines)
        p.close()
        assert ran(emu) == expected and emu.heaters_off()
        numbered = sum(1 for line in emu.received if line.startswith("N"))
        assert emu.max_outstanding <= window
    assert state.status == "done"
    # Each damaged line goes out once more; a window of 4 may resend the (at most 3) lines behind it.
    assert numbered <= len(expected) + 2 + 3 * window + (3 * window if window > 1 else 0)
    assert p.timeouts == 0


# -- 11. a long blocking command without keep-alive; with keep-alive ---------------------------------
@pytest.mark.parametrize("command", ["G29", "M0"])
def test_silent_blocking_command_is_not_a_lost_link(command):
    lines, expected = make_job(heat=False)
    lines.insert(lines.index("G92 E0"), command)
    expected.insert(expected.index("G92 E0"), command)
    with MarlinPty(faults={command: "block:3"}) as emu:
        p = connect(emu, timeout=0.4, max_timeouts=2)
        state = bounded(p.print_gcode, lines)
        p.close()
        assert ran(emu) == expected
        sent = [line for line in emu.received if line.startswith("N") and "M105" not in line]
    assert state.status == "done"
    # 3 s of silence at a 0.4 s window: pokes (M105) went out, no line of the job was sent twice.
    assert p.timeouts >= 5 and p.pokes >= 1
    assert len(sent) == len({line.split()[0] for line in sent})


def test_keepalive_printer_blocking_command_and_a_lost_ok_after_it():
    """M0 answered after 2 s of `busy:` lines at a 0.5 s timeout; then the ok of a dwell is lost: once the
    printer has shown it sends keep-alives, a silent blocking command is a lost answer after the timeout."""
    lines, expected = make_job(heat=False)
    for c in ("M0", "G4 P100"):
        lines.insert(lines.index("G92 E0"), c)
        expected.insert(expected.index("G92 E0"), c)
    with MarlinPty(keepalive=True, faults={"M0": "block:2", "G4 P100": "lose_ok"}) as emu:
        p = connect(emu, timeout=0.5, max_timeouts=3)
        state = bounded(p.print_gcode, lines, seconds=20)
        p.close()
        assert ran(emu) == expected
    assert state.status == "done"
    assert p.timeouts == 1  # the lost ok of G4 only


# -- the firmware halts; the host fails ------------------------------------------------------------
def test_thermal_halt_says_why_before_a_resume(tmp_path, capsys):
    lines, expected = make_job()
    gcode = write_gcode(tmp_path, lines)
    job = tmp_path / "job.json"
    with MarlinPty(faults={move(25): "halt"}) as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(PrinterHalted, match="Thermal Runaway"):
            bounded(p.print_gcode, lines, gcode_path=str(gcode))
        p.close()
        k = expected.index(move(25))
        assert ran(emu) == expected[:k] and emu.heaters_off()
    state = JobState.load(job)
    assert state.status == "halted"
    with MarlinPty() as emu:
        rc = main(["print", "--resume", str(job), "--port", emu.port])
        assert ran(emu) == []
    err = capsys.readouterr().err
    assert rc == 2 and "Thermal Runaway" in err and "--after-halt" in err
    with MarlinPty() as emu:
        rc = main(["print", "--resume", str(job), "--port", emu.port, "--after-halt", "--timeout", "1"])
        second = ran(emu)
        assert emu.heaters_off()
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "Thermal Runaway" in captured.err
    assert second[-len(expected[k:]):] == expected[k:]


def test_host_failure_ends_like_every_other_stop(tmp_path):
    lines, expected = make_job()
    job = tmp_path / "job.json"

    def broken_progress(s):
        if s.lines_done >= 30:
            raise RuntimeError("display failed")

    with MarlinPty() as emu:
        p = connect(emu, job_path=job)
        with pytest.raises(LinkError, match="display failed") as info:
            bounded(p.print_gcode, lines, progress=broken_progress)
        p.close()
        done = ran(emu)
        assert emu.heaters_off() and not emu.motors_on
    assert done[-4:] == SAFE_STOP and done[:-4] == expected[: len(done) - 4]
    assert JobState.load(job).status == "failed" and str(job) in str(info.value)


# -- a hand-edited job file ---------------------------------------------------------------------------
@pytest.mark.parametrize("key, value, words", [
    ("x", float("nan"), "finite"),
    ("bed_target", 1e9, "maximum"),
    ("next_line", -50, ">= 0"),
    ("gcode_sha256", "", "sha256"),
    ("z", 500.0, "bed"),
    ("fan", "full", "whole number"),
])
def test_bad_job_file_is_refused_naming_file_and_field(tmp_path, capsys, key, value, words):
    lines, _ = make_job()
    gcode = write_gcode(tmp_path, lines)
    program = Program.from_lines(lines)
    data = {"format": "arapp-printjob/1", **JobState(gcode=str(gcode), gcode_sha256=program.sha256,
                                                      source_lines=len(lines), next_line=20, x=10.0, y=20.0,
                                                      z=0.2, status="link_lost").__dict__}
    data[key] = value
    job = tmp_path / "job.json"
    job.write_text(json.dumps(data))
    with pytest.raises(JobFileError) as info:
        JobState.load(job)
    assert str(job) in str(info.value) and f"'{key}'" in str(info.value) and words in str(info.value)
    with MarlinPty() as emu:
        rc = main(["print", "--resume", str(job), "--port", emu.port])
        emu.settle()
        assert emu.executed == []
    err = capsys.readouterr().err
    assert rc == 2 and f"'{key}'" in err and len(err.strip().splitlines()) == 1
