"""Anchor kinds as plug-ins (tracking/anchors/kinds): the table, the built-in kinds' words and files,
and a toy kind defined here, registered with one line, read from a session block and tracked.

Oracles: a synthetic image drawn with OpenCV's own marker generator (cv2.aruco.generateImageMarker)
warped with cv2.warpPerspective onto corners from cv2.projectPoints at a known pose; OpenCV's
ArucoDetector on the printed sheet; strings and file names written out here.
"""

from __future__ import annotations

import argparse
import json

import cv2
import numpy as np
import pytest

from arapp.commands import markers as markers_cmd
from arapp.app.guidance import distance_range_m, looking_for
from arapp.geometry.placement import world_from_placement
from tracking.anchors import AnchorTracker
from tracking.anchors.kinds import DEFAULT_DICTIONARY, KINDS, AnchorKind, register, square_corners
from tracking.anchors.model import build_models
from tracking.camera import Camera
from tracking.errors import SessionError
from tracking.poses import from_rvec_tvec, invert
from tracking.printables import sheet
from tracking.recording.schema import parse_anchors

DICT = "DICT_4X4_50"


# -- a toy kind: the whole of what a new kind needs ----------------------------------------------------
class DominoKind(AnchorKind):
    """Two ArUco markers side by side, ids `id` (left) and `id`+1 (right), side `length`, `gap` apart
    (a field no built-in kind has). Frame: centred between them, x right, y up, z out of the paper."""

    name = "domino"
    required = {"dictionary": str, "id": int, "length": float, "gap": float}
    positive = ("length",)
    non_negative = ("gap",)

    def marker_ids(self, spec):
        return [spec.id, spec.id + 1]

    def geometry(self, spec):
        dx = (spec.length + spec.gap) / 2
        sq = square_corners(spec.length)
        return {spec.id: sq - [dx, 0, 0], spec.id + 1: sq + [dx, 0, 0]}, None, None

    def extent(self, spec):
        return spec.length, 2 * spec.length + spec.gap

    def describe(self, spec):
        return f"domino ids {spec.id}-{spec.id + 1}, {spec.dictionary}, {spec.length * 1000:g} mm"


@pytest.fixture
def domino():
    kind = register(DominoKind())  # the one registration line
    yield kind
    KINDS.pop("domino")


BLOCK = {"kind": "domino", "dictionary": DICT, "id": 10, "length": 0.05, "gap": 0.02}


def _camera() -> Camera:
    return Camera(np.array([[900.0, 0, 639.5], [0, 900.0, 359.5], [0, 0, 1]]), np.zeros(5), 1280, 720)


def _draw_markers(camera: Camera, rvec, tvec, corners_by_id: dict[int, np.ndarray], paper: np.ndarray) -> np.ndarray:
    """Gray image: white paper (3-D corners `paper`) and OpenCV's own markers warped onto projected corners."""
    img = np.full((camera.height, camera.width), 110, np.uint8)
    # drawn 4x larger (paper, then markers warped from 480 px images) and averaged down: anti-aliased edges
    s = 4
    big = cv2.resize(img, (camera.width * s, camera.height * s), interpolation=cv2.INTER_NEAREST)
    K = camera.K.copy()
    K[:2] *= s
    K[0, 2], K[1, 2] = (camera.K[0, 2] + 0.5) * s - 0.5, (camera.K[1, 2] + 0.5) * s - 0.5
    pq, _ = cv2.projectPoints(paper, rvec, tvec, K, None)
    cv2.fillConvexPoly(big, np.round(pq.reshape(-1, 2) * 16).astype(np.int32), 255, cv2.LINE_AA, shift=4)
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, DICT))
    for mid, c3 in corners_by_id.items():
        size = 480
        tile = cv2.aruco.generateImageMarker(d, int(mid), size, borderBits=1)
        src = np.array([[-0.5, -0.5], [size - 0.5, -0.5], [size - 0.5, size - 0.5], [-0.5, size - 0.5]], np.float32)
        dst, _ = cv2.projectPoints(c3, rvec, tvec, K, None)
        H = cv2.getPerspectiveTransform(src, dst.reshape(4, 2).astype(np.float32))
        warped = cv2.warpPerspective(tile, H, big.shape[::-1], flags=cv2.INTER_LINEAR)
        mask = cv2.warpPerspective(np.full_like(tile, 255), H, big.shape[::-1], flags=cv2.INTER_LINEAR)
        big = np.where(mask > 127, warped, big).astype(np.uint8)
    img = cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), 0.6)


# -- the table and the built-in kinds ---------------------------------------------------------------
def test_built_in_kinds_are_registered_once_each():
    assert list(KINDS)[:4] == ["aruco", "aruco_board", "charuco", "qr"]
    assert {KINDS[k].detector for k in ("aruco", "aruco_board", "charuco", "qr")} == {"aruco", "charuco", "qr"}


