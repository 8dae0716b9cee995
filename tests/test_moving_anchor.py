"""A card held before a camera (issue 25 part 2): the anchors move in the room, so the room's keypoints must
not carry the model.

Recordings: tracking.synth.presets.HELD, rendered on first use and cached in .cache/recordings/ (tests/scenes.py
`held_recording`): a board or marker card waved before a still webcam (slow drifts a few cm/s and two fast
swings smeared past reading), a textured wall 0.8 m behind it; and one where a hand-held camera moves too.
Ground truth: the camera in the card's anchor frame, per frame, from the generator (an oracle independent of
the tracker). The peer: plain OpenCV (detectMarkers + solvePnP, benchmarks/peers.py) on the same frames.
The tuning recordings (tune_held_*) are the ones the rules were chosen on; test_held_* are only measured.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import held_recording, run_tracker
from tracking.synth.presets import HELD, HELD_TEST, HELD_TUNING, PRESETS
from tracking.fusion import Tracker

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

MAX_ERR_M = 0.03   # the goal: no frame placed more than 3 cm off


def _plain_errors(frames, session) -> np.ndarray:
    """Plain OpenCV's camera-position error (m) per frame, NaN where it finds nothing."""
    from peers import PlainPeer

    peer = PlainPeer(session.anchors, session.camera)
    out = []
    for _, img, gt in frames:
        p = peer.pose(img)
        out.append(np.nan if p is None else float(np.linalg.norm(p[:3, 3] - gt[:3, 3])))
    return np.array(out)


_RUNS: dict = {}


def _run(name: str) -> dict:
    """arapp's tracker and the plain peer on one held recording (once per test session)."""
    if name not in _RUNS:
        frames, session = held_recording(name)
        with Tracker(session.camera, session.anchors) as tr:
            seen: list[bool] = []

            class Noting:   # the tracker, noting after each frame whether the anchors move
                def process(self, img, t):
                    res = tr.process(img, t)
                    seen.append(tr.anchors_moving)
                    return res

                def catch_up(self):
                    tr.catch_up()

            r = run_tracker(Noting(), frames)
            r["moving"] = tr.anchors_moving
            r["moving_from"] = seen.index(True) if True in seen else None
        r["plain"] = _plain_errors(frames, session)
        gt = np.array([f[2] for f in frames])
        # how far the card moves in the camera's view (the truth's camera position in the card's frame)
        r["travel"] = float(np.linalg.norm(gt[:, :3, 3] - gt[0, :3, 3], axis=1).max())
        _RUNS[name] = r
    return _RUNS[name]


def test_held_presets_are_apart_from_the_rest():
    """Test and tuning held cards share no seed with each other or with any bundled recording."""
    def seeds(names):
        return {HELD[n]["seed"] for n in names} | {HELD[n]["desk"]["seed"] for n in names} | \
               {HELD[n]["held"]["wall"]["seed"] for n in names}

    assert HELD_TEST and HELD_TUNING and not set(HELD) & set(PRESETS)
    assert not seeds(HELD_TEST) & seeds(HELD_TUNING)
    assert not seeds(HELD) & ({p["seed"] for p in PRESETS.values()} | {p["desk"]["seed"] for p in PRESETS.values()})


def test_held_card_ground_truth_is_the_card_frame():
    """The generator's truth is the camera in the moving card's frame: the card's corners drawn from it with
    cv2.projectPoints land on the markers OpenCV detects in the image (median 0.5 px, the worst 2.4 px on a
    drifting, slightly smeared card; measured), while the first frame's truth misses them by more than 10 px
    once the card has moved, and with the
    camera still the truth moves as the card does."""
    import cv2

    from tracking.anchors.model import build_models
    from tracking.poses import invert

    frames, session = held_recording("test_held_board", slice(0, 42))
    model = build_models(session.anchors)[0]
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), params)

    def gap(pose, obj, seen):
        cfw = invert(pose)
        px, _ = cv2.projectPoints(obj, cv2.Rodrigues(cfw[:3, :3])[0], cfw[:3, 3], session.camera.K, session.camera.dist)
        return float(np.linalg.norm(px.reshape(4, 2) - seen.reshape(4, 2), axis=1).max())

    gaps, stale = [], []
    for _, img, gt in frames[::6]:
        corners, ids, _ = det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        for c, i in zip(corners, ids.ravel()):
            obj = model.to_world(model.markers[int(i)])
            gaps.append(gap(gt, obj, c))
            stale.append(gap(frames[0][2], obj, c))   # the first frame's truth: a camera still in the card's frame
    assert len(gaps) >= 40 and float(np.median(gaps)) < 0.75 and float(np.max(gaps)) < 3.0, np.percentile(gaps, [50, 100])
    assert float(np.max(stale)) > 10.0   # by frame 36 the card has moved: the truth must have followed it
    assert _run("test_held_board")["travel"] > 0.1   # the card really moves: 10 cm and more before the camera


@pytest.mark.parametrize("name", [n for n in HELD_TEST if "board" in n or "both" in n])
def test_held_board_card_is_followed(name):
    """A board card held and waved before the camera: arapp notices it moves in the room, places at least as
    many frames as plain OpenCV, none more than 3 cm off (plain places its smeared detections 5-17 cm off)."""
    r = _run(name)
    e, plain = r["errors"], r["plain"]
    assert r["moving"], "the card moved in the room but the tracker did not notice"
    placed, plain_placed = int(np.isfinite(e).sum()), int(np.isfinite(plain).sum())
    assert placed >= plain_placed, (placed, plain_placed)
    assert float(np.nanmax(e)) <= MAX_ERR_M, (float(np.nanmax(e)), int(np.nanargmax(e)))
    # lost when nothing carries it, never placed from the still room: every placed frame is on the card
    assert all(s in ("marker", "slam") for s, p in zip(r["states"], r["poses"]) if p is not None)


