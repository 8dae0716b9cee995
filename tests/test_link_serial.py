"""Serial link against OctoPrint's VirtualPrinter on a pty, through real pyserial.

The reference for "executed exactly once, in order" is the printer's own
command handling (tests/virtual_printer.py records each command that reaches
it). Every G1 line below is distinct, so order and multiplicity are checked
one to one.
"""

from __future__ import annotations

import json
import threading
import time

import pytest

from arapp.printing.link import LinkLost, PrinterHalted, PrinterReset
from arapp.printing.link.job import JobState, Program, is_heating, resume_commands
from arapp.printing.link.serial_link import SerialPrinter

from virtual_printer import VirtualPrinterPty

# The plugin's defaults without 105:resend_with_timeout, which makes line 105
# unrunnable by any host (docs/domain.md §4); test_survives_resend_with_timeout has it.
FAULTS = ["100:resend", "110:missing_lineno", "115:checksum_mismatch"]
# Host lines before the program: N0 M110, N1 M115, N2 M155 (auto-report).
FIRST_PROGRAM_LINE = 3


def make_gcode(n: int = 300, layers: int = 3) -> list[str]:
    lines = ["; test job", "G90", "M82", "G92 E0"]
    per_layer = n // layers
    for i in range(n):
        if i % per_layer == 0 and i // per_layer < layers:
            lines.append(f";LAYER:{i // per_layer}")
            lines.append(f"G1 Z{0.2 * (i // per_layer + 1):.1f} F60000")
        # Distinct, short, fast moves (the printer simulates move time).
        lines.append(f"G1 X{10 + i % 50}.{i % 10} Y{20 + i % 37}.{i % 3} E{0.01 * (i + 1):.3f} F60000  ; move {i}")
    return lines


def expected_commands(lines) -> list[str]:
    """The commands a firmware must run, by a rule written here (not the host's parser): each line's
    text before `;`, surrounding blanks removed, blank results dropped."""
    return [line.split(";")[0].strip() for line in lines if line.split(";")[0].strip()]


def layer_of_command(lines, k: int) -> int:
    """The `;LAYER:n` in force at the k-th command (0-based) of `lines`, -1 before the first."""
    layer, seen = -1, -1
    for line in lines:
        if line.startswith(";LAYER:"):
            layer = int(line.split(":")[1])
        if line.split(";")[0].strip():
            seen += 1
            if seen == k:
                return layer
    raise IndexError(k)


def program_commands(executed: list[str], lines) -> list[str]:
    """The executed commands that belong to the program (not host M105/M115...)."""
    wanted = set(expected_commands(lines))
    return [c for c in executed if c in wanted]


def last_axes(commands):
    """Last X, Y, Z commanded by absolute G1 moves (the test programs use G90)."""
    pos = {}
    for c in commands:
        if c.startswith("G1"):
            pos.update((w[0], float(w[1:])) for w in c.split()[1:] if w[0] in "XYZ")
    return pos.get("X"), pos.get("Y"), pos.get("Z")


def connect(vp, **kw) -> SerialPrinter:
    kw.setdefault("timeout", 2.0)
    p = SerialPrinter(vp.port, 115200, **kw)
    p.connect()
    return p


@pytest.mark.parametrize("window", [1, 4])
def test_every_line_once_in_order_under_default_faults(window):
    gcode = make_gcode(300)
    with VirtualPrinterPty(simulated_errors=FAULTS) as vp:
        # rx_buffer: the VirtualPrinter's receive buffer is 64 bytes.
        p = connect(vp, window=window, rx_buffer=63)
        state = p.print_gcode(gcode)
        p.close()
        assert program_commands(vp.executed, gcode) == expected_commands(gcode)
        assert vp.printer._already_simulated_errors == {100, 110, 115}  # the faults did happen
    assert state.status == "done"
    assert state.commands_done == state.commands_total == len(expected_commands(gcode))
    assert state.layer == 2 and state.layer_count == 3


def test_slow_command_with_a_cancel_event_is_not_sent_again():
    """A dwell (or homing, or a long move) answers only when done; with a cancel Event to watch (as the
    GUI gives) the host looks at it every 0.25 s, which must not count as the printer not answering."""
    gcode = make_gcode(60)
    gcode.insert(gcode.index(";LAYER:1") + 1, "G4 P1500")
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        p = connect(vp, timeout=5.0)
        state = p.print_gcode(gcode, cancel=threading.Event())
        p.close()
        assert program_commands(vp.executed, gcode) == expected_commands(gcode)
    assert state.status == "done"
    assert p.timeouts == 0


