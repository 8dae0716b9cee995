"""Reply classification on Marlin's own messages (Marlin 2.x language.h strings) and framing."""

from arapp.printing.link import protocol as P
from arapp.printing.link.job import Program, cancel_commands, JobState, is_heating


def test_marlin_replies():
    cases = {
        "ok": P.OK,
        "ok T:210.0 /210.0 B:60.0 /60.0 @:0 B@:0": P.OK,
        "Resend: 42": P.RESEND,
        "rs N42": P.RESEND,
        "Error:checksum mismatch, Last Line: 41": P.ERROR,
        "Error:Line Number is not Last Line Number+1, Last Line: 41": P.ERROR,
        "Error:No Checksum with line number, Last Line: 41": P.ERROR,
        "Error:Thermal Runaway, system stopped! Heater_ID: 0": P.FATAL,
        "Error:Printer halted. kill() called!": P.FATAL,
        "!! Lost communication with MCU 'mcu'": P.FATAL,
        "echo:busy: processing": P.BUSY,
        "busy: paused for user": P.BUSY,
        "wait": P.WAIT,
        "start": P.START,
        "echo:Unknown command: \"G999\"": P.ECHO,
        " T:201.3 E:0 W:?": P.TEMPERATURE,
        "//action:pause": P.ACTION,
    }
    for text, kind in cases.items():
        assert P.parse_reply(text).kind == kind, text
    assert P.parse_reply("Resend: 42").line == 42 and P.parse_reply("rs N42").line == 42
    temps = P.parse_reply("ok T:210.0 /215.0 B:60.0 /60.0 @:0 B@:0").temperatures
    assert temps == {"T": (210.0, 215.0), "B": (60.0, 60.0)}
    assert P.parse_reply(" T:201.3 E:0 W:?").temperatures == {"T": (201.3, None)}


def test_frame_matches_marlin_example():
    # Marlin's G-code reference (N and checksum): "N123 G1 X10*..." checksum is the XOR of the bytes.
    body = "N123 G1 X10"
    expected = 0
    for ch in body:
        expected ^= ord(ch)
    assert P.frame(123, "G1 X10") == f"{body}*{expected}\n".encode()


def test_program_layers_and_cancel_heats_nothing():
    prog = Program.from_lines(["G28 ; home", "", ";LAYER:0", "G1 Z0.2", ";LAYER:1", "G1 Z0.4 ; up"])
    assert [(c.text, c.layer) for c in prog.commands] == [("G28", -1), ("G1 Z0.2", 0), ("G1 Z0.4", 1)]
    assert prog.layer_count == 2
    state = JobState(z=205.0, hotend_target=210, bed_target=60)
    cmds = cancel_commands(state, bed_height=210.0)
    assert not any(is_heating(c) for c in cmds) and "G1 Z5 F600" in cmds and cmds[-1] == "M84"


def test_reply_texts():
    """What each kind of reply keeps as its text (the halt message shown to the user, echo lines...)."""
    cases = [
        ("ok T:210.0 /210.0", P.OK, "ok T:210.0 /210.0"),
        ("Resend: 42", P.RESEND, "Resend: 42"),
        ("Error:Thermal Runaway, system stopped!", P.FATAL, "Thermal Runaway, system stopped!"),
        ("error checksum mismatch", P.ERROR, "checksum mismatch"),
        ("Error MINTEMP triggered", P.FATAL, "MINTEMP triggered"),
        ("!! Lost communication", P.FATAL, "Lost communication"),
        ("!!", P.FATAL, "!!"),
        ("fatal: board gone", P.FATAL, "board gone"),
        ("start", P.START, "start"),
        ("wait", P.WAIT, "wait"),
        ("busy: processing", P.BUSY, "busy: processing"),
        ("//action:pause now", P.ACTION, "pause now"),
        ("// just a comment", P.OTHER, "// just a comment"),
        ("echo:Unknown command", P.ECHO, "Unknown command"),
        ("X:1.00 Y:2.00 T:20", P.OTHER, "X:1.00 Y:2.00 T:20"),  # a position report, not temperatures
        ("Marlin 2.1", P.OTHER, "Marlin 2.1"),
    ]
    for raw, kind, text in cases:
        reply = P.parse_reply(raw)
        assert (reply.kind, reply.text) == (kind, text), raw


def test_frame_replaces_what_ascii_cannot_carry():
    assert P.frame(1, "M117 Grüße") == b"N1 M117 Gr??e*" + str(P.checksum("N1 M117 Gr??e")).encode() + b"\n"
    assert P.checksum("ü") == ord("?")
