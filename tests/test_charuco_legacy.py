"""ChArUco boards printed in OpenCV's legacy pattern (before 4.6; tracking/anchors/kinds/charuco.py `legacy`):
with an even number of rows their markers sit in other squares than today's, so today's board finds the
markers but no corner. Tracked, discovered, diagnosed and calibrated on.

Oracles: the boards as OpenCV's own CharucoBoard.generateImage draws them (setLegacyPattern), and OpenCV's
CharucoDetector on the board made with the matching pattern (its corner count and positions).
"""

import json

import cv2
import numpy as np
import pytest

from arapp.cli import main

DICT = cv2.aruco.DICT_5X5_100


def board_image(path, squares=(6, 8), legacy=True):
    """OpenCV's own drawing of a squares_x x squares_y board (DICT_5X5_100, marker 3/4 of a square)."""
    board = cv2.aruco.CharucoBoard(squares, 0.04, 0.03, cv2.aruco.getPredefinedDictionary(DICT))
    board.setLegacyPattern(legacy)
    img = board.generateImage((100 * squares[0], 100 * squares[1]), marginSize=20)
    cv2.imwrite(str(path), img)
    return board, img


def anchors_file(path, legacy=None, squares=(6, 8)):
    block = {"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": squares[0], "squares_y": squares[1],
             "square_length": 0.04, "marker_length": 0.03}
    if legacy is not None:
        block["legacy"] = legacy
    path.write_text(json.dumps([block]))
    return path


def test_a_legacy_board_is_found_said_and_tracked_with_legacy_true(tmp_path, capsys):
    photo = tmp_path / "legacy.png"
    board, img = board_image(photo)
    # OpenCV itself: today's pattern finds the markers and no corner, the legacy one every corner
    today = cv2.aruco.CharucoBoard((6, 8), 0.04, 0.03, cv2.aruco.getPredefinedDictionary(DICT))
    assert cv2.aruco.CharucoDetector(today).detectBoard(img)[1] is None
    _, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(img)
    assert len(ids) == 5 * 7
    # an anchor without "legacy" tracks nothing and says what to change
    assert main(["replay", str(photo), "--anchors", str(anchors_file(tmp_path / "a.json")), "--out",
                 str(tmp_path / "r1"), "--no-video"]) == 0
    out = capsys.readouterr().out
    assert "frames 1, tracked_fraction 0" in out
    assert "the board is printed in the legacy pattern of OpenCV before 4.6: add \"legacy\": true to it" in out
    # discovery offers the board with its pattern, and that anchor tracks
    (found,) = json.loads((tmp_path / "r1" / "anchors-found.json").read_text())
    assert (found["kind"], found["squares_x"], found["squares_y"], found.get("legacy")) == ("charuco", 6, 8, True)
    assert main(["replay", str(photo), "--anchors", str(anchors_file(tmp_path / "b.json", legacy=True)), "--out",
                 str(tmp_path / "r2"), "--no-video"]) == 0
    assert "frames 1, tracked_fraction 1" in capsys.readouterr().out


def test_today_s_board_with_legacy_true_is_told_to_drop_it(tmp_path, capsys):
    photo = tmp_path / "today.png"
    board_image(photo, legacy=False)
    assert main(["replay", str(photo), "--anchors", str(anchors_file(tmp_path / "a.json", legacy=True)), "--out",
                 str(tmp_path / "r"), "--no-video"]) == 0
    out = capsys.readouterr().out
    assert "tracked_fraction 0" in out and "printed in today's pattern (OpenCV 4.6 on): drop its \"legacy\"" in out


@pytest.mark.parametrize("squares", [(5, 7), (6, 8)])
def test_discovery_says_legacy_only_where_the_patterns_differ(tmp_path, squares):
    from tracking.anchors.discover import Discovery

    # with an odd number of rows both patterns are one board: no "legacy" then
    _, img = board_image(tmp_path / "b.png", squares, legacy=True)
    found = Discovery()
    found.look_all(img)
    board = next(s for s in found.suggestions() if s.kind == "charuco")
    assert (board.block["squares_x"], board.block["squares_y"]) == squares
    assert board.block.get("legacy", False) == (squares[1] % 2 == 0)


def test_calibration_reads_a_legacy_board(tmp_path):
    from tracking.calibration import BoardDetector, BoardSpec
    from tracking.recording.schema import parse_anchors

    board, img = board_image(tmp_path / "b.png")
    spec = parse_anchors(json.loads(anchors_file(tmp_path / "a.json", legacy=True).read_text()))[0]
    found = BoardDetector(BoardSpec.from_anchor(spec)).detect(img)
    cc, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(img)
    assert found is not None and len(found[2]) == len(ids) == 35
    mine = dict(zip(found[2].tolist(), found[1]))
    assert max(np.linalg.norm(mine[int(i)] - c) for i, c in zip(ids.ravel(), cc.reshape(-1, 2))) < 0.2
    spec_today = parse_anchors(json.loads(anchors_file(tmp_path / "c.json").read_text()))[0]
    assert BoardDetector(BoardSpec.from_anchor(spec_today)).detect(img) is None
