"""Anchor measurements that must not move the model: a hand reaching into a marker's white margin, and a
look-alike of an anchor (a packaging icon decoding as its id) far from where the map puts it.

Frames are rendered by the synthesiser with exact ground truth; the hand is painted here (skin colour,
rounded fingertips) at a geometry this file chooses, so the oracle is the true pose and the painted
cover, not the code under test."""

import cv2
import numpy as np
import pytest

from tracking.anchors import AnchorTracker
from tracking.anchors.model import build_models
from tracking.anchors.occlusion import covered_fraction, is_covered
from tracking.recording.schema import parse_anchors
from scene_book import book_frames, desk_point, scene_json
from scenes import SKIN_BGR, marker_side
from tracking.fusion import Tracker

def paint_fingers(img, quad, side, reach_cells, shade=0.85, shift=0.0):
    """Three rounded fingers coming from outside side `side` (corners side, side+1) of the marker `quad`
    (4,2 pixels), fingertips `reach_cells` cells (of 6 across the marker) outside the black border
    (negative: over it), the hand moved `shift` of the side's length along it (toward corner side+1).
    Anti-aliased at 4x; returns a new BGR image."""
    mid, out, along, length, cell = marker_side(quad, side)
    tip = mid + out * cell * reach_cells + along * shift * length
    s = 4
    mask = np.zeros((img.shape[0] * s, img.shape[1] * s), np.uint8)

    def P(p):
        return int(round((p[0] + 0.5) * s - 0.5)), int(round((p[1] + 0.5) * s - 0.5))

    for off, back in ((-0.33, 0.06), (0.0, 0.0), (0.3, 0.05)):
        base = tip + along * off * length + out * back * length
        cv2.line(mask, P(base), P(base + out * 600), 255, int(0.22 * length * s), cv2.LINE_AA)
        cv2.circle(mask, P(base), int(0.11 * length * s), 255, -1, cv2.LINE_AA)
    mask = cv2.resize(mask, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_AREA)
    al = (mask.astype(np.float64) / 255.0)[..., None]
    return np.clip(img * (1 - al) + al * SKIN_BGR * shade, 0, 255).astype(np.uint8)


def marker_quad(scene, pose):
    m = build_models(scene.anchors)[0]
    return scene.camera.project_world(m.to_world(m.markers[3]), pose)


@pytest.fixture(scope="module")
def hand_sequence():
    """2.5 s at 0.45 m from a lone 6 cm marker; from 1.5 s three fingers slide in from above, from a
    cell outside the margin to half a cell over the black border, then stay."""
    frames, scene = book_frames("finger_flick")   # tests/scene_book.py
    out, reach = [], []
    for i, (t, img, gt) in enumerate(frames):
        r = None
        if i >= 45:
            r = max(1.2 - 1.6 * (i - 45) / 20, -0.4)
            img = paint_fingers(img, marker_quad(scene, gt), 0, r)
        out.append((t, img, gt))
        reach.append(r)
    return out, scene, reach, frames


def test_a_finger_flicking_over_a_corner_does_not_make_the_model_jump(hand_sequence):
    """Single frames (and runs of two and three) in which fingers reach a third of a cell over one side's
    border, on the clean frames: the issue's "pose jumps for a frame"."""
    _, scene, _, clean = hand_sequence
    flicks = {50: 1, 51: 1, 60: 2, 70: 3, 71: 3, 72: 3}
    with Tracker(scene.camera, scene.anchors, threaded=False) as tr:
        errs = []
        for i, (t, img, gt) in enumerate(clean):
            if i in flicks:
                img = paint_fingers(img, marker_quad(scene, gt), flicks[i], -0.3)
            res = tr.process(img, t)
            errs.append(np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
    # measured: before the margin check the run of three moved the camera 1.4, 3.7, 5.3 cm; now 2.2 mm at most
    assert max(errs) < 0.005, np.round(errs, 4)


def test_covered_side_is_the_one_the_fingers_reach(hand_sequence):
    frames, scene, reach, _ = hand_sequence
    gray = lambda img: cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)  # noqa: E731
    for (t, img, gt), r in zip(frames, reach):
        frac = covered_fraction(gray(img), marker_quad(scene, gt), 6)
        if r is None:
            assert not is_covered(frac), (t, frac)
        elif r <= 0.6:   # fingertips within 0.6 cell of the border: side 0 covered, the others clear
            assert frac[0] >= 0.3 and frac[1:].max() < 0.2, (t, r, frac)


