"""PrusaLink link against the real PrusaLink 0.8.1 (tests/prusalink_server.py) and, behind it on a
pseudo-terminal, the project's Marlin emulator answering as Prusa's MK3S firmware (tests/prusa_firmware.py).

Oracles: the G-code as the test writes it (its commands counted by the rule below: what is left of a line
once `;` comments and blanks are dropped), the file PrusaLink stored (read from its storage folder), and the
emulator's own list of the commands it executed (PrusaLink prints by sending the file's lines over the
serial port, adding its own M73/M117 lines: the job's lines are told apart by being the job's, each one
unique by its E value). The emulator runs `G4 P<ms>` as a real dwell, which sets the job's pace.
"""

from __future__ import annotations

import threading

import pytest

from arapp.printing.link.factory import PrusaLinkTarget, make_link
from arapp.printing.link.prusalink import PrusaLinkError, PrusaLinkLink, check_prusalink
from arapp.printing.link.webapi import save_api_key
from prusalink_server import PASSWORD, USER, prusalink_server  # noqa: F401 (the session fixture)


def commands(lines) -> list[str]:
    """G-code commands in `lines`: what remains of each line without its `;` comment, when not blank."""
    return [c for c in (line.split(";", 1)[0].strip() for line in lines) if c]


def job(n: int, layers: int = 3, dwell_every: int = 0, dwell_ms: int = 100) -> list[str]:
    """`n` extruder moves (each unique by its E value) in `layers` layers (`;LAYER:k`), the hotend target set
    to 200 °C first, a `G4 P<dwell_ms>` dwell after every `dwell_every` moves."""
    lines = ["; arapp test job", "G90", "M82", "M104 S200", "G92 E0"]
    per = n // layers
    for i in range(n):
        if i % per == 0 and i // per < layers:
            lines.append(f";LAYER:{i // per}")
        lines.append(f"G1 X{i % 100} E{0.01 * (i + 1):.3f} F6000")
        if dwell_every and i % dwell_every == dwell_every - 1:
            lines.append(f"G4 P{dwell_ms + i}")  # unique too
    return lines


def ran(firmware, since: int, lines) -> list[str]:
    """The job's commands among what the emulator executed after index `since`, in order."""
    ours = set(commands(lines))
    return [c for c in firmware.executed[since:] if c in ours]


def link_for(server) -> PrusaLinkLink:
    link = PrusaLinkLink(server.url, server.api_key, poll_interval=0.1)
    link.connect()
    return link


def test_print_round_trip_runs_our_exact_file(prusalink_server, tmp_path):
    fw = prusalink_server.firmware
    lines = job(300, dwell_every=30, dwell_ms=150)
    link = link_for(prusalink_server)
    assert link.version == "PrusaLink 0.8.1" and "MK3S" in link.printer_kind
    since = len(fw.executed)
    seen = []
    state = link.print_gcode(lines, progress=seen.append, gcode_path=str(tmp_path / "arapp-part.gcode"))
    link.close()
    assert state.status == "done"
    assert state.commands_done == state.commands_total == len(commands(lines)) == 314
    assert state.layer == 2 and state.layer_count == 3
    # PrusaLink stored our file byte for byte, and the emulator ran each of its commands once, in order
    assert (prusalink_server.storage / "arapp-part.gcode").read_bytes() == ("\n".join(lines) + "\n").encode()
    assert ran(fw, since, lines) == commands(lines)
    # progress reached the app while printing, never going back
    mid = [p for p in seen if p.state == "printing" and 0 < p.percent < 100]
    assert mid, [(p.state, p.percent) for p in seen]
    assert [p.percent for p in seen] == sorted(p.percent for p in seen)
    assert seen[-1].state == "done" and seen[-1].percent == 100.0