def test_built_in_kinds_keep_their_words_and_blocks():
    specs = parse_anchors([
        {"kind": "aruco", "dictionary": DICT, "id": 40, "length": 0.05},
        {"kind": "aruco_board", "dictionary": DICT, "markers_x": 4, "markers_y": 3, "marker_length": 0.04,
         "separation": 0.01, "first_id": 20, "world_from_anchor": np.eye(4).tolist()},
        {"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 5, "squares_y": 4, "square_length": 0.03,
         "marker_length": 0.022},
        {"kind": "qr", "text": "arapp anchor 1", "length": 0.06},
    ])
    assert looking_for(specs) == (
        "Looking for ArUco id 40, DICT_4X4_50, 50 mm or ArUco board 4 x 3, DICT_4X4_50, ids 20-31, 40 mm markers"
        " or ChArUco board 5 x 4, DICT_5X5_100, 30 mm squares or QR code \"arapp anchor 1\", 60 mm")
    # session.json blocks are written back as docs/recording-format.md shows them (first_id on boards only)
    assert specs[0].to_dict() == {"kind": "aruco", "dictionary": DICT, "id": 40, "length": 0.05}
    assert specs[1].to_dict() == {"kind": "aruco_board", "dictionary": DICT, "markers_x": 4, "markers_y": 3,
                                  "marker_length": 0.04, "separation": 0.01, "first_id": 20}
    assert specs[2].marker_ids() == list(range(10))
    assert specs[3].marker_ids() == []
    # the placement frame of a GridBoard: its centre, z out of the paper (the board frame's z points in)
    T = world_from_placement(specs[1])
    np.testing.assert_allclose(T[:3, 3], [(4 * 0.04 + 3 * 0.01) / 2, (3 * 0.04 + 2 * 0.01) / 2, 0])
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1])


def test_a_taken_name_is_refused():
    class Impostor(DominoKind):
        name = "aruco"

    with pytest.raises(ValueError, match="'aruco' is already registered by ArucoKind"):
        register(Impostor())
    assert type(KINDS["aruco"]).__name__ == "ArucoKind"


def test_unknown_kind_names_the_registered_ones():
    with pytest.raises(SessionError, match=r"anchors\[0\]\.kind: must be one of aruco, aruco_board, charuco, qr"):
        parse_anchors([{"kind": "domino", "dictionary": DICT, "id": 1, "length": 0.05, "gap": 0.01}])


def test_markers_command_defaults_to_the_one_default_dictionary(tmp_path):
    assert DEFAULT_DICTIONARY == "DICT_ARUCO_MIP_36h12"
    parser = argparse.ArgumentParser()
    markers_cmd.add_arguments(parser)
    args = parser.parse_args(["board", "-o", str(tmp_path)])
    assert args.dictionary == DEFAULT_DICTIONARY
    assert markers_cmd.run(args) == 0
    assert (tmp_path / "board_DICT_ARUCO_MIP_36h12_4x3_40mm.png").is_file()
    with pytest.raises(SystemExit):
        parser.parse_args(["domino"])  # not registered here


# -- a new kind: one class and one registration line -------------------------------------------------
def test_toy_kind_fields_are_read_checked_and_written_back(domino):
    spec = parse_anchors([BLOCK])[0]
    assert spec.kind == "domino" and spec.gap == 0.02 and spec.marker_ids() == [10, 11]
    assert spec.to_dict() == BLOCK
    with pytest.raises(SessionError, match=r"anchors\[0\]\.gap: must not be negative"):
        parse_anchors([{**BLOCK, "gap": -0.01}])
    with pytest.raises(SessionError, match=r"anchors\[0\]\.gap: missing \(a domino anchor needs dictionary, id, "
                                           r"length, gap\)"):
        parse_anchors([{k: v for k, v in BLOCK.items() if k != "gap"}])
    with pytest.raises(SessionError, match=r"anchors\[0\]: marker ids 49\.\.50 do not fit DICT_4X4_50"):
        parse_anchors([{**BLOCK, "id": 49}])
    assert looking_for([spec]) == "Looking for domino ids 10-11, DICT_4X4_50, 50 mm"
    near, far = distance_range_m(spec, _camera())
    assert near == pytest.approx(900 * 0.12 / (0.8 * 720)) and far == pytest.approx(900 * 0.05 / 25)


def test_toy_kind_prints_a_sheet_opencv_reads(domino):
    spec = parse_anchors([BLOCK])[0]
    img, block = sheet(spec, dpi=200)
    assert block == {"anchors": [BLOCK]}
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    corners, ids, _ = cv2.aruco.ArucoDetector(d).detectMarkers(img)
    assert ids is not None and sorted(ids.ravel().tolist()) == [10, 11]
    # id 10 left of id 11, as the kind's geometry says, and 70 mm apart centre to centre at 200 dpi
    centre = {int(i): c.reshape(4, 2).mean(axis=0) for i, c in zip(ids.ravel(), corners)}
    assert centre[11][0] - centre[10][0] == pytest.approx(0.07 / 0.0254 * 200, abs=2.0)
    assert abs(centre[11][1] - centre[10][1]) < 2.0


