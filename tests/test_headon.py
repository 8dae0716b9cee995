"""A small marker seen nearly head-on (issue 25.4, the planar ambiguity): the desk around it decides its tilt.

Recording: tracking.synth.presets.HEADON `test_headon` (a 3 cm marker at ~0.7 m on a textured desk, the camera
held by hand 4-7 degrees off the marker's normal, webcam effects), rendered on first use and cached in
the recordings cache, .cache/recordings/ (tests/scenes.py `held_recording`). It was made from fresh seeds and never looked at while
choosing the desk's parameters (those were chosen on tune_headon and tune_headon_b to tune_headon_e). Ground truth:
the camera pose per frame from the generator, an oracle independent of the tracker. The goals (rotation error
<= 2 degrees after the first second, position error <= 1 % of the distance, jitter <= half of plain OpenCV's)
are asserted as the issue states them.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from scenes import held_recording, run_tracker
from tracking.anchors import AnchorTracker

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.fixture(scope="module")
def headon():
    return held_recording("test_headon")


def _run(frames, session, **kw):
    at = AnchorTracker(session.anchors, session.camera, **kw)
    results = [at.process(img, t) for t, img, _ in frames]
    return [r.world_from_camera for r in results], results


@pytest.fixture(scope="module")
def runs(headon):
    frames, session = headon
    return {"desk": _run(frames, session), "marker": _run(frames, session, desk=False)}


def test_the_desk_settles_the_tilt_of_a_head_on_marker(headon, runs):
    from bench_slam import headon_errors
    from peers import PlainPeer

    frames, session = headon
    peer = PlainPeer(session.anchors, session.camera)
    plain = headon_errors(frames, [peer.pose(img) for _, img, _ in frames])
    desk = headon_errors(frames, runs["desk"][0])
    marker = headon_errors(frames, runs["marker"][0])
    # the recording shows the ambiguity: the marker's own pose flips or tilts by degrees, plain OpenCV's too
    assert marker["rot_late_max"] > 5.0 and plain["rot_late_max"] > 5.0
    assert desk["tracked"] == 1.0
    assert desk["rot_late_max"] <= 2.0          # issue 25.4's goal (measured 0.30)
    assert desk["pos_fraction"] <= 0.01         # issue 25.4's goal (measured 0.45 %)
    assert desk["jitter_m"] <= 0.5 * plain["jitter_m"]


def test_the_full_tracker_keeps_the_desks_tilt(headon):
    """The full tracker (the anchors with the keypoint map, tracking.fusion) on the same recording: the map
    around a lone head-on marker holds the same desk the judge uses, and must not pull the decided pose back
    to the other tilt (with the desk's pose merely starting the joint fit of the corners and the map, the
    output here went 9-12 degrees off for stretches of the last two seconds: tracking.fusion.fits)."""
    from bench_slam import headon_errors
    from tracking.fusion import Tracker

    frames, session = headon
    with Tracker(session.camera, session.anchors) as tr:
        r = run_tracker(tr, frames)
    e = headon_errors(frames, r["poses"])
    assert e["tracked"] == 1.0
    assert e["rot_late_max"] <= 2.0      # measured 0.30
    assert e["pos_fraction"] <= 0.01     # measured 0.45 %


def test_undecided_at_first_decided_later(runs):
    results = runs["desk"][1]
    flags = [r.ambiguous for r in results]
    assert flags[0], "a lone head-on marker's first frame cannot be decided yet"
    assert not any(flags[45:]), "the desk has decided by 1.5 s"
    assert all(r.desk for r in results[45:])
    # the marker-only run never claims the desk decided
    assert not any(r.desk for r in runs["marker"][1])


def test_ambiguous_hint_shows_while_tracked_and_undecided(qtbot):
    from arapp.app.guidance import ambiguous_hint
    from arapp.gui.first_hour.welcome import LostHint

    hint = LostHint(delay_s=1.0)
    qtbot.addWidget(hint)
    hint.update_state("marker", [], now=0.0, ambiguous=True)
    assert not hint.isHidden() and hint.text() == ambiguous_hint()
    assert "Tilt the camera" in hint.text()
    hint.update_state("marker", [], now=0.1, ambiguous=False)
    assert hint.isHidden()
    hint.update_state("lost", [], now=0.2)
    assert hint.isHidden()   # lost: the lost hint still waits its delay