@pytest.mark.parametrize("name", [n for n in HELD_TEST if "marker" in n])
def test_held_marker_card_is_no_worse_than_plain(name):
    """A lone 6 cm marker card: its four corners hold the camera position to only 1-3 cm at 0.42 m (the
    plain peer's own median), so the goal here is the peer's: as many frames placed, and the worst frame
    no further off than the peer's worst; the few points on a lone marker do not carry it across a swing.
    The card is seen to move by the still background (pixels, no pose) while it drifts, before its first
    swing, so the still room never carries it; from then on the card the marker is printed on judges its
    tilt (tracking.anchors.card: its points, each placed where many frames' marker poses put it), and no
    frame is placed more than 3 cm off (measured on test_held_marker: moving from frame 30, 105 frames placed
    against plain's 105, worst 3.2 cm against 6.4 cm, 5 frames over 3 cm against plain's 6, all five before
    the card was seen to move, still before the camera; after that the worst 2.1 cm (6.1 cm with the marker's
    own corners and filter alone); the rules were chosen on tune_held_marker, where it places 110 against 110,
    is 3.0 cm off at worst against plain's 7.8 and no frame over 3 cm against plain's 12 (3.9 cm and 3 frames
    with the corners alone), 2.5 cm at worst once the card moves)."""
    r = _run(name)
    e, plain = r["errors"], r["plain"]
    assert r["moving"], "the card moved in the room but the tracker did not notice"
    # noticed before the first swing (the first frame plain OpenCV cannot read): the room's keypoints never
    # carried the card across it
    assert r["moving_from"] < int(np.flatnonzero(~np.isfinite(plain))[0]), r["moving_from"]
    assert int(np.isfinite(e).sum()) >= int(np.isfinite(plain).sum()), (int(np.isfinite(e).sum()),
                                                                         int(np.isfinite(plain).sum()))
    assert float(np.nanmax(e)) <= 0.6 * float(np.nanmax(plain)), (float(np.nanmax(e)), float(np.nanmax(plain)))
    # once the card is seen to move its points judge the tilt: none more than 3 cm off (measured 2.1 cm; the
    # marker's corners and filter alone placed a frame 6.1 cm off there)
    after = e[r["moving_from"] + 1:]
    assert float(np.nanmax(after)) <= 0.025, (float(np.nanmax(after)), int(np.nanargmax(after)) + r["moving_from"] + 1)
    # the 3 cm: not more frames beyond it than plain OpenCV's (measured 5 against 6, all before the
    # card moved: a still head-on marker's tilt)
    over, plain_over = int(np.sum(e > MAX_ERR_M)), int(np.sum(plain > MAX_ERR_M))
    assert over <= plain_over, (over, plain_over)
    # never placed from the still room: every placed frame is the marker's or the flow on it
    assert all(s in ("marker", "slam") for s, p in zip(r["states"], r["poses"]) if p is not None)


def test_held_card_put_down_between_swings():
    """Both move, and the board card is put down for 2.5 s between its swings while the camera goes on moving
    (the map stays off once the card was seen to move: letting it back while the card rested placed the
    second swing's smeared start 7 cm off): the goal of the board cards, as many frames as plain OpenCV and
    none more than 3 cm off. The card drifts only ~0.6 s before its first swing; measured on test_held_rest:
    159 frames placed against plain's 149, the worst 24.7 mm (23.1 in one run of nine; plain 95.3 mm), seen to
    move from frame 49, after the first swing: a check that disagreed at frame 35 was cleared at 38 by a
    two-view test over frames in which the card barely moved, and the room's map carried the swing 7-25 mm off
    (with a check only every tenth frame, before issue 25.2: 155 placed, 138 mm, seen to move from frame 60).
    The rules were chosen on tune_held_rest and tune_held_rest_b to _e (tracking.synth.presets.HELD), all met
    there, _d noticed before its swing only by the checks every frame (52 mm and 3 frames over 3 cm without)."""
    r = _run("test_held_rest")
    e, plain = r["errors"], r["plain"]
    assert r["moving"]
    assert int(np.isfinite(e).sum()) >= int(np.isfinite(plain).sum())
    assert float(np.nanmax(e)) <= MAX_ERR_M, (float(np.nanmax(e)), int(np.nanargmax(e)))


@pytest.mark.parametrize("name", ["board_orbit", "static_camera", "printer_bed"])
def test_still_card_is_not_taken_for_a_moving_one(name):
    """A card lying still on a desk: the room is rigid with the anchors and the map keeps carrying. The
    bundled orbit over a board (the camera moves), a lone marker before a camera on a tripod (the background
    stands still, and so do the marker's corners, within their noise) and a lone marker on a printer bed
    seen from a moving camera (the background moves with the marker)."""
    from scenes import bundled_recording

    frames, session = bundled_recording(name)
    with Tracker(session.camera, session.anchors) as tr:
        for t, img, _ in frames:
            tr.process(img, t)
            tr.catch_up()
        assert not tr.anchors_moving
