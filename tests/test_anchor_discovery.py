"""Anchor discovery and the why of a run that tracks nothing (issues 26.1 and 25's "says why").

Oracles: the anchors a recording's session.json states (board_orbit: a 4x3 DICT_4X4_50 GridBoard,
40 mm markers 10 mm apart), SOURCES.md of the caliscope clip (an inverted 4x5 ChArUco board, 54 mm
squares, 40.5 mm markers), boards drawn by the renderer from a stated layout, and a photo with no
marker at all (OpenCV's circuit board).
"""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.anchors.diagnose import suggestion_line, why_line, why_untracked
from tracking.anchors.discover import Discovery, board_from_markers
from tracking.anchors.render import look_at, render_view
from scenes import plain_clip
from tracking.camera import Camera
from tracking.recording.schema import load_session, parse_anchors

REPO = Path(__file__).resolve().parents[1]
REALVIDEO = REPO / "tests" / "data" / "realvideo"
CAM = Camera(np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)
DEFAULT = [{"kind": "aruco", "dictionary": "DICT_ARUCO_MIP_36h12", "id": 0, "length": 0.06}]


def frames_of(path, count):
    """`count` gray frames spread over a video file."""
    cap = cv2.VideoCapture(str(path))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    out = []
    for k in range(count):
        cap.set(cv2.CAP_PROP_POS_FRAMES, int((k + 0.5) * n / count))
        ok, f = cap.read()
        if ok:
            out.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY))
    cap.release()
    return out


@pytest.fixture(scope="module")
def orbit_clip(tmp_path_factory):
    """A plain video (no session.json) cut from recordings/board_orbit, as a user would have one."""
    return plain_clip(REPO / "recordings" / "board_orbit" / "video.avi",
                      tmp_path_factory.mktemp("clip") / "clip.mp4", 45)


@pytest.fixture(scope="module")
def orbit_found(orbit_clip):
    return looked(frames_of(orbit_clip, 2))


def looked(frames):
    d = Discovery()
    for g in frames:
        d.look_all(g)
    return d


def test_a_plain_clip_of_the_bundled_board_is_recognised(orbit_found):
    truth = load_session(REPO / "recordings" / "board_orbit").anchors[0].to_dict()
    best = orbit_found.suggestions()[0]
    assert best.summary == "a 4x3 DICT_4X4_50 board (ids 0-11)"
    block = best.with_size(truth["marker_length"])   # the user types the measured marker size
    for key in ("kind", "dictionary", "markers_x", "markers_y", "first_id", "marker_length"):
        assert block[key] == truth[key], key
    # the gap is measured from the picture: measured 10.5 mm (true 10 mm)
    assert abs(block["separation"] - truth["separation"]) <= 0.001
    assert "polarity" not in block
    # the block is a valid anchor, and tracks the clip
    (spec,) = parse_anchors([block])
    assert spec.kind == "aruco_board"


def test_the_inverted_caliscope_board_is_recognised_as_an_inverted_charuco():
    found = looked(frames_of(REALVIDEO / "caliscope_charuco_cam0.mp4", 2))
    best = found.suggestions()[0]
    truth = json.loads((REALVIDEO / "caliscope_anchors.json").read_text())[0]
    assert best.kind == "charuco" and best.block["polarity"] == "inverted"
    assert (best.block["squares_x"], best.block["squares_y"]) == (truth["squares_x"], truth["squares_y"])
    # DICT_4X4_1000's first 50 markers are DICT_4X4_50's: the smallest that holds ids 0-9
    assert best.dictionary == "DICT_4X4_50"
    ratio = best.block["square_length"] / best.block["marker_length"]
    assert ratio == pytest.approx(truth["square_length"] / truth["marker_length"], rel=0.03)   # measured 1.1 %


@pytest.mark.parametrize("block,summary", [
    ({"kind": "aruco_board", "dictionary": "DICT_5X5_100", "markers_x": 3, "markers_y": 5, "marker_length": 0.03,
      "separation": 0.006}, "a 3x5 DICT_5X5_50 board (ids 0-14)"),
    ({"kind": "charuco", "dictionary": "DICT_APRILTAG_36h11", "squares_x": 5, "squares_y": 4, "square_length": 0.035,
      "marker_length": 0.026}, "a 5x4 ChArUco DICT_APRILTAG_36h11 board (ids 0-9)"),
], ids=["grid", "charuco"])
def test_drawn_boards_are_recognised_with_their_layout(block, summary):
    wfc = look_at([0.05, 0.08, -0.33], [0.045, 0.07, 0.0], up=(0, -1, 0))
    img = render_view(parse_anchors([block]), CAM, wfc)
    best = looked([img]).suggestions()[0]
    assert best.summary == summary
    got = best.with_size(block["marker_length"])
    other = "separation" if block["kind"] == "aruco_board" else "square_length"
    assert abs(got[other] - block[other]) <= 0.001, (got[other], block[other])