@pytest.mark.parametrize("window", [1, 4])
def test_every_line_once_in_order_under_line_noise(window):
    """Damaged bytes on the wire (one line in 7) on top of the default faults."""
    gcode = make_gcode(250)
    with VirtualPrinterPty(simulated_errors=FAULTS, corrupt_every=7, marlin_resend=True) as vp:
        p = connect(vp, window=window, rx_buffer=63)
        p.print_gcode(gcode)
        p.close()
        assert vp.corrupted >= 30
        assert program_commands(vp.executed, gcode) == expected_commands(gcode)


def test_survives_virtual_printer_noise_setting():
    """`resend_ratio` (the printer's own noise) drops lines it reports as taken.

    No host can get those lines run (the printer asks for the next one); the
    host must finish, run nothing twice and lose nothing else.
    """
    gcode = make_gcode(200)
    with VirtualPrinterPty(simulated_errors=[], inject={40: "resend_ratio 10"}) as vp:
        p = connect(vp)
        state = p.print_gcode(gcode)
        p.close()
        swallowed = {vp.sent_command(n) for n in vp.printer.swallowed}
        assert len(swallowed) >= 10
        expected = [c for c in expected_commands(gcode) if c not in swallowed]
        assert program_commands(vp.executed, gcode) == expected
    assert state.status == "done"


def test_survives_resend_with_timeout():
    """The plugin's full default faults: line 105 is swallowed by the printer."""
    gcode = make_gcode(200)
    with VirtualPrinterPty() as vp:  # plugin defaults, 105:resend_with_timeout included
        p = connect(vp)
        state = p.print_gcode(gcode)
        p.close()
        lost = vp.sent_command(105)
        expected = [c for c in expected_commands(gcode) if c != lost]
        assert program_commands(vp.executed, gcode) == expected
    assert state.status == "done"
    assert p.timeouts >= 1  # line 105 got no answer


@pytest.mark.parametrize(
    "debug, message",
    [
        ("trigger_fatal_error_marlin", "Thermal Runaway, system stopped! Heater_ID: bed"),
        ("mintemp_error", "MINTEMP triggered!"),
    ],
)
def test_fatal_error_stops_with_printers_message(tmp_path, debug, message):
    gcode = make_gcode(200)
    job = tmp_path / "job.json"
    with VirtualPrinterPty(simulated_errors=[], inject={80: debug}) as vp:
        p = connect(vp, job_path=job)
        with pytest.raises(PrinterHalted) as info:
            p.print_gcode(gcode)
        p.close()
        ran = program_commands(vp.executed, gcode)
    assert message in str(info.value)
    expected = expected_commands(gcode)
    assert ran == expected[: len(ran)]  # stopped, in order, nothing twice
    assert len(ran) < 90
    saved = json.loads(job.read_text())
    assert saved["status"] == "halted" and message in saved["message"]


def test_dropped_link_leaves_resumable_job(tmp_path):
    gcode_path = tmp_path / "part.gcode"
    # Targets at the printer's ambient 21.3 C: the resume's heat waits return at once.
    gcode = ["M140 S21", "M104 S21", "G28"] + make_gcode(200)
    gcode_path.write_text("\n".join(gcode) + "\n")
    job = tmp_path / "job.json"
    expected = expected_commands(gcode)

    with VirtualPrinterPty(simulated_errors=[], inject={120: "drop_connection"}) as vp:
        p = connect(vp, job_path=job)
        with pytest.raises(LinkLost) as info:
            p.print_gcode(gcode, gcode_path=str(gcode_path))
        p.close()
        first = program_commands(vp.executed, gcode)
    assert str(job) in str(info.value)
    state = JobState.load(job)
    assert state.status == "link_lost"
    done = state.commands_done
    # What ran is the program's start; at most the one line in flight ran unacknowledged.
    assert first == expected[: len(first)]
    assert done <= len(first) <= done + 1
    # The drop came right after line N120 (its `ok` may or may not have got through).
    assert done in (120 - FIRST_PROGRAM_LINE, 120 - FIRST_PROGRAM_LINE + 1)
    # The saved state is where the printer was: position and heater targets.
    assert (state.x, state.y, state.z) == last_axes(expected[:done])
    assert state.bed_target == 21 and state.hotend_target == 21
    assert state.layer == layer_of_command(gcode, done - 1)

    program = Program.from_file(gcode_path)
    state.check_program(program, gcode_path)
    preamble = resume_commands(state)
    with VirtualPrinterPty(simulated_errors=[]) as vp2:
        p2 = connect(vp2, job_path=job)
        final = p2.print_gcode([], program=program, state=state, preamble=preamble)
        p2.close()
        second = vp2.executed
    assert final.status == "done"
    # After the host's own lines, the resume preamble, then exactly the rest of the job.
    start = second.index(preamble[0])
    assert second[start : start + len(preamble)] == preamble
    assert program_commands(second[start + len(preamble) :], gcode) == expected[done:]
    assert not any(c.startswith("G28") and "Z" in c for c in preamble)  # never home Z onto the part


