"""Anchors printed in a custom ArUco dictionary (an OpenCV dictionary file), as OpenCV's tutorial boards are."""

import json

import cv2
import numpy as np
import pytest

from tracking.anchors import AnchorTracker
from tracking.anchors.dictionaries import aruco_dictionary
from tracking.camera import Camera
from tracking.errors import SessionError
from tracking.recording.schema import load_session, parse_anchors


def write_dictionary(path):
    """A 20-marker 5x5 dictionary made by OpenCV (not predefined), written as OpenCV writes one."""
    d = cv2.aruco.extendDictionary(20, 5, randomSeed=7)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    d.writeDictionary(fs)
    fs.release()
    return d


def test_session_names_a_dictionary_file_relative_to_its_folder(tmp_path):
    write_dictionary(tmp_path / "my_dict.yml")
    session = {"format": "arapp-recording/1", "video": "video.mkv", "fps": 30.0,
               "camera": {"width": 640, "height": 480, "K": [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]]},
               "anchors": [{"kind": "aruco", "dictionary": "my_dict.yml", "id": 7, "length": 0.05}]}
    (tmp_path / "session.json").write_text(json.dumps(session))
    s = load_session(tmp_path)
    assert s.anchors[0].dictionary == str((tmp_path / "my_dict.yml").resolve())
    session["anchors"][0]["id"] = 20  # the file holds ids 0..19
    (tmp_path / "session.json").write_text(json.dumps(session))
    with pytest.raises(SessionError, match=r"ids 0\.\.19"):
        load_session(tmp_path)


def test_missing_or_broken_dictionary_file_is_one_clear_error(tmp_path):
    with pytest.raises(SessionError, match="anchors\\[0\\].dictionary: dictionary file .*nope.yml' not found"):
        parse_anchors([{"kind": "aruco", "dictionary": "nope.yml", "id": 0, "length": 0.05}], folder=tmp_path)
    (tmp_path / "bad.yml").write_text("%YAML:1.0\nfoo: 1\n")
    with pytest.raises(SessionError, match="not an OpenCV dictionary file"):
        parse_anchors([{"kind": "aruco", "dictionary": "bad.yml", "id": 0, "length": 0.05}], folder=tmp_path)


def test_marker_of_a_custom_dictionary_is_tracked(tmp_path):
    d = write_dictionary(tmp_path / "d.yml")
    assert np.array_equal(aruco_dictionary(str(tmp_path / "d.yml")).bytesList, d.bytesList)
    cam = Camera([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]], None, 640, 480)
    img = np.full((480, 640), 255, np.uint8)
    img[100:300, 300:500] = cv2.aruco.generateImageMarker(d, 7, 200, borderBits=1)  # off the optical axis
    img = cv2.GaussianBlur(img, (0, 0), 0.8)
    an = parse_anchors([{"kind": "aruco", "dictionary": "d.yml", "id": 7, "length": 0.05}], folder=tmp_path)
    res = AnchorTracker(an, cam, filter=False).process(img, 0.0)
    assert res.markers == 1
    # oracles: OpenCV's detector with the same dictionary finds the same id; the drawing's geometry: edges at
    # pixels 299.5..499.5 and 99.5..299.5 (200 px = 0.05 m, so 0.15 m away), the centre (80, -40) px off
    # the principal point, the camera facing the marker: it sits at (-0.02, -0.01, 0.15) in the marker frame
    p = cv2.aruco.DetectorParameters()
    corners, ids, _ = cv2.aruco.ArucoDetector(d, p).detectMarkers(img)
    assert ids.ravel().tolist() == [7]
    assert np.linalg.norm(res.raw_world_from_camera[:3, 3] - [-0.02, -0.01, 0.15]) < 0.0005
