"""The serial protocol's state object (arapp.printing.link.stream.LineStream), one rule at a time, no I/O.

Expected values are written here from Marlin's protocol (docs/domain.md §4): frames
are built by hand (`N<n> <cmd>*<xor>`), times are given explicitly.
"""

from __future__ import annotations

import pytest

from arapp.printing.link import protocol as P
from arapp.printing.link.job import Command, JobState
from arapp.printing.link.stream import (
    BLOCKING,
    Item,
    LineStream,
    Step,
    Stop,
    StopReason,
    code_of,
)

HELLO = b"N0 M110 N0*125\n"


def framed(n: int, cmd: str) -> bytes:
    body = f"N{n} {cmd}"
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return f"{body}*{cs}\n".encode()


def program_items(texts, start_index=0):
    """Program items whose source line index is their position (+ start_index), layer 0."""
    return [Item(t, Command(start_index + i, t, 0)) for i, t in enumerate(texts)]


def stream(**kw) -> LineStream:
    s = LineStream(**kw)
    s.reset_numbering(HELLO, now=0.0)
    return s


def test_frames_are_numbered_from_one_after_the_hello():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G28", "G1 X1", "G1 X2"]), JobState(), now=0.0)
    assert s.frames_to_send(0.0) == [framed(1, "G28"), framed(2, "G1 X1")]
    assert s.frames_to_send(0.0) == []  # the window (2) is full
    assert s.on_ok(0.1) is Step.CONFIRMED
    assert s.frames_to_send(0.1) == [framed(3, "G1 X2")]
    assert s.max_inflight == 2


def test_rx_buffer_limits_bytes_in_flight():
    s = stream(window=4, rx_buffer=len(framed(1, "G1 X1")) * 2)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    assert len(s.frames_to_send(0.0)) == 2


def test_ok_confirms_program_lines_only():
    state = JobState(next_line=7, commands_done=3)
    s = stream(window=1)
    items = [Item("M105"), *program_items(["G1 X5 Y6 Z0.2"], start_index=10), Item("M106 S255")]
    s.start(items, state, now=0.0)
    s.frames_to_send(0.0)
    assert s.on_ok(0.1) is Step.CONFIRMED  # M105: a host line
    assert (state.next_line, state.commands_done) == (7, 3)
    s.frames_to_send(0.1)
    s.on_ok(0.2)
    assert (state.next_line, state.commands_done, state.x) == (11, 4, 5.0)
    s.frames_to_send(0.2)
    s.on_ok(0.3)  # host M106 (e.g. a resume preamble): the job's fan stays as the program left it
    assert (state.next_line, state.commands_done, state.fan) == (11, 4, 0)
    assert s.finished()


def test_ok_with_nothing_in_flight_is_ignored():
    s = stream()
    s.start([], None, now=0.0)
    assert s.on_ok(0.0) is Step.IGNORED
    assert s.confirmed == 0


def test_resend_rewinds_once_and_a_doubled_request_is_absorbed():
    s = stream(window=1)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    assert s.frames_to_send(0.0) == [framed(1, "G1 X1")]
    assert s.on_resend(1, 0.1) is Step.REWOUND
    assert s.on_ok(0.1) is Step.IGNORED  # the ok that goes with the request
    assert s.frames_to_send(0.1) == [framed(1, "G1 X1")]
    # The same request again (the firmware answered one error twice).
    assert s.on_resend(1, 0.2) is Step.IGNORED
    assert s.on_ok(0.2) is Step.IGNORED
    assert s.frames_to_send(0.2) == []  # no third copy
    assert s.on_ok(0.3) is Step.CONFIRMED and s.confirmed == 1


def test_resend_of_a_confirmed_line_or_line_zero_stops():
    s = stream(window=1)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    for t in (0.0, 0.1):
        s.frames_to_send(t)
        s.on_ok(t)
    s.frames_to_send(0.2)
    for line in (0, 1, 2):
        out = s.on_resend(line, 0.3)
        assert isinstance(out, Stop) and out.reason is StopReason.BAD_RESEND, line
    assert "nothing was sent twice" in s.on_resend(1, 0.3).message
    assert s.on_resend(3, 0.3) is Step.REWOUND  # the line in flight: a normal request


