"""The camera model and session parsing against OpenCV and the recording contract."""

import json

import cv2
import numpy as np
import pytest

from tracking.camera import Camera
from tracking.errors import SessionError
from tracking.poses import invert, pose_to_tum, read_tum, tum_to_pose, write_tum
from tracking.recording.schema import parse_session

K = [[612.3, 0.0, 331.7], [0.0, 598.1, 229.2], [0.0, 0.0, 1.0]]
DIST = [0.12, -0.21, 0.002, -0.001, 0.05]


def test_project_matches_cv2_and_unproject_inverts():
    cam = Camera(K, DIST, 640, 480)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-0.3, -0.2, 0.8], [0.3, 0.2, 2.0], (50, 3))
    rvec, tvec = np.array([0.1, -0.2, 0.05]), np.array([0.01, 0.02, 0.1])
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec
    ref, _ = cv2.projectPoints(pts, rvec, tvec, np.array(K), np.array(DIST))
    got = cam.project_world(pts, invert(T))
    assert np.abs(got - ref.reshape(-1, 2)).max() < 1e-9
    pc = pts @ T[:3, :3].T + T[:3, 3]
    back = cam.unproject(cam.project(pc), pc[:, 2])
    assert np.abs(back - pc).max() < 1e-9


def test_yaml_roundtrip_and_opencv_names(tmp_path):
    cam = Camera(K, DIST, 640, 480)
    path = tmp_path / "cam.yaml"
    cam.save_yaml(path)
    text = path.read_text()
    for key in ("camera_matrix", "distortion_coefficients", "image_width", "image_height"):
        assert key in text
    back = Camera.load_yaml(path)
    assert np.allclose(back.K, cam.K) and np.allclose(back.dist, cam.dist)
    assert back.size == (640, 480)


def test_scaled_keeps_pixel_centre_convention():
    cam = Camera(K, np.zeros(5), 640, 480)
    half = cam.scaled(320, 240)
    # A ray through pixel centre (0,0) of the big image hits (-0.25,-0.25) in the small one.
    ray = cam.unproject(np.array([0.0, 0.0]))
    assert np.allclose(half.project(ray), [-0.25, -0.25])


def test_tum_roundtrip(tmp_path):
    rng = np.random.default_rng(2)
    poses = []
    for _ in range(5):
        R = cv2.Rodrigues(rng.normal(size=3))[0]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, rng.normal(size=3)
        poses.append(T)
    write_tum(tmp_path / "x.tum", np.arange(5) / 30, poses)
    t, back = read_tum(tmp_path / "x.tum")
    assert np.allclose(t, np.arange(5) / 30, atol=1e-6)
    assert np.abs(back - np.array(poses)).max() < 1e-8
    assert pose_to_tum(poses[0])[6] >= 0
    assert np.allclose(tum_to_pose(pose_to_tum(poses[1])), poses[1])


def _session():
    return {
        "format": "arapp-recording/1", "video": "video.mkv", "fps": 30.0,
        "camera": {"width": 1280, "height": 720, "K": [[900.0, 0, 639.5], [0, 900.0, 359.5], [0, 0, 1]],
                   "dist": [0, 0, 0, 0, 0]},
        "anchors": [
            {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
             "marker_length": 0.04, "separation": 0.01, "first_id": 0},
            {"kind": "qr", "text": "arapp anchor 1", "length": 0.06,
             "world_from_anchor": [[1, 0, 0, 0], [0, 1, 0, 0.3], [0, 0, 1, 0], [0, 0, 0, 1]]},
        ],
        "source": {"kind": "synthetic"},
    }


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.update(format="x"), "format must be"),
        (lambda d: d["camera"].update(K=[[1, 2], [3, 4]]), "camera.K: must be 3x3"),
        (lambda d: d["anchors"][0].update(dictionary="DICT_9X9_1"), "anchors[0].dictionary"),
        (lambda d: d["anchors"][1].update(length="big"), "anchors[1].length: must be a number"),
        (lambda d: d["anchors"][1].pop("text"), "anchors[1].text: missing"),
        (lambda d: d["anchors"][1].update(world_from_anchor=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
         "anchors[1].world_from_anchor: must be a rigid"),
        (lambda d: d.update(fps=0), "fps: must be a positive number"),
    ],
)
def test_session_errors_name_the_field(mutate, message):
    d = json.loads(json.dumps(_session()))
    parse_session(d, ".")
    mutate(d)
    with pytest.raises(SessionError) as err:
        parse_session(d, ".")
    assert message in str(err.value)
