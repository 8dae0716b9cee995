"""`arapp markers` prints, by default, markers of a dictionary whose codes are far apart (issue 13).

A "fragile glass" icon on packaging decodes as DICT_4X4_50 id 17, the old default. Oracles: OpenCV's
detector on the printed PNG and on that pattern, and the minimum distance computed here from the bits.
"""

import json

import cv2
import numpy as np

from arapp.cli import main


def min_distance(name: str) -> int:
    """Fewest differing bits between two codes of a dictionary, or a code and its own rotations."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    n = d.markerSize
    bits = np.array([d.getBitsFromByteList(d.bytesList[i:i + 1], n).reshape(n * n) for i in range(len(d.bytesList))])
    rots = [np.array([np.rot90(b.reshape(n, n), r).ravel() for b in bits]) for r in range(4)]
    best = min(int((rots[r] != bits).sum(axis=1).min()) for r in (1, 2, 3))
    for r in range(4):
        diff = (rots[r][:, None, :] != bits[None, :, :]).sum(axis=2)
        np.fill_diagonal(diff, 10 ** 6)
        best = min(best, int(diff.min()))
    return best


def test_default_sheet_is_a_far_apart_dictionary(tmp_path, capsys):
    assert main(["markers", "aruco", "--id", "5", "--length", "0.05", "--dpi", "150", "-o", str(tmp_path),
                 "--name", "m"]) == 0
    block = json.loads((tmp_path / "m.anchors.json").read_text())["anchors"][0]
    name = block["dictionary"]
    assert name in ("DICT_ARUCO_MIP_36h12", "DICT_APRILTAG_36h11")
    assert min_distance(name) >= 11 and min_distance("DICT_4X4_50") <= 4
    page = cv2.imread(str(tmp_path / "m.png"), cv2.IMREAD_GRAYSCALE)
    _, ids, _ = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))).detectMarkers(page)
    assert ids is not None and ids.ravel().tolist() == [5]


def test_charuco_sheet_uses_the_same_default(tmp_path, capsys):
    assert main(["markers", "charuco", "--dpi", "150", "-o", str(tmp_path), "--name", "c"]) == 0
    block = json.loads((tmp_path / "c.anchors.json").read_text())["anchors"][0]
    assert block["dictionary"] == "DICT_ARUCO_MIP_36h12"
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_ARUCO_MIP_36h12)
    board = cv2.aruco.CharucoBoard((7, 5), 0.03, 0.022, d)
    _, ci, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(cv2.imread(str(tmp_path / "c.png"), 0))
    assert ci is not None and len(ci) == 24


def test_the_icon_pattern_is_not_a_default_marker():
    """DICT_4X4_50 id 17 drawn as a pattern: a 4x4 detector finds it, the default dictionary's does not."""
    icon = np.full((300, 300), 255, np.uint8)
    icon[50:250, 50:250] = cv2.aruco.generateImageMarker(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 17, 200)
    _, ids, _ = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)).detectMarkers(icon)
    assert ids.ravel().tolist() == [17]
    _, ids, _ = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_ARUCO_MIP_36h12)).detectMarkers(icon)
    assert ids is None


def test_a_recording_keeps_the_dictionary_it_states():
    from tracking.recording.schema import parse_anchors
    a = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 17, "length": 0.05}])[0]
    assert a.dictionary == "DICT_4X4_50" and a.dictionary_id == cv2.aruco.DICT_4X4_50