def test_pause_holds_the_emulator_then_resume_finishes(prusalink_server, tmp_path):
    fw = prusalink_server.firmware
    lines = job(120, dwell_every=10, dwell_ms=150)
    link = link_for(prusalink_server)
    since = len(fw.executed)
    held = {}

    def on_progress(p):
        if p.state == "printing" and not held and len(ran(fw, since, lines)) > 20:
            link.pause()
            held["at"] = None
        elif p.state == "paused" and held.get("at") is None:
            held["at"] = len(ran(fw, since, lines))
            # paused: nothing more of the job runs for a while (5 polls)
            held["polls"] = 0
        elif p.state == "paused":
            held["polls"] += 1
            if held["polls"] == 5:
                held["after"] = len(ran(fw, since, lines))
                link.resume()

    state = link.print_gcode(lines, progress=on_progress, gcode_path=str(tmp_path / "arapp-pause.gcode"))
    link.close()
    assert state.status == "done"
    assert 20 < held["at"] == held["after"] < len(commands(lines))
    assert "M601" in fw.prusa_queries and "M602" in fw.prusa_queries
    assert ran(fw, since, lines) == commands(lines)


def test_cancel_stops_the_job_and_the_firmware_turns_the_heaters_off(prusalink_server, tmp_path):
    fw = prusalink_server.firmware
    lines = job(300, dwell_every=5, dwell_ms=200)
    link = link_for(prusalink_server)
    since = len(fw.executed)
    stop = threading.Event()
    busy = {}

    def on_progress(p):
        if p.state == "printing" and "M104 S200" in fw.executed[since:] and not stop.is_set():
            # while it prints, a second link is refused in one line: at connect, and (past that check) by
            # PrusaLink itself at the upload
            other = PrusaLinkLink(prusalink_server.url, prusalink_server.api_key)
            with pytest.raises(PrusaLinkError) as err:
                other.connect()
            busy["connect"] = str(err.value)
            other._open_session()
            other.read_status()
            with pytest.raises(PrusaLinkError) as err:
                other.upload(b"G28\n", name="other.gcode")
            other.close()
            busy["message"] = str(err.value)
            stop.set()

    state = link.print_gcode(lines, progress=on_progress, cancel=stop, gcode_path=str(tmp_path / "arapp-stop.gcode"))
    link.close()
    assert state.status == "cancelled", state.message
    assert "not ready to print (state PRINTING)" in busy["connect"]
    assert "HTTP 409" in busy["message"] and "busy or not ready" in busy["message"] and "\n" not in busy["message"]
    done = ran(fw, since, lines)
    assert 0 < len(done) < len(commands(lines)) and done == commands(lines)[:len(done)]
    assert "M603" in fw.prusa_queries
    assert fw.printer.targetTemp[0] == 0.0 and fw.printer.bedTargetTemp == 0.0
    assert state.message == ""  # PrusaLink reported the targets off


def test_credentials(prusalink_server, tmp_path):
    # the API key from a file of mode 600, through the factory
    key_file = save_api_key(tmp_path / "key", prusalink_server.api_key)
    link = make_link(PrusaLinkTarget(prusalink_server.url, api_key_file=str(key_file)))
    link.connect()
    link.close()
    # digest: PrusaLink's user and password
    pw = save_api_key(tmp_path / "pw", PASSWORD)
    link = make_link(PrusaLinkTarget(prusalink_server.url, user=USER, password_file=str(pw)))
    link.connect()
    assert link.read_status()["printer"]["state"] in ("IDLE", "READY", "FINISHED", "STOPPED")
    link.close()
    # refusals: one line, naming what to check, never the secret
    ok, message, _ = check_prusalink(prusalink_server.url, "wrong-key-123")
    assert not ok and "refused the API key (HTTP 403)" in message and "wrong-key-123" not in message
    ok, message, _ = check_prusalink(prusalink_server.url, user=USER, password="wrong-password-9")
    assert not ok and "refused the user name or password (HTTP 401)" in message and "wrong-password" not in message
    ok, message, _ = check_prusalink(prusalink_server.url, prusalink_server.api_key)
    assert ok and message.startswith("PrusaLink 0.8.1")
    # a password file others can read is refused as the password file it is
    pw.chmod(0o644)
    with pytest.raises(ValueError, match="password file .* can be read by other users"):
        make_link(PrusaLinkTarget(prusalink_server.url, user=USER, password_file=str(pw)))
    assert repr(PrusaLinkLink(prusalink_server.url, "secret-key-xyz")) == f"PrusaLinkLink({prusalink_server.url!r})"