def test_fingers_in_the_margin_do_not_move_the_model(hand_sequence):
    frames, scene, reach, _ = hand_sequence
    with Tracker(scene.camera, scene.anchors, threaded=False) as tr:
        errs = []
        for t, img, gt in frames:
            res = tr.process(img, t)
            assert res.world_from_camera is not None, t
            errs.append(np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
    errs = np.array(errs)
    clear = errs[:45]
    assert clear.max() < 0.004   # the lone marker alone, before the hand: the scale of the bound below
    # measured: before this check the fingers dragged the pose 2.5-3 cm; now it stays within 5 mm
    assert errs[45:].max() < 0.005, errs[45:].round(4)


def test_anchor_tracker_marks_covered_markers_and_weighs_them_little(hand_sequence):
    frames, scene, reach, _ = hand_sequence
    at = AnchorTracker(scene.anchors, scene.camera)
    flagged, errs = [], []
    for (t, img, gt), r in zip(frames, reach):
        res = at.process(img, t)
        if res.world_from_camera is not None:
            errs.append(np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
            flagged.append(res.covered)
        if r is not None and 0 <= r <= 0.6:
            # flagged: down-weighted as covered, or its corners found again on the uncovered edges
            assert res.world_from_camera is None or res.covered or res.refitted, t
    assert not any(flagged[:45])
    # without a map the filter leans on its prediction: the fingers' pull is a fraction of the raw one
    assert max(errs) < 0.012


def _corner_covered_run(clean, scene, refit: bool):
    """AnchorTracker errors (m) over the clean frames 0-74 with, from frame 30 on, a hand over corner 0:
    one fingertip a third of a cell onto the black border right at the corner, the next one at the border
    a quarter of the side along."""
    at = AnchorTracker(scene.anchors, scene.camera)
    at.cover_refit = refit
    errs = []
    for i, (t, img, gt) in enumerate(clean[:75]):
        if i >= 30:
            img = paint_fingers(img, marker_quad(scene, gt), 0, -0.3, shift=-0.55)
        res = at.process(img, t)
        errs.append(np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]) if res.world_from_camera is not None
                    else np.nan)
    return np.array(errs), at


def test_a_finger_over_a_corner_is_refitted_from_the_uncovered_edges(hand_sequence):
    """A fingertip over a marker's corner drags the detector's contour (and that corner) by pixels for as
    long as it stays; down-weighting alone lets a second of such frames pull the pose away. The marker's
    four sides, refitted where the prediction puts them, keep it where it is."""
    _, scene, _, clean = hand_sequence
    errs, at = _corner_covered_run(clean, scene, refit=True)
    assert at.refitted >= 40                       # measured: all 45 covered frames were refitted
    assert np.isfinite(errs[30:]).all()
    # measured: 4.8 mm at most with the refit; without it (below) the pose walked off to 15.7 mm
    assert np.nanmax(errs[30:]) < 0.0065, errs[30:].round(4)
    old, _ = _corner_covered_run(clean, scene, refit=False)
    assert np.nanmax(old[30:]) > 2 * np.nanmax(errs[30:])


# ----------------------------------------------------------------------------------------------------
DECLARED_AT = [0.24, 0.06]    # where the session says anchor id 17 is


@pytest.fixture(scope="module")
def lookalike_sequence():
    """The camera starts on marker id 3 (the world), pans until a look-alike of anchor id 17 comes into
    view beside it (from the first frame: nothing holds the pose yet), then on until only the look-alike is
    in view; the session declares id 17 8.9 cm
    from where the look-alike lies."""
    sj = scene_json("lookalike")   # tests/scene_book.py (the look-alike lies at its LOOKALIKE_AT)
    frames, scene = book_frames("lookalike")
    declared = parse_anchors(sj["anchors"][:1] + [dict(sj["anchors"][1], world_from_anchor=desk_point(DECLARED_AT))])
    return frames, scene, declared


def _seen(frames, marker_id):
    """Frames in which OpenCV's own detector finds `marker_id` (DICT_4X4_50)."""
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    n = 0
    for _, img, _ in frames:
        _, ids, _ = det.detectMarkers(img)
        n += ids is not None and marker_id in ids.ravel()
    return n


def test_a_lookalike_anchor_does_not_teleport_the_model(lookalike_sequence):
    frames, scene, declared = lookalike_sequence
    errs = []
    with Tracker(scene.camera, declared, threaded=False) as tr:
        for t, img, gt in frames:
            res = tr.process(img, t)
            errs.append(np.inf if res.world_from_camera is None else
                        np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
        trusted = set(getattr(tr.anchor_tracker, "trusted", ()))
    errs = np.array(errs)
    assert _seen(frames, 17) > 10 and _seen(frames[-10:], 3) == 0   # in view, at the end alone
    # before: the model jumped by centimetres once the look-alike was measured; now the world marker and
    # the map keep it within what they give on their own
    assert np.isfinite(errs).mean() > 0.95
    assert np.nanmax(errs[np.isfinite(errs)]) < 0.02, errs.round(3)
    assert 1 not in trusted


def test_anchor_tracker_rejects_a_new_anchor_far_from_its_prediction(lookalike_sequence):
    """The anchor tracker alone, while the world marker is in view (its filter holds the pose). Once
    nothing has held the pose for longer than the filter's gap, a lone new anchor is all there is and is
    taken (the combined tracker's map covers that case, above)."""
    frames, scene, declared = lookalike_sequence
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    with_world = [i for i, (_, img, _) in enumerate(frames)
                  if (ids := det.detectMarkers(img)[1]) is not None and 3 in ids.ravel()]
    at = AnchorTracker(declared, scene.camera)
    for t, img, gt in frames[:with_world[-1] + 1]:
        res = at.process(img, t)
        assert res.world_from_camera is not None, t
        assert np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]) < 0.01, t
    assert 1 not in getattr(at, "trusted", {1})
