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
    s.reset_numbering(now=0.0)
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


def test_the_same_request_after_its_own_error_is_a_new_one():
    """OctoPrint's VirtualPrinter refuses the copy sent for a request again, with an Error line first."""
    s = stream(window=1)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(0.1)
    assert s.on_resend(1, 0.1) is Step.REWOUND
    s.on_ok(0.1)
    assert s.frames_to_send(0.1) == [framed(1, "G1 X1")]
    s.on_error(0.2)
    assert s.on_resend(1, 0.2) is Step.REWOUND
    assert s.on_ok(0.2) is Step.IGNORED
    assert s.frames_to_send(0.2) == [framed(1, "G1 X1")]


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
    # Lines 2 and 3 were refused by number: each gets Error + Resend: 1 + ok, answering its stale copy.
    for t in (0.2, 0.3):
        s.on_error(t)
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
    assert s.deadline() == pytest.approx(2.0)
    assert s.on_timeout(1.9) is Step.WAITING
    assert s.on_timeout(2.0) is Step.REWOUND and s.timeouts == 1


def test_busy_keeps_a_blocking_command_alive():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["G29"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.deadline() == pytest.approx(100.0)  # silent so far: a silent firmware gets minutes
    busy = P.parse_reply("echo:busy: processing")
    for t in range(1, 300):
        s.on_keepalive(busy, float(t))
        assert s.on_timeout(float(t) + 0.5) is Step.WAITING
    assert s.deadline() == pytest.approx(301.0)  # alive printer: timeout after the last keep-alive
    assert s.on_timeout(301.0) is Step.REWOUND


def test_heat_wait_temperatures_extend_only_until_the_target():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["M109 S210"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_keepalive(P.parse_reply("T:150.0 /210.0 B:25.0 /0.0 @:0 B@:0"), 5.0)
    assert s.deadline() == pytest.approx(7.0)
    s.on_keepalive(P.parse_reply("T:209.0 /210.0 B:25.0 /0.0 W:5"), 6.0)  # Marlin's countdown: still waiting
    assert s.deadline() == pytest.approx(8.0)
    s.on_keepalive(P.parse_reply("T:210.0 /210.0 B:25.0 /0.0 @:0 B@:0"), 7.0)  # auto-report at target
    assert s.deadline() == pytest.approx(8.0)


def test_temperatures_do_not_extend_a_non_heating_blocking_command():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["G28"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_keepalive(P.parse_reply("T:150.0 /210.0 B:25.0 /0.0"), 50.0)
    assert s.deadline() == pytest.approx(100.0)


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
    assert s.deadline() == pytest.approx(4.0)


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


# -- rules pinned by mutation testing (docs/mutation-testing.md) ------------------------------------
def test_nothing_left_to_send_is_an_empty_list():
    s = stream()
    s.start([], JobState(), now=0.0)
    assert s.frames_to_send(0.0) == [] and s.finished()


def test_finished_needs_every_condition():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    assert not s.finished()  # items left
    s.frames_to_send(0.0)
    assert not s.finished()  # in flight
    s.on_ok(0.1)
    s.on_ok(0.2)
    assert s.finished()
    s.on_timeout(100.0)  # nothing in flight: no timer
    s.next_number = s.top  # a rewound top line not sent yet
    assert not s.finished()


def test_paused_stream_still_resends_up_to_the_top_line():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.paused = True
    assert s.on_timeout(10.0) is Step.REWOUND
    assert s.frames_to_send(10.0) == [framed(1, "G1 X1"), framed(2, "G1 X2")]
    assert s.frames_to_send(10.0) == []


def test_timer_starts_when_a_line_goes_out_after_an_idle_time():
    s = stream(timeout=2.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.paused = True
    s.frames_to_send(0.0)
    s.paused = False
    s.frames_to_send(50.0)
    assert s.deadline() == pytest.approx(52.0)


def test_history_keeps_the_last_lines_only():
    s = stream(window=1, history_len=2)
    s.start(program_items([f"G1 X{i}" for i in range(1, 6)]), JobState(), now=0.0)
    for t in range(5):
        s.frames_to_send(float(t))
        s.on_ok(float(t) + 0.5)
    assert sorted(s.history) == [4, 5]


def test_resend_bookkeeping():
    s = stream(window=2, rx_buffer=1000, timeout=5.0)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2
    s.on_error(1.0)
    assert s.deadline() == pytest.approx(2.0)
    assert s.on_resend(2, 1.5) is Step.REWOUND  # confirms 1
    assert s.confirmed == 1 and s.resends == 1 and s.epoch == 1
    assert s.deadline() == pytest.approx(6.5)  # the answer reset the timer and the error wait
    assert s.on_resend(5, 1.6).reason is StopReason.BAD_RESEND  # top + 2: never sent
    assert s.on_resend(4, 1.6) is not None and s.resends == 3


def test_resend_with_nothing_in_flight():
    s = stream(window=1)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_ok(0.1)
    assert s.on_resend(2, 0.2) is Step.REWOUND and s.next_number == 2


def test_two_rewinds_make_both_older_epochs_stale():
    s = stream(window=3, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2, 3 (epoch 0)
    s.on_timeout(20.0)  # epoch 1: nothing in flight
    s.frames_to_send(20.0)  # 1, 2, 3 again (epoch 1)
    assert s.on_resend(1, 20.1) is Step.REWOUND  # epoch 2
    assert s.epoch == 2
    s.on_ok(20.1)
    assert [c.epoch for c in s.inflight] == [1, 1]
    assert s.on_resend(1, 20.2) is Step.IGNORED  # a stale copy's request


def test_a_stale_copy_asked_for_twice_absorbs_the_second_ok():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2
    assert s.on_resend(1, 0.1) is Step.REWOUND
    assert s.on_ok(0.1) is Step.IGNORED
    s.on_error(0.2)
    assert s.on_resend(1, 0.2) is Step.IGNORED  # stale copy 2's request
    assert s.absorb_oks == 0 and s.inflight[0].rejected
    assert s.on_resend(1, 0.2) is Step.IGNORED  # ... doubled (no Error line of its own)
    assert s.absorb_oks == 1
    assert s.on_ok(0.2) is Step.IGNORED and s.on_ok(0.2) is Step.IGNORED
    assert s.absorb_oks == 0 and s.confirmed == 0


def test_a_new_request_after_progress_is_not_a_double():
    s = stream(window=1)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_resend(1, 0.1) is Step.REWOUND
    s.on_ok(0.1)
    s.frames_to_send(0.1)
    s.on_ok(0.2)  # line 1 ran
    s.frames_to_send(0.2)
    assert s.on_resend(2, 0.3) is Step.REWOUND  # a different request: honoured


def test_error_without_a_line_in_flight_sets_no_timer():
    s = stream(timeout=5.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.on_error(1.0)
    s.frames_to_send(10.0)
    assert s.deadline() == pytest.approx(15.0)


def test_wait_counts_as_a_timeout_only_for_an_old_line():
    s = stream(timeout=10.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(10.0)
    assert s.on_wait(10.1) is Step.NOTHING and s.timeouts == 0
    assert s.on_wait(10.5) is Step.REWOUND and s.timeouts == 1
    s.frames_to_send(10.5)
    assert s.on_wait(11.0) is Step.REWOUND and s.timeouts == 2


def test_keepalive_resets_the_timeout_count_and_marks_the_printer():
    s = stream(timeout=1.0, max_timeouts=1, blocking_timeout=100.0)
    s.start(program_items(["G28", "G29"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_timeout(100.0) is Step.REWOUND and s.consecutive_timeouts == 1
    s.frames_to_send(100.0)
    s.on_keepalive(P.parse_reply("busy: processing"), 100.5)
    assert s.consecutive_timeouts == 0 and s.keepalive_seen
    s.on_ok(101.0)
    s.frames_to_send(101.0)  # G29: the printer sends keep-alives, silence is a lost answer after the timeout
    assert s.deadline() == pytest.approx(102.0)


def test_heat_wait_keepalive_resets_the_timeout_count():
    s = stream(timeout=1.0, blocking_timeout=100.0)
    s.start(program_items(["M190 S60"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_timeout(100.0)
    s.frames_to_send(100.0)
    s.on_keepalive(P.parse_reply("T:25.0 /0.0 B:40.0 /60.0"), 100.5)
    assert s.consecutive_timeouts == 0 and s.deadline() == pytest.approx(101.5)


@pytest.mark.parametrize("command, reply, alive", [
    ("M109", "T:150.0 /0.0", False),  # no target to compare with
    ("M190 S60", "T:25.0 /0.0", False),  # no bed reading
    ("M190 S60", "B:57.0 /60.0", False),  # within 3 C
    ("M190 S60", "B:56.9 /60.0", True),
    ("M109 S210", "T0:100.0 /210.0", True),
])
def test_heat_wait_reading(command, reply, alive):
    s = stream(timeout=1.0, blocking_timeout=100.0)
    s.start(program_items([command]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_keepalive(P.parse_reply(reply), 50.0)
    assert s.deadline() == pytest.approx(51.0 if alive else 100.0)


def test_timeout_counters_and_message():
    s = stream(timeout=1.5, max_timeouts=2)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(0.5)
    assert s.on_timeout(1.5) is Step.REWOUND  # the error's 1 s wait
    assert s.error_seen_at is None and s.deadline() is None
    s.frames_to_send(1.5)
    assert s.deadline() == pytest.approx(3.0)
    s.on_timeout(3.0)
    s.frames_to_send(3.0)
    out = s.on_timeout(4.5)
    assert s.timeouts == 3 and out.message == "the printer stopped answering (no reply for 1.5 s, 2 times)"


def test_action_and_start_messages():
    s = stream()
    assert s.on_action("") is Step.NOTHING
    assert s.on_action("disconnect").message == "the printer asked the host to disconnect"
    assert s.on_start().message == "the printer restarted (firmware reset) during the print"


def test_cancel_while_paused_sends_the_cancel_sequence():
    state = JobState(z=205.0)
    s = stream(window=1)
    s.start(program_items(["G1 X1"]), state, now=0.0)
    s.paused = True
    assert s.progress_kind() == "paused"
    s.cancel(bed_height=210.0, emergency_parser=True, now=0.0)  # nothing in flight: no M108
    assert not s.paused
    assert s.frames_to_send(0.0) == [framed(1, "M104 S0")]
    assert [i.text for i in s.items][3] == "G1 Z5 F600"  # lift capped by the bed's height
    assert s.cancel(bed_height=210.0, emergency_parser=True, now=0.0) == []  # once


def test_no_m108_unless_a_heat_wait_with_an_emergency_parser():
    s = stream(window=1)
    s.start(program_items(["G28", "G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.progress_kind() == "printing"
    assert s.cancel(bed_height=None, emergency_parser=True, now=0.1) == []
    s2 = stream(window=1)
    s2.start(program_items(["M109 S200"]), JobState(), now=0.0)
    s2.frames_to_send(0.0)
    assert s2.cancel(bed_height=None, emergency_parser=False, now=0.1) == []


def test_m108_while_resending_goes_out_in_order():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["M190 S60", "G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2
    s.on_timeout(1000.0)  # rewind to 1
    s.window = 1
    assert s.frames_to_send(1000.0) == [framed(1, "M190 S60")]  # line 2 is still to be resent
    assert s.cancel(bed_height=None, emergency_parser=True, now=1000.1) == []
    assert s.items[0].text == "M108" and s.top == 2


def test_m108_is_kept_for_a_resend():
    s = stream(window=1)
    s.start(program_items(["M109 S200", "G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.cancel(bed_height=None, emergency_parser=True, now=0.1) == [framed(2, "M108")]
    assert s.top == 2 and len(s.inflight) == 2 and s.inflight[1].sent_at == 0.1
    s.on_timeout(100.0 + 600.0)
    assert s.frames_to_send(700.0) == [framed(1, "M109 S200")]
    s.on_ok(700.1)
    assert s.frames_to_send(700.1) == [framed(2, "M108")]


def test_finish_keeps_the_stop_and_clears_old_messages():
    state = JobState(message="old")
    s = stream()
    s.start([], state, now=0.0)
    stop = Stop(StopReason.HALTED, "Thermal Runaway")
    assert s.finish(stop).stop is stop
    s.cancelling = True
    f = s.finish(None)
    assert (f.status, f.message, f.stop, state.message) == ("cancelled", "cancelled", None, "")
    s.cancelling = False
    f = s.finish(None)
    assert (f.status, f.message, state.message) == ("done", "", "")


def test_poll_frames_while_paused_and_their_resend():
    s = stream(window=1, poll_interval=1.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.paused = True
    assert s.poll_frame(1.5) == framed(1, "M105")
    s.on_ok(1.6)
    assert s.poll_frame(2.0) is None  # 0.5 s after the last poll
    assert s.poll_frame(2.5) == framed(2, "M105")
    assert s.top == 2 and s.history[2][1].text == "M105"
    s.on_timeout(20.0)
    assert s.frames_to_send(20.0) == [framed(2, "M105")]  # resent while paused
    s2 = stream(window=1, poll_interval=0.0)
    s2.start([], JobState(), now=0.0)
    s2.paused = True
    assert s2.poll_frame(100.0) is None


def test_ok_for_an_already_confirmed_copy_is_ignored():
    s = stream(window=2, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_resend(3, 0.1)  # confirms 1 and 2
    assert s.on_ok(0.1) is Step.IGNORED  # the request's own ok (head rejected)
    assert s.on_ok(0.2) is Step.IGNORED  # copy 2: confirmed already


def test_code_of_takes_the_first_word():
    assert code_of("G28 X Y") == "G28" and code_of("  m400  ") == "M400"