def test_firmware_reset_mid_print_stops_job(tmp_path):
    gcode = make_gcode(200)
    with VirtualPrinterPty(simulated_errors=[], inject={60: "reset"}) as vp:
        p = connect(vp, job_path=tmp_path / "job.json")
        with pytest.raises(PrinterReset):
            p.print_gcode(gcode)
        p.close()
        ran = program_commands(vp.executed, gcode)
    assert ran == expected_commands(gcode)[: len(ran)]
    assert JobState.load(tmp_path / "job.json").status == "reset"


def test_heating_waits_report_progress():
    gcode = ["M140 S25", "M104 S26", "M190 S25", "M109 S26"] + make_gcode(30, layers=1)
    seen = []
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        p = connect(vp)
        p.print_gcode(gcode, progress=seen.append)
        p.close()
        assert program_commands(vp.executed, gcode) == expected_commands(gcode)
        bed, hot = vp.printer.bedTemp, vp.printer.temp[0]
    heating = [s for s in seen if s.state == "heating"]
    assert heating, "no progress reported while the printer heated"
    # Temperatures reported during the wait come from the printer and rise.
    readings = [s.temperatures["B"][0] for s in heating if "B" in s.temperatures]
    assert readings and min(readings) < 24.0
    assert bed >= 24.0 and hot >= 25.0
    assert seen[-1].state == "done" and seen[-1].percent == 100.0


def test_pause_resume_and_cancel():
    gcode = ["M140 S25", "M104 S25"] + make_gcode(800, layers=4)
    expected = expected_commands(gcode)
    marks = {}
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        p = connect(vp)

        def resume_later():
            time.sleep(0.4)
            marks["during"] = len(vp.executed)
            marks["resumed_at"] = len(vp.executed)
            p.resume()

        def on_progress(s):
            # Called on the streaming thread, at most every 0.1 s.
            if s.lines_done >= 100 and "paused" not in marks:
                p.pause()
                marks["paused"] = len(vp.executed)
                threading.Thread(target=resume_later, daemon=True).start()
            if "resumed_at" in marks and s.lines_done >= marks["resumed_at"] + 50:
                p.cancel()

        state = p.print_gcode(gcode, progress=on_progress)
        p.close()
        executed = list(vp.executed)
        hot, bed = vp.printer.targetTemp[0], vp.printer.bedTargetTemp
    assert state.status == "cancelled"
    # Paused: at most the line already in flight ran during the pause.
    assert marks["during"] - marks["paused"] <= 1
    cut = executed.index("M104 S0")  # the cancel sequence starts here
    ran = program_commands(executed[:cut], gcode)
    assert ran == expected[: len(ran)] and marks["resumed_at"] < len(ran) < len(expected)
    tail = executed[cut:]
    assert not any(is_heating(c) for c in tail)  # a cancel heats nothing
    assert tail[:3] == ["M104 S0", "M140 S0", "M107"]
    assert "G91" in tail and any(c.startswith("G1 Z") for c in tail) and tail[-1] == "M84"
    assert hot == 0 and bed == 0  # the printer's own heater targets


def test_checksum_matches_virtual_printer():
    """Framing agrees with the printer's own checksum routine."""
    from arapp.printing.link.protocol import frame

    with VirtualPrinterPty(simulated_errors=[]) as vp:
        for n, cmd in [(0, "M110 N0"), (17, "G1 X10.5 Y-3 E0.25 F1800"), (123456, "M104 S210")]:
            body, star, cs = frame(n, cmd).decode().strip().rpartition("*")
            assert int(cs) == vp.printer._calculate_checksum(body.encode())


def test_cancel_during_heat_wait_sends_m108_then_cools():
    gcode = ["M140 S28", "M190 S28"] + make_gcode(50, layers=1)
    with VirtualPrinterPty(simulated_errors=[]) as vp:
        p = connect(vp)

        def on_progress(s):
            if s.state == "heating":
                p.cancel()

        state = p.print_gcode(gcode, progress=on_progress)
        p.close()
        executed = list(vp.executed)
        bed = vp.printer.bedTargetTemp
    assert state.status == "cancelled"
    # M108 (break the wait; Marlin's emergency parser acts on it at once) right after the wait.
    i = executed.index("M190 S28")
    assert executed[i + 1] == "M108"
    # (A poke, M105, may come between when the wait outlasts the progress window: it changes nothing.)
    assert [c for c in executed[i + 2:] if c != "M105"][:3] == ["M104 S0", "M140 S0", "M107"]
    assert not any(c.startswith("G1 X") for c in executed)  # nothing of the part was printed
    assert bed == 0