def test_arapp_print_cli_through_prusalink(prusalink_server, tmp_path, capsys):
    from arapp.cli import main

    fw = prusalink_server.firmware
    lines = job(30)
    gcode = tmp_path / "cli-part.gcode"
    gcode.write_text("\n".join(lines) + "\n")
    pw = save_api_key(tmp_path / "pw", PASSWORD)
    since = len(fw.executed)
    rc = main(["print", str(gcode), "--prusalink", prusalink_server.url, "--prusalink-user", USER,
               "--password-file", str(pw)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert out.out.startswith(f"done: {len(commands(lines))}/{len(commands(lines))} lines")
    assert ran(fw, since, lines) == commands(lines)
    assert PASSWORD not in out.out + out.err
    # a password given in the URL is refused in one line, never echoed
    rc = main(["print", str(gcode), "--prusalink", prusalink_server.url.replace("//", f"//{USER}:{PASSWORD}@"),
               "--api-key-file", str(pw)])
    err = capsys.readouterr().err
    assert rc == 2 and "holds a user name or password" in err and PASSWORD not in err and "Traceback" not in err


def test_temperatures_reach_the_app(prusalink_server, tmp_path):
    # PrusaLink turns the firmware's temperature reports on itself (M155 S2 C7), but its first try is lost while
    # it waits 8 s for the printer to boot and the next comes 60 s later; the job turns them on the same way at
    # its start instead of the test waiting a minute: PrusaLink reads the reports whoever asked for them
    fw = prusalink_server.firmware
    lines = ["M155 S2 C7", "M104 S215", "M140 S60"] + [f"G4 P{1200 + i}" for i in range(3)] + ["G1 X5 E0.2 F600"]
    link = link_for(prusalink_server)
    seen = []
    state = link.print_gcode(lines, progress=seen.append, gcode_path=str(tmp_path / "arapp-heat.gcode"))
    link.close()
    assert state.status == "done"
    # the emulator's own targets (the oracle) are what the app was shown
    assert (fw.printer.targetTemp[0], fw.printer.bedTargetTemp) == (215.0, 60.0)
    shown = [(p.temperatures["T"][1], p.temperatures["B"][1]) for p in seen if "T" in p.temperatures]
    assert (215.0, 60.0) in shown, shown
    actual = seen[-1].temperatures["T"][0]
    assert abs(actual - fw.printer.temp[0]) < 30.0  # a report at most 2 s old of a hotend heating at its pace


def test_a_job_right_after_another_waits_for_the_end_screen(prusalink_server, tmp_path):
    # PrusaLink shows an ended job FINISHED for a while (PRINT_END_S here) and refuses a new one meanwhile: the
    # link waits that out, saying so, instead of failing on PrusaLink's 409
    fw = prusalink_server.firmware
    first, second = job(12), [line.replace("G1 X", "G1 Y") for line in job(12)]
    link = link_for(prusalink_server)
    assert link.print_gcode(first, gcode_path=str(tmp_path / "first.gcode")).status == "done"
    assert prusalink_server.status()["printer"]["state"] == "FINISHED"
    since = len(fw.executed)
    seen = []
    state = link.print_gcode(second, progress=seen.append, gcode_path=str(tmp_path / "second.gcode"))
    link.close()
    assert state.status == "done"
    assert any(p.message == "waiting for the printer to leave FINISHED (the last job's end)" for p in seen)
    assert ran(fw, since, second) == commands(second)