def test_a_picture_without_markers_suggests_nothing_and_says_so():
    photo = cv2.imread(str(REPO / "tests" / "data" / "realphotos" / "opencv" / "board.jpg"), cv2.IMREAD_GRAYSCALE)
    blank = np.full((480, 640), 128, np.uint8)
    found = looked([photo, blank])
    # (one square of the circuit board reads as an inverted DICT_4X4_1000 id 37, once: no finding)
    assert found.suggestions() == [] and found.markers_seen == {}
    line = why_line(parse_anchors(DEFAULT), found)
    assert line == "nothing tracked: no marker or QR code of any dictionary seen (2 frames looked at, both polarities)"


def test_feed_looks_at_a_few_frames_a_second_and_round_robins_the_passes(orbit_clip):
    frames = frames_of(orbit_clip, 2)
    d = Discovery(rate_hz=4.0, passes_per_frame=2)
    looked_at = sum(d.feed(frames[k % 2], k / 30.0) for k in range(60))   # 2 s of 30 fps video
    assert looked_at == 8   # the rule: every 1/4 s of frame time
    assert d.rounds == pytest.approx(16 / 21)
    # DICT_4X4 normal is the round's first pass: the board is found within the first frame looked at
    assert d.suggestions()[0].summary == "a 4x3 DICT_4X4_50 board (ids 0-11)"


def test_why_names_the_default_anchors_and_the_dictionary_seen(orbit_found):
    found = orbit_found
    reasons = why_untracked(parse_anchors(DEFAULT), found, default_anchors=True)
    assert reasons[0] == ("no anchors were given, so the default (ArUco id 0, DICT_ARUCO_MIP_36h12, 60 mm) was "
                          "looked for")
    assert reasons[1] == ("markers of another dictionary seen (DICT_4X4 ids 0-11), not the anchors' "
                          "DICT_ARUCO_MIP_36h12")
    line = suggestion_line(found.suggestions()[0])
    assert line.startswith("found a 4x3 DICT_4X4_50 board (ids 0-11); assuming 40 mm markers")
    blocks = json.loads(line.split("holding: ", 1)[1])
    assert parse_anchors(blocks)[0].markers_x == 4


def test_why_names_other_ids_and_a_pinned_polarity(orbit_clip, orbit_found):
    found = orbit_found
    board = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
             "marker_length": 0.04, "separation": 0.01}
    (reason,) = why_untracked(parse_anchors([dict(board, first_id=20)]), found)
    assert reason == "DICT_4X4 markers seen with ids 0-11, not anchors[0]'s ids 20-31: check anchors[0].id / first_id"
    inverted = looked([255 - g for g in frames_of(orbit_clip, 1)])
    (reason,) = why_untracked(parse_anchors([dict(board, polarity="normal")]), inverted)
    assert reason.startswith("DICT_4X4_50 markers seen printed inverted (white on black), but anchors[0].polarity "
                             "is 'normal'")


def test_why_says_what_qr_text_was_read():
    text = "BEGIN:VCARD\r\nN:Owen;Sean\r\nEND:VCARD\r\n"
    img = render_view(parse_anchors([{"kind": "qr", "text": text, "length": 0.08}]), CAM,
                      look_at([0.0, 0.0, 0.3], [0, 0, 0], up=(0, 1, 0)))
    found = looked([img])
    (reason,) = why_untracked(parse_anchors([{"kind": "qr", "text": "arapp anchor 1", "length": 0.05}]), found)
    assert reason == f"QR codes with other text seen ({text!r}), not anchors[0].text 'arapp anchor 1'"
    # the same text typed with LF ends is not "other text"
    assert why_untracked(parse_anchors([{"kind": "qr", "text": "BEGIN:VCARD\nN:Owen;Sean\nEND:VCARD",
                                         "length": 0.05}]), found) == []
    assert found.suggestions()[0].block == {"kind": "qr", "text": text, "length": 0.05}


def test_markers_that_fit_no_grid_are_no_board():
    rng = np.random.default_rng(3)
    quads = np.array([[[0, 0], [20, 0], [20, 20], [0, 20]]], float) + rng.uniform(0, 400, (6, 1, 2))
    assert board_from_markers("DICT_4X4_1000", "normal", np.arange(6), quads) is None


def test_a_lone_marker_seen_once_is_looked_for_again_in_the_next_frame():
    # a lone marker counts once seen in two frames (a look-alike square more likely otherwise); its pass comes
    # first in the next frame looked at, so a three-second clip of one marker gets its offer (a whole round of
    # the 21 passes takes five seconds at 4 frames a second, two passes each). Oracle: the marker drawn here.
    d6 = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250)
    img = np.full((480, 640), 200, np.uint8)
    img[140:340, 220:420] = 255
    img[165:315, 245:395] = cv2.aruco.generateImageMarker(d6, 23, 150)
    d = Discovery(rate_hz=4.0, passes_per_frame=2)
    firsts = []
    for k in range(12):   # 3 s at 4 looks a second
        d.feed(img, k * 0.25)
        seen = d.markers_seen
        if seen and not firsts:
            firsts.append(k)
    # 24 passes, one of them the look again: 23 count toward the rounds
    assert d.frames_looked == 12 and d.rounds == pytest.approx(23 / 21)
    assert firsts and d.suggestions()[0].summary == "a DICT_6X6_50 marker, id 23"
    assert d._frames[("DICT_6X6_1000", "normal")] >= 2
