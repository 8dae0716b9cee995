"""Printable sheets: true scale, detectable by OpenCV, with the matching anchors block."""

import json
import re

import cv2
import numpy as np
import pytest

from tracking.printables import sheet
from tracking.recording.schema import parse_anchor, parse_anchors

DPI = 150.0
PPM = DPI / 0.0254  # pixels per metre


def test_aruco_sheet_true_scale():
    spec = parse_anchor({"kind": "aruco", "dictionary": "DICT_6X6_250", "id": 17, "length": 0.05})
    img, block = sheet(spec, DPI, "A4")
    assert img.shape == (round(297 / 25.4 * DPI), round(210 / 25.4 * DPI))
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250))
    corners, ids, _ = det.detectMarkers(img)
    assert ids is not None and ids.ravel().tolist() == [17]
    c = corners[0].reshape(4, 2)
    side = np.mean(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1))
    assert side == pytest.approx(0.05 * PPM, abs=1.5)
    assert parse_anchors(block["anchors"])[0].id == 17


def test_board_and_charuco_sheets():
    board = parse_anchor({"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                          "marker_length": 0.04, "separation": 0.01, "first_id": 5})
    img, block = sheet(board, DPI, "A4")
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    corners, ids, _ = det.detectMarkers(img)
    got = dict(zip(ids.ravel().tolist(), [c.reshape(4, 2) for c in corners]))
    assert sorted(got) == list(range(5, 17))
    # marker 5 is top-left and marker 6 right of it, one pitch (length + separation) away, as getObjPoints says
    assert got[6][0, 0] - got[5][0, 0] == pytest.approx(0.05 * PPM, abs=1.5)
    assert got[9][0, 1] - got[5][0, 1] == pytest.approx(0.05 * PPM, abs=1.5)
    assert block["anchors"][0]["first_id"] == 5
    ch = parse_anchor({"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 7, "squares_y": 5,
                       "square_length": 0.03, "marker_length": 0.022})
    img, _ = sheet(ch, DPI, "A4")
    cb = cv2.aruco.CharucoBoard((7, 5), 0.03, 0.022, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100))
    cc, ci, _, _ = cv2.aruco.CharucoDetector(cb).detectBoard(img)
    assert ci is not None and len(ci) == 24
    cc, ci = cc.reshape(-1, 2), ci.ravel()
    i0, i1 = np.flatnonzero(ci == 0)[0], np.flatnonzero(ci == 1)[0]
    assert np.linalg.norm(cc[i1] - cc[i0]) == pytest.approx(0.03 * PPM, abs=1.0)


def test_qr_sheet_decodes():
    spec = parse_anchor({"kind": "qr", "text": "arapp anchor 2", "length": 0.06})
    img, block = sheet(spec, DPI, "Letter")
    text, pts, _ = cv2.QRCodeDetector().detectAndDecode(img)
    assert text == "arapp anchor 2"
    side = np.linalg.norm(pts.reshape(4, 2)[1] - pts.reshape(4, 2)[0])
    assert side == pytest.approx(0.06 * PPM, abs=2.0)
    assert block == {"anchors": [{"kind": "qr", "text": "arapp anchor 2", "length": 0.06}]}


def test_markers_command_writes_png_pdf_json(tmp_path, capsys):
    from arapp.cli import main

    assert main(["markers", "aruco", "--id", "3", "--length", "0.05", "--dpi", "100", "-o", str(tmp_path),
                 "--name", "m3"]) == 0
    pdf = (tmp_path / "m3.pdf").read_bytes()
    box = [float(v) for v in re.search(rb"/MediaBox \[ ?([\d. ]+)\]", pdf).group(1).split()]
    assert box[2] == pytest.approx(210 / 25.4 * 72, abs=1.0) and box[3] == pytest.approx(297 / 25.4 * 72, abs=1.0)
    from PIL import Image
    with Image.open(tmp_path / "m3.png") as im:
        assert im.info["dpi"][0] == pytest.approx(100, abs=0.5)
    blk = json.loads((tmp_path / "m3.anchors.json").read_text())
    assert blk["anchors"][0] == {"kind": "aruco", "dictionary": "DICT_ARUCO_MIP_36h12", "id": 3, "length": 0.05}
    assert '"anchors"' in capsys.readouterr().out
    assert main(["markers", "board", "--marker-length", "0.2", "-o", str(tmp_path)]) == 2
    assert "does not fit" in capsys.readouterr().err
