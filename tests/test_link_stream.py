"""The serial protocol's state object (arapp.printing.link.stream.LineStream), one rule at a time, no I/O.

Expected values are written here from Marlin's protocol (docs/domain.md §4): frames
are built by hand (`N<n> <cmd>*<xor>`), times are given explicitly.
"""

from __future__ import annotations

import random
from collections import deque

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


def test_temperature_lines_are_life_not_progress_busy_is_both():
    """Liveness and progress are separate: a temperature report restarts neither the window nor
    (alone) the stop; `busy:` restarts the window for any line (Marlin sends it for a slow move too)."""
    temp = P.parse_reply("T:25.0 /0.0 B:25.0 /0.0 @:0 B@:0")
    s = stream(timeout=2.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    for t in (0.5, 1.0, 1.5, 1.9):
        s.on_line(t)
        s.on_keepalive(temp, t)
    assert s.deadline() == pytest.approx(2.0) and s.last_byte == 1.9
    assert s.on_timeout(1.9) is Step.WAITING
    assert s.on_timeout(2.0) is Step.POKE and s.timeouts == 1
    b = stream(timeout=2.0)
    b.start(program_items(["G1 X1"]), JobState(), now=0.0)
    b.frames_to_send(0.0)
    for t in (0.5, 1.0, 1.5, 1.9):
        b.on_line(t)
        b.on_keepalive(P.parse_reply("busy: processing"), t)
    assert b.deadline() == pytest.approx(3.9) and b.keepalive_seen


def test_busy_keeps_a_command_alive_without_pokes():
    s = stream(timeout=2.0, blocking_timeout=100.0)
    s.start(program_items(["M600"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.deadline() == pytest.approx(2.0)  # the window runs from the line
    for t in range(1, 300):  # Marlin's host keep-alive while it waits for the user, every second
        s.on_line(float(t))
        s.on_keepalive(P.parse_reply("echo:busy: paused for user"), float(t))
        assert s.on_timeout(float(t) + 0.5) is Step.WAITING
    assert s.pokes == 0 and s.timeouts == 0
    assert s.deadline() == pytest.approx(301.0)  # the keep-alives stop: a poke after one window
    assert s.on_timeout(301.0) is Step.POKE


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
    s.on_keepalive(P.parse_reply("T:150.0 /210.0 B:25.0 /0.0"), 1.0)
    assert s.deadline() == pytest.approx(2.0)


def test_silence_for_the_liveness_limit_stops():
    s = stream(timeout=1.0, max_timeouts=2)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_timeout(1.0) is Step.POKE
    assert s.frames_to_send(1.0) == [framed(2, "M105")]  # the poke: the next number, never line 1 again
    out = s.on_timeout(2.0)
    assert isinstance(out, Stop) and out.reason is StopReason.NO_ANSWER
    assert out.message == "the printer stopped answering (nothing at all received for 2.0 s; the limit is 2 s)"


def test_any_line_keeps_the_printer_alive_but_not_for_ever():
    """Temperature lines in every window: no "stopped answering"; but with no progress for the same
    limit the stream still stops (it never waits for ever)."""
    s = stream(timeout=1.0, max_timeouts=3, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    for t in (1.0, 2.0):
        s.on_line(t - 0.5)
        assert s.on_timeout(t) is Step.POKE
        s.frames_to_send(t)
    s.on_line(2.5)
    out = s.on_timeout(3.0)
    assert isinstance(out, Stop) and "still talks but has acknowledged no line for 3.0 s" in out.message
    s2 = stream(timeout=1.0, max_timeouts=1)
    s2.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s2.frames_to_send(0.0)
    s2.on_ok(0.9)
    s2.frames_to_send(0.9)
    assert s2.on_timeout(1.9) is Step.POKE  # an answer restarted both timers


def test_recoverable_error_shortens_the_wait_for_its_resend():
    s = stream(timeout=10.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(3.0)
    assert s.deadline() == pytest.approx(4.0)


def test_wait_with_an_old_unanswered_line_pokes():
    s = stream(timeout=10.0)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_wait(0.1) is Step.NOTHING  # just sent
    assert s.on_wait(0.5) is Step.POKE and s.next_number == 2
    assert s.frames_to_send(0.5) == [framed(2, "M105")]


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
    assert s.on_resend(1, 10.0) is Step.REWOUND
    s.on_ok(10.0)
    s.on_error(10.0)
    assert s.on_resend(1, 10.0) is Step.IGNORED  # line 2's stale copy
    s.on_ok(10.0)
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
    assert s.on_resend(1, 0.1) is Step.REWOUND  # epoch 1
    s.on_ok(0.1)
    s.frames_to_send(0.1)  # 1 again (window: 2 stale copies + 1)
    s.on_error(0.2)
    assert s.on_resend(1, 0.2) is Step.IGNORED  # copy 2 of epoch 0
    s.on_ok(0.2)
    s.frames_to_send(0.2)  # 2 (epoch 1)
    s.on_error(0.25)
    assert s.on_resend(1, 0.25) is Step.IGNORED  # copy 3 of epoch 0
    s.on_ok(0.25)
    s.on_error(0.3)
    assert s.on_resend(1, 0.3) is Step.REWOUND  # copy 1 of epoch 1 refused: a new request, epoch 2
    assert s.epoch == 2
    s.on_ok(0.3)
    assert [c.epoch for c in s.inflight] == [1]
    s.on_error(0.4)
    assert s.on_resend(1, 0.4) is Step.IGNORED  # a stale copy's request


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
    assert s.on_wait(10.5) is Step.POKE and s.timeouts == 1
    s.frames_to_send(10.5)
    assert s.on_wait(10.6) is Step.NOTHING  # the poke has just gone out
    assert s.on_wait(11.0) is Step.POKE and s.timeouts == 2


def test_keepalive_resets_the_timeout_count_and_marks_the_printer():
    s = stream(timeout=1.0, max_timeouts=1, blocking_timeout=100.0)
    s.start(program_items(["G28", "G29"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.give_up_after() == 100.0  # a silent blocking command: minutes
    assert s.on_timeout(1.0) is Step.POKE and s.consecutive_timeouts == 1
    s.frames_to_send(1.0)
    s.on_keepalive(P.parse_reply("busy: processing"), 1.5)
    assert s.consecutive_timeouts == 0 and s.keepalive_seen
    s.on_ok(2.0)
    s.frames_to_send(2.0)
    # G29 on a printer that sends keep-alives: its silence counts like any other.
    assert s.give_up_after() == 1.0 and s.deadline() == pytest.approx(3.0)


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
    assert s.deadline() == pytest.approx(51.0 if alive else 1.0)


def test_error_without_resend_is_the_whole_answer_then_a_poke():
    """The VirtualPrinter's missing-line-number fault: `Error:` and nothing else. After the short error
    wait the copy counts as answered (not confirmed) and a poke goes out; the firmware's refusal of the
    poke asks for the line, which then goes out again."""
    s = stream(timeout=1.5, rx_buffer=1000)
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(0.5)
    assert s.deadline() == pytest.approx(1.5)
    assert s.on_timeout(1.5) is Step.POKE and s.error_seen_at is None and not s.inflight
    assert s.frames_to_send(1.5) == [framed(2, "M105")]
    s.on_error(1.6)
    assert s.on_resend(1, 1.6) is Step.REWOUND
    s.on_ok(1.6)
    assert s.frames_to_send(1.6) == [framed(1, "G1 X1")]
    assert s.timeouts == 1 and s.confirmed == 0


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
    s.on_resend(1, 0.5)  # rewind to 1
    s.on_ok(0.5)
    s.window = 1
    assert s.frames_to_send(0.5) == []  # line 2's copy (refused in its turn) still fills the window
    s.on_error(0.6)
    s.on_resend(1, 0.6)
    s.on_ok(0.6)
    assert s.frames_to_send(0.6) == [framed(1, "M190 S60")]  # line 2 is still to be resent
    assert s.cancel(bed_height=None, emergency_parser=True, now=1000.1) == []
    assert s.items[0].text == "M108" and s.top == 2


def test_m108_is_kept_for_a_resend():
    s = stream(window=1)
    s.start(program_items(["M109 S200", "G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.cancel(bed_height=None, emergency_parser=True, now=0.1) == [framed(2, "M108")]
    assert s.top == 2 and len(s.inflight) == 2 and s.inflight[1].sent_at == 0.1
    s.on_error(0.2)
    s.on_resend(1, 0.2)
    s.on_ok(0.2)
    s.on_error(0.3)
    assert s.on_resend(1, 0.3) is Step.IGNORED  # the M108 copy, refused by number
    s.on_ok(0.3)
    assert s.frames_to_send(0.3) == [framed(1, "M109 S200")]
    s.on_ok(0.4)
    assert s.frames_to_send(0.4) == [framed(2, "M108")]


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
    s.on_error(20.0)
    s.on_resend(2, 20.0)
    s.on_ok(20.0)
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


# -- issue #27: a busy printer, pokes, duplicate requests ------------------------------------------
def test_a_busy_printer_gets_pokes_never_its_line_again():
    """Line 1 keeps the firmware busy for 3.5 windows: each window without progress sends a numbered
    M105 on the next free number (while the buffer has room), never line 1; the answers, in order,
    confirm everything and the job goes on with line 4."""
    s = stream(window=1, timeout=1.0, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    assert s.frames_to_send(0.0) == [framed(1, "G1 X1")]
    sent = []
    for t in (1.0, 2.0, 3.0):
        assert s.on_timeout(t) is Step.POKE
        sent += s.frames_to_send(t)
    assert sent == [framed(2, "M105"), framed(3, "M105"), framed(4, "M105")]
    s.on_ok(3.5)  # line 1 done
    assert s.confirmed == 1 and s.frames_to_send(3.5) == []  # three pokes still in flight
    for _ in range(3):
        s.on_ok(3.6, temperatures=True)
    assert s.confirmed == 4 and s.frames_to_send(3.6) == [framed(5, "G1 X2")]
    assert s.state.commands_done == 1


def test_pokes_stop_at_the_receive_buffer():
    line = framed(1, "G1 X1")
    s = stream(window=1, timeout=1.0, rx_buffer=len(line) + len(framed(2, "M105")))
    s.start(program_items(["G1 X1"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_timeout(1.0)
    assert s.frames_to_send(1.0) == [framed(2, "M105")]
    assert s.on_timeout(2.0) is Step.POKE
    assert s.frames_to_send(2.0) == [] and s.pokes == 1 and s.timeouts == 2  # it would overflow


def test_a_lost_ok_is_found_by_the_pokes_answer():
    """Line 2's ok is lost; the poke's `ok T:` (Marlin answers M105 so, other lines with a bare ok)
    accounts for line 2: Marlin took the poke's number only after line 2."""
    s = stream(window=1, timeout=1.0)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    assert s.on_ok(0.1) is Step.CONFIRMED  # a bare ok: this firmware's usual answer
    s.frames_to_send(0.1)  # line 2; its ok never comes
    assert s.on_timeout(1.1) is Step.POKE
    assert s.frames_to_send(1.1) == [framed(3, "M105")]
    assert s.on_ok(1.2, temperatures=True) is Step.CONFIRMED
    assert s.confirmed == 3 and not s.inflight and s.state.commands_done == 2
    assert s.frames_to_send(1.2) == [framed(4, "G1 X3")]


def test_ok_with_temperatures_is_plain_on_a_firmware_that_always_sends_them():
    s = stream(window=1, timeout=1.0)
    s.start(program_items(["G1 X1", "G1 X2"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_timeout(1.0)
    s.frames_to_send(1.0)  # poke 2 behind line 1
    assert s.on_ok(1.1, temperatures=True) is Step.CONFIRMED  # no bare ok seen yet: it answers line 1
    assert s.confirmed == 1 and len(s.inflight) == 1


def test_a_request_for_a_line_already_being_resent_is_ignored():
    """During a resend a poke goes out on top + 1, ahead of lines still to be resent. The firmware,
    busy, then takes the resent line, refuses the poke by number and asks for the next line, which
    is already on its way behind the poke: that request is ignored (no second copy of it)."""
    s = stream(window=2, timeout=1.0, rx_buffer=1000)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)  # 1, 2
    s.on_ok(0.1)  # 1 ran
    s.frames_to_send(0.1)  # 3
    s.on_error(0.2)
    assert s.on_resend(2, 0.2) is Step.REWOUND  # line 2 damaged
    s.on_ok(0.2)
    assert s.frames_to_send(0.2) == [framed(2, "G1 X2")]  # window: stale 3 + resent 2
    # The firmware is busy; a window passes: the poke goes on top + 1 = 4, line 3 still to be resent.
    assert s.on_timeout(1.2) is Step.POKE
    assert s.frames_to_send(1.2) == [framed(4, "M105")]
    s.on_error(2.0)
    assert s.on_resend(2, 2.0) is Step.IGNORED  # stale 3 refused (an older rewind)
    s.on_ok(2.0)
    s.on_ok(2.1)  # the resent 2 ran
    assert s.confirmed == 2
    assert s.frames_to_send(2.1) == [framed(3, "G1 X3")]  # behind the poke
    s.on_error(2.2)
    assert s.on_resend(3, 2.2) is Step.IGNORED  # the poke refused; 3 is on its way
    s.on_ok(2.2)
    assert s.on_ok(2.3) is Step.CONFIRMED and s.confirmed == 3  # 3 ran, once
    assert s.frames_to_send(2.3) == [framed(4, "M105")]  # the poke's number, in its turn
    assert s.epoch == 1


class _Firmware:
    """Marlin's line rules, written here from docs/domain.md §4: N must be the last line + 1, else `Error:` +
    `Resend:` + `ok`; a line in `damage` arrives damaged once (checksum error, asked for again); a line in
    `missing` is answered by `Error:` alone once (OctoPrint's VirtualPrinter's missing line number).
    M105 is answered `ok T:...`."""

    def __init__(self, damage=(), missing=()):
        self.last, self.executed, self.damage, self.missing = 0, [], set(damage), set(missing)

    def receive(self, frame: bytes) -> list[str]:
        body = frame.decode().split("*")[0]
        number, command = int(body.split()[0][1:]), body.split(None, 1)[1]
        if number != self.last + 1:
            return [f"Error:Line Number is not Last Line Number+1, Last Line: {self.last}",
                    f"Resend: {self.last + 1}", "ok"]
        if number in self.damage:
            self.damage.discard(number)
            return [f"Error:checksum mismatch, Last Line: {self.last}", f"Resend: {self.last + 1}", "ok"]
        if number in self.missing:
            self.missing.discard(number)
            return [f"Error:No Line Number with checksum, Last Line: {self.last}"]
        self.last = number
        self.executed.append(command)
        return ["ok T:20.0 /0.0 B:20.0 /0.0" if command == "M105" else "ok"]


def _reply(s: LineStream, line: str, now: float):
    s.on_line(now)
    if line.startswith("ok"):
        return s.on_ok(now, temperatures="T:" in line)
    if line.startswith("Resend:"):
        return s.on_resend(int(line.split(":")[1]), now)
    return s.on_error(now)


def _stream_against(fw: _Firmware, s: LineStream, rng: random.Random) -> Stop | None:
    """Run `s` against `fw`, the host reading each reply line late now and then (0.3 to 3 s: its
    reader thread not scheduled on a loaded machine); the serial line keeps the lines' order."""
    now, pending, last_at = 0.0, deque(), 0.0
    for _ in range(20000):
        for frame in s.frames_to_send(now):
            for line in fw.receive(frame):
                late = rng.choice([0.3, 0.9, 1.1, 2.1, 3.0]) if rng.random() < 0.3 else 0.0
                last_at = max(last_at, now + 0.001 + late)
                pending.append((last_at, line))
        if s.finished():
            return None
        if pending and pending[0][0] <= now:
            step = _reply(s, pending.popleft()[1], now)
            if isinstance(step, Stop):
                return step
            continue
        now = max(now, min(t for t in (pending[0][0] if pending else None, s.deadline()) if t is not None))
        if not (pending and pending[0][0] <= now):
            step = s.on_timeout(now)
            if isinstance(step, Stop):
                return step
    raise AssertionError("the stream neither finished nor stopped")


@pytest.mark.parametrize("window", [1, 2, 4, 6])
def test_replies_read_late_never_shift_what_is_confirmed(window):
    """Damaged lines, `Error:`-only answers and replies read up to 3 s late (the host's reader
    starved on a loaded machine; the short error wait then runs out before a `Resend:` is read):
    every program line runs once, in order, and the host confirms exactly what the firmware took,
    never a line it refused (which stops the print as a garbled resend, or confirms a line never run)."""
    texts = [f"G1 X{i}" for i in range(1, 61)]
    for seed in range(120):
        rng = random.Random(seed)
        fw = _Firmware(damage={rng.randint(2, 60) for _ in range(5)}, missing={rng.randint(2, 60) for _ in range(3)})
        s = stream(window=window, rx_buffer=1000, timeout=2.0)
        s.start(program_items(texts), JobState(), now=0.0)
        assert _stream_against(fw, s, rng) is None, seed
        assert [c for c in fw.executed if c != "M105"] == texts, seed  # every line once, in order
        assert s.confirmed == fw.last, seed


def test_a_second_error_before_any_resend_ends_the_first_copys_answer():
    """`Error:` alone answers line 1 (missing line number); line 2's `Error:` + `Resend: 1` + `ok` follow
    at once: the request and its ok are line 2's, so line 2's copy (not line 1's) is the one refused,
    and the copies line up with the answers without waiting for a window to run out."""
    s = stream(window=2, rx_buffer=1000, timeout=2.0)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_error(0.1)
    s.on_error(0.1)
    assert [c.number for c in s.inflight] == [2]
    assert s.on_resend(1, 0.1) is Step.REWOUND and s.on_ok(0.1) is Step.IGNORED and not s.inflight
    assert s.frames_to_send(0.1) == [framed(1, "G1 X1"), framed(2, "G1 X2")]


def test_a_resend_read_after_the_error_wait_puts_the_copy_back():
    """`Error:`, then (read 1.5 s later) its `Resend: 2` and `ok`: the short error wait took the copy as
    answered; the request gives it back, so the `ok` answers it and not line 3's copy."""
    s = stream(window=3, rx_buffer=1000, timeout=2.0)
    s.start(program_items(["G1 X1", "G1 X2", "G1 X3"]), JobState(), now=0.0)
    s.frames_to_send(0.0)
    s.on_ok(0.05)
    s.on_error(0.1)
    assert s.on_timeout(1.1) is Step.POKE and [c.number for c in s.inflight] == [3]
    assert s.on_resend(2, 1.6) is Step.REWOUND and s.on_ok(1.6) is Step.IGNORED
    assert [c.number for c in s.inflight] == [3] and s.confirmed == 1 and s.next_number == 2
