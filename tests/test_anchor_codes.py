"""The ArUco detector reads only the anchors' own codes (tracking/anchors/detect.py `anchor_codes`) and refines
every anchor's markers in one call (`ArucoDetection._refine`), and finds what the whole dictionary finds.

Oracles: OpenCV's ArucoDetector on the whole predefined dictionary, its markers of the anchors' ids kept
(the same corners, to the bit); the edge refinement of each marker on its own (a rule: one call for many
markers changes none of them).
"""

from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.anchors.detect import ArucoDetection, anchor_codes, detector_parameters
from tracking.anchors.edges import refine_squares
from tracking.anchors.model import build_models
from tracking.default_intrinsics import estimated_camera
from tracking.recording.schema import parse_anchors

CLIPBOARD = Path(__file__).resolve().parent / "data" / "realvideo" / "apriltag_clipboard" / "frames"
ROOM = Path(__file__).resolve().parent / "data" / "realvideo" / "apriltag_room" / "frames"


@pytest.mark.parametrize("name, ids", [("DICT_APRILTAG_36h11", [3, 7, 8, 11, 12, 17, 29]),
                                       ("DICT_APRILTAG_36h11", list(range(0, 30, 2)))])
def test_the_anchors_codes_find_what_the_whole_dictionary_finds(name, ids):
    full = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    codes, entry_ids = anchor_codes(full, ids)
    assert entry_ids.tolist() == sorted(ids) and len(codes.bytesList) == len(ids)
    params = detector_parameters()
    whole, ours = cv2.aruco.ArucoDetector(full, params), cv2.aruco.ArucoDetector(codes, params)
    compared = 0
    for path in sorted(CLIPBOARD.glob("*.png")) + sorted(ROOM.glob("*"))[:4]:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        c_all, id_all, _ = whole.detectMarkers(gray)
        c_our, id_our, _ = ours.detectMarkers(gray)
        expect = {} if id_all is None else {int(i): c for i, c in zip(id_all.ravel(), c_all) if int(i) in ids}
        got = {} if id_our is None else {int(entry_ids[e]): c for e, c in zip(id_our.ravel(), c_our)}
        assert sorted(got) == sorted(expect), path.name
        for i in expect:
            np.testing.assert_array_equal(got[i], expect[i])
        compared += len(expect)
    assert compared >= 20   # the photos show many of the anchors' tags


def test_many_lone_markers_are_refined_as_each_alone():
    gray = cv2.imread(str(CLIPBOARD / "clipboard03.png"), cv2.IMREAD_GRAYSCALE)
    cam = estimated_camera(320, 240)
    blocks = [{"kind": "aruco", "dictionary": "DICT_APRILTAG_36h11", "id": i, "length": 0.026} for i in range(30)]
    det = ArucoDetection(build_models(parse_anchors(blocks)), cam)
    det.lone_end_margin = 0.1
    obs = det.detect(gray)
    assert len(obs) >= 10
    # the rule: each marker refined in a call of its own, from the whole dictionary's corners, gives the same
    whole = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11),
                                    det.detectors[("DICT_APRILTAG_36h11", "auto")].getDetectorParameters())
    corners, ids, _ = whole.detectMarkers(gray)
    raw = {int(i): c.reshape(4, 2).astype(np.float64) for i, c in zip(ids.ravel(), corners)}
    bits = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11).markerSize + 2
    for o in obs:
        (mid,) = set(o.groups.tolist())
        q = raw[mid][None]
        side = np.sqrt(((q - q[:, [3, 0, 1, 2]]) ** 2).sum(2)).min(1)
        alone, ok = refine_squares(gray, q, side / bits, cam, end_margin=np.array([0.1]), strong_only=np.array([True]))
        if not ok.all():
            alone = cv2.cornerSubPix(gray, q.reshape(-1, 1, 2).astype(np.float32), (3, 3), (-1, -1),
                                     (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)).reshape(1, 4, 2)
        np.testing.assert_allclose(o.img, alone.reshape(4, 2), atol=1e-9)