@pytest.mark.parametrize("tilt_deg", [0.0, 35.0])
def test_toy_kind_is_tracked_at_its_true_pose(domino, tilt_deg):
    spec = parse_anchors([BLOCK])[0]
    camera = _camera()
    # camera 0.45 m in front of the domino, tilted about x and turned a little about z
    R = cv2.Rodrigues(np.array([np.radians(180 + tilt_deg), 0.0, 0.0]))[0] @ cv2.Rodrigues(np.array([0, 0, 0.2]))[0]
    rvec, tvec = cv2.Rodrigues(R)[0], np.array([0.01, -0.005, 0.45])
    corners = build_models([spec])[0].markers
    paper = np.array([[-0.1, 0.05, 0], [0.1, 0.05, 0], [0.1, -0.05, 0], [-0.1, -0.05, 0]])
    image = _draw_markers(camera, rvec, tvec, corners, paper)
    truth = invert(from_rvec_tvec(rvec, tvec))  # world_from_camera; the world is the domino's frame

    res = AnchorTracker([spec], camera, filter=False).process(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR), 0.0)

    assert res.world_from_camera is not None and res.markers == 2
    pos_err = np.linalg.norm(res.world_from_camera[:3, 3] - truth[:3, 3])
    rot_err = np.degrees(np.arccos(np.clip((np.trace(res.world_from_camera[:3, :3].T @ truth[:3, :3]) - 1) / 2, -1, 1)))
    # measured 0.09 / 0.04 mm and 0.012 / 0.004 degrees (face-on / tilted)
    assert pos_err < 0.0003, f"position off by {pos_err * 1000:.2f} mm"
    assert rot_err < 0.04, f"rotation off by {rot_err:.3f} degrees"


@pytest.mark.parametrize("block, field", [
    ({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 40}, "length"),
    ({"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 5, "markers_y": 7, "marker_length": 0.04,
      "separation": 10}, "separation"),
    ({"kind": "charuco", "dictionary": "DICT_4X4_50", "squares_x": 5, "squares_y": 7, "square_length": 0.03,
      "marker_length": 22}, "marker_length"),
])
def test_a_length_typed_in_millimetres_is_refused_saying_metres(block, field):
    # the rule: no printed anchor is 5 m long; 40 (mm meant) would put the camera hundreds of metres off
    from tracking.errors import SessionError
    from tracking.recording.schema import parse_anchors

    value = block[field]
    with pytest.raises(SessionError, match=rf"^anchors\[0\]\.{field}: {value} m is larger than any printed anchor; "
                                            rf"lengths are in metres \({value} mm is {value / 1000:g}\)$"):
        parse_anchors([block])
    assert parse_anchors([{**block, field: 5.0}])   # a poster-sized board is still taken


@pytest.mark.parametrize("typed, meant", [("DICT_6x6_50", "DICT_6X6_50"), ("4X4_50", "DICT_4X4_50"),
                                          ("DICT_5X5_10O", "DICT_5X5_100")])
def test_a_dictionary_name_typed_nearly_right_is_named(typed, meant):
    from tracking.errors import SessionError
    from tracking.recording.schema import parse_anchors

    with pytest.raises(SessionError, match=rf"'{typed}' is not an OpenCV ArUco dictionary; did you mean '{meant}'\?"):
        parse_anchors([{"kind": "aruco", "dictionary": typed, "id": 3, "length": 0.05}])
    with pytest.raises(SessionError, match=r"is not an OpenCV ArUco dictionary; use one of"):
        parse_anchors([{"kind": "aruco", "dictionary": "MY_MARKERS", "id": 3, "length": 0.05}])


def test_json_saved_with_a_byte_order_mark_is_read(tmp_path):
    # Windows editors save UTF-8 with a byte-order mark: an anchors file and a session.json edited there
    from tracking.jsonfile import read_json
    from tracking.recording.schema import load_session

    block = [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05}]
    path = tmp_path / "anchors.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(block).encode())
    assert read_json(path, "anchors file", expect=list) == block
    rec = tmp_path / "rec"
    rec.mkdir()
    session = {"format": "arapp-recording/1", "video": "video.avi", "fps": 30.0,
               "camera": {"width": 64, "height": 48, "K": [[50, 0, 32], [0, 50, 24], [0, 0, 1]], "dist": [0] * 5},
               "anchors": block}
    (rec / "session.json").write_bytes(b"\xef\xbb\xbf" + json.dumps(session).encode())
    loaded = load_session(rec)
    assert loaded.fps == 30.0 and loaded.anchors[0].id == 3
