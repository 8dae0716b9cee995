"""The live engine's anchor discovery stage (arapp/engine/discovery.py): when it looks, how often, when it stops.

Oracles: a fake clock and a rule written here (look only after LOST_BEFORE_S without a pose, then at most
RATE_HZ frames a second); recordings/board_orbit's session.json for what its frames show.
"""

import json
import time

import cv2
import numpy as np
import pytest

from arapp.engine.discovery import DiscoveryStage
from tracking.recording.schema import parse_anchors
from arapp.engine.sourcespec import DEFAULT_ANCHORS


@pytest.fixture(scope="module")
def frame(repo_root):
    cap = cv2.VideoCapture(str(repo_root / "recordings" / "board_orbit" / "video.avi"))
    ok, f = cap.read()
    cap.release()
    assert ok
    return f


@pytest.fixture(scope="module")
def truth(repo_root):
    return json.loads((repo_root / "recordings" / "board_orbit" / "session.json").read_text())["anchors"][0]


class Clock:
    t = 0.0

    def __call__(self):
        return self.t


def test_looks_only_after_the_lost_window_at_the_rate_and_stops_on_a_pose(frame):
    clock = Clock()
    stage = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), lambda d: None, after_s=1.0, rate_hz=4.0, clock=clock)
    stage._run = lambda: None   # no thread: only what observe hands over is counted here
    times = np.round(np.arange(0.0, 3.0, 0.05), 3)
    for t in times:
        clock.t = float(t)
        stage.observe(frame, None)
    expected, last = 0, None   # the rule: from 1.0 s of lost on, one frame per 0.25 s at most
    for t in times:
        if t >= 1.0 and (last is None or t - last >= 0.25 - 1e-9):
            expected, last = expected + 1, t
    assert stage._inbox.put_count == expected == 8
    clock.t = 3.1
    stage.observe(frame, np.eye(4))   # the anchors give a pose: done for good
    for t in (3.5, 4.0, 5.0):
        clock.t = t
        stage.observe(frame, None)
    assert stage.done.is_set() and stage._inbox.put_count == expected


def test_a_board_frame_is_offered_with_the_why(frame, truth):
    got = []
    stage = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), got.append, default_anchors=True)
    stage.look(frame, 0.0)   # the first passes are DICT_4X4's: the board is found in one frame
    (offer,) = got
    assert offer["summary"] == (f"a {truth['markers_x']}x{truth['markers_y']} {truth['dictionary']} board "
                                f"(ids 0-{truth['markers_x'] * truth['markers_y'] - 1})")
    block = offer["block"]
    assert (block["dictionary"], block["markers_x"], block["markers_y"]) == (
        truth["dictionary"], truth["markers_x"], truth["markers_y"])
    assert offer["size_mm"] == 40.0 and offer["size_field"] == "marker_length"
    assert offer["why"].startswith("nothing tracked: no anchors were given")
    assert "markers of another dictionary seen (DICT_4X4 ids 0-11)" in offer["why"]
    stage.look(frame, 10.0)   # the same finding again: not published twice
    assert len(got) == 1


def test_a_source_with_its_own_anchors_gets_the_why_only(frame):
    got = []
    stage = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), got.append, offer=False)
    stage.look(frame, 0.0)
    (offer,) = got
    assert offer["block"] is None and offer["summary"] is None
    assert "DICT_4X4 ids 0-11" in offer["why"]


def test_a_clip_that_ends_before_the_lost_window_gets_its_last_frame_looked_at(frame, truth):
    # a few photos, or a clip shorter than LOST_BEFORE_S: without a look at the end the view would end on
    # "lost" without a word
    clock, got = Clock(), []
    stage = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), got.append, default_anchors=True, after_s=1.0, clock=clock)
    for t in (0.0, 0.1, 0.2):
        clock.t = t
        stage.observe(frame, None)
    assert stage._thread is None   # inside the lost window: nothing looked at
    stage.at_end()
    stage.at_end()   # (said twice: looked at once)
    deadline = time.monotonic() + 20.0
    while not got and time.monotonic() < deadline:
        time.sleep(0.02)
    stage.finish()
    (offer,) = got
    assert offer["block"]["dictionary"] == truth["dictionary"]
    assert (offer["block"]["markers_x"], offer["block"]["markers_y"]) == (truth["markers_x"], truth["markers_y"])
    assert stage._inbox.put_count == 1


def test_the_end_adds_no_look_after_a_pose_or_after_looking(frame):
    clock = Clock()
    tracked = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), lambda d: None, clock=clock)
    tracked.observe(frame, None)
    tracked.observe(frame, np.eye(4))
    tracked.at_end()
    assert tracked._inbox.put_count == 0
    looked = DiscoveryStage(parse_anchors(DEFAULT_ANCHORS), lambda d: None, after_s=1.0, clock=clock)
    looked._run = lambda: None
    for t in (0.0, 1.0):
        clock.t = t
        looked.observe(frame, None)
    assert looked._inbox.put_count == 1
    looked.at_end()
    assert looked._inbox.put_count == 1