def test_resend_for_a_line_never_sent_stops():
    s = stream()
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    out = s.on_resend(99999, 0.1)
    assert isinstance(out, Stop) and out.reason is StopReason.BAD_RESEND and "99999" in out.message
    assert s.on_resend(2, 0.1) is Step.REWOUND  # top + 1: the printer has everything sent


def test_resend_of_a_later_line_confirms_the_ones_before():
    s = stream(window=3, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_resend(3, 0.1) is Step.REWOUND
    assert s.confirmed == 2 and s.next_number == 3


def test_stale_copies_absorb_their_own_replies():
    s = stream(window=3, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2, 3 in flight
    assert s.on_resend(1, 0.1) is Step.REWOUND
    assert s.on_ok(0.1) is Step.IGNORED
    # Lines 2 and 3 were refused by number: each gets Resend: 1 + ok, answering its stale copy.
    for t in (0.2, 0.3):
        assert s.on_resend(1, t) is Step.IGNORED
        assert s.on_ok(t) is Step.IGNORED
    assert s.confirmed == 0
    assert s.frames_to_send(0.3) == [framed(1, "G1 X1"), framed(2, "G1 X2"), framed(3, "G1 X3")]


def test_only_answers_reset_the_timer_for_a_plain_line():
    s = stream(timeout=2.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    temp = P.parse_reply("T:25.0 /0.0 B:25.0 /0.0 @:0 B@:0")
    busy = P.parse_reply("echo:busy: processing")
    for t in (0.5, 1.0, 1.5, 1.9):
        s.on_keepalive(temp, t)
        s.on_keepalive(busy, t)
    assert s.deadline(1.9) == pytest.approx(2.0)
    assert s.on_timeout(1.9) is Step.WAITING
    assert s.on_timeout(2.0) is Step.REWOUND and s.timeouts == 1


def test_busy_keeps_a_blocking_command_alive():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["G29"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.deadline(0.0) == pytest.approx(100.0)  # silent so far: a silent firmware gets minutes
    busy = P.parse_reply("echo:busy: processing")
    for t in range(1, 300):
        s.on_keepalive(busy, float(t))
        assert s.on_timeout(float(t) + 0.5) is Step.WAITING
    assert s.deadline(299.0) == pytest.approx(301.0)  # alive printer: timeout after the last keep-alive
    assert s.on_timeout(301.0) is Step.REWOUND


def test_heat_wait_temperatures_extend_only_until_the_target():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["M109 S210"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_keepalive(P.parse_reply("T:150.0 /210.0 B:25.0 /0.0 @:0 B@:0"), 5.0)
    assert s.deadline(5.0) == pytest.approx(7.0)
    s.on_keepalive(P.parse_reply("T:209.0 /210.0 B:25.0 /0.0 W:5"), 6.0)  # Marlin's countdown: still waiting
    assert s.deadline(6.0) == pytest.approx(8.0)
    s.on_keepalive(P.parse_reply("T:210.0 /210.0 B:25.0 /0.0 @:0 B@:0"), 7.0)  # auto-report at target
    assert s.deadline(7.0) == pytest.approx(8.0)


def test_temperatures_do_not_extend_a_non_heating_blocking_command():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["G28"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_keepalive(P.parse_reply("T:150.0 /210.0 B:25.0 /0.0"), 50.0)
    assert s.deadline(50.0) == pytest.approx(100.0)


def test_too_many_timeouts_stop():
    s = stream(timeout=1.0, max_timeouts=2)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_timeout(1.0) is Step.REWOUND
    s.frames_to_send(1.0)
    assert s.on_timeout(2.0) is Step.REWOUND
    s.frames_to_send(2.0)
    out = s.on_timeout(3.0)
    assert isinstance(out, Stop) and out.reason is StopReason.NO_ANSWER


def test_an_answer_resets_the_timeout_count():
    s = stream(timeout=1.0, max_timeouts=1)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_timeout(1.0) is Step.REWOUND
    s.frames_to_send(1.0)
    s.on_ok(1.5)
    s.frames_to_send(1.5)
    assert s.on_timeout(2.5) is Step.REWOUND  # a new first timeout, not the second


def test_recoverable_error_shortens_the_wait_for_its_resend():
    s = stream(timeout=10.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(3.0)
    assert s.deadline(3.0) == pytest.approx(4.0)


def test_wait_with_an_old_unanswered_line_rewinds():
    s = stream(timeout=10.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_wait(0.1) is Step.NOTHING  # just sent
    assert s.on_wait(0.5) is Step.REWOUND and s.next_number == 1


def test_actions():
    s = stream()
    assert s.on_action("pause") is Step.PAUSE and s.paused
    assert s.on_action("resume") is Step.RESUME and not s.paused
    assert s.on_action("cancel") is Step.CANCEL
    out = s.on_action("disconnect")
    assert isinstance(out, Stop) and out.reason is StopReason.DISCONNECT
    assert s.on_action("unknown thing") is Step.NOTHING
    assert s.on_start().reason is StopReason.RESET


def test_paused_stream_sends_only_resends():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.paused = True
    assert s.frames_to_send(0.0) == []


def test_cancel_replaces_the_rest_with_the_cancel_sequence():
    state = JobState(z=0.4)
    s = stream(window=1)
    s.start(program_items(["G1 X1", "G1 X2"]), state, now=0.0)
    s.frames_to_send(0.0)
    assert s.cancel(bed_height=210.0, emergency_parser=False, now=0.1) == []
    texts = [i.text for i in s.items]
    assert texts == ["M104 S0", "M140 S0", "M107", "G91", "G1 Z10 F600", "G90", "M84"]
    assert s.progress_kind() == "cancelling"
    assert s.finish(None).status == "cancelled" and state.status == "cancelled"


def test_cancel_during_a_heat_wait_sends_m108_past_the_window():
    s = stream(window=1)
    s.start(program_items(["M190 S60", "G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.progress_kind() == "heating"
    assert s.cancel(bed_height=None, emergency_parser=True, now=0.1) == [framed(2, "M108")]


def test_finish_names_each_way_out():
    for reason, status in [(StopReason.HALTED, "halted"), (StopReason.RESET, "reset"),
                           (StopReason.BAD_RESEND, "reset"), (StopReason.NO_ANSWER, "link_lost"),
                           (StopReason.LINK_LOST, "link_lost"), (StopReason.DISCONNECT, "link_lost"),
                           (StopReason.FAILED, "failed")]:
        state = JobState()
        s = stream()
        s.start([], state, now=0.0)
        f = s.finish(Stop(reason, "why"))
        assert (f.status, state.status, state.message) == (status, status, "why")
    state = JobState()
    s = stream()
    s.start([], state, now=0.0)
    assert s.finish(None).status == "done" and state.status == "done"


def test_poll_goes_out_between_program_lines():
    s = stream(window=1, poll_interval=1.0)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    assert s.frames_to_send(0.5) == [framed(1, "G1 X1")]
    s.on_ok(1.5)
    assert s.frames_to_send(1.5) == [framed(2, "M105")]
    s.on_ok(1.6)
    assert s.frames_to_send(1.6) == [framed(3, "G1 X2")]


def test_poll_while_paused():
    s = stream(window=1, poll_interval=1.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.paused = True
    assert s.poll_frame(0.5) is None
    assert s.poll_frame(1.5) == framed(1, "M105")
    assert s.poll_frame(3.0) is None  # one in flight


def test_code_of_and_blocking_set():
    assert code_of("g01 x1") == "G1" and code_of("M109 S210") == "M109" and code_of("") == ""
    assert {"M109", "M190", "G28", "G29", "M0", "M1", "M600", "M400"} <= BLOCKING
    assert "G1" not in BLOCKING
