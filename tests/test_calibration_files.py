"""Calibration files in the conventions people have (issue 25): OpenCV FileStorage with
camera_matrix / distortion_coefficients or K / D (or dist_coeffs), ROS camera_info YAML, and files
without an image size (taken from the video, and said). The oracle is the numbers each test writes
into the file (and OpenCV's own FileStorage writer for the XML/JSON forms); the ROS layout is the one
camera_calibration documents (image_width, image_height, camera_name, camera_matrix{rows,cols,data},
distortion_model, distortion_coefficients{rows,cols,data}, rectification_matrix, projection_matrix)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from arapp.cli import main
from tracking.camera import Camera
from tracking.errors import CalibrationError
from tracking.recording.schema import load_session

DATA = Path(__file__).resolve().parent / "data" / "realvideo"
K = [[500.0, 0.0, 31.5], [0.0, 505.0, 23.5], [0.0, 0.0, 1.0]]
D = [-0.1, 0.02, 0.001, -0.002, 0.003]


def _flat(m):
    return ", ".join(repr(float(x)) for x in np.ravel(m))


def ros_yaml(path: Path, width=64, height=48, model="plumb_bob", dist=D) -> Path:
    P = [[K[0][0], 0, K[0][2], 0], [0, K[1][1], K[1][2], 0], [0, 0, 1, 0]]
    path.write_text(
        f"image_width: {width}\nimage_height: {height}\ncamera_name: narrow_stereo\n"
        f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{_flat(K)}]\n"
        f"distortion_model: {model}\n"
        f"distortion_coefficients:\n  rows: 1\n  cols: {len(dist)}\n  data: [{_flat(dist)}]\n"
        f"rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [{_flat(np.eye(3))}]\n"
        f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: [{_flat(P)}]\n")
    return path


def video(path: Path, n: int = 6, size=(64, 48)) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, size)
    for i in range(n):
        w.write(np.full((size[1], size[0], 3), 20 * i, np.uint8))
    w.release()
    return path


def assert_camera(cam: Camera, width=64, height=48, dist=D):
    assert np.allclose(cam.K, K) and np.allclose(cam.dist, dist) and (cam.width, cam.height) == (width, height)


def test_ros_camera_info_yaml_reads_as_written(tmp_path):
    cam, notes = Camera.load_file(ros_yaml(tmp_path / "ros.yaml"))
    assert_camera(cam)
    assert any("ROS camera_info" in n for n in notes)
    eight = [-0.1, 0.02, 0.001, -0.002, 0.003, 0.01, 0.0, 0.0]
    assert_camera(Camera.load_yaml(ros_yaml(tmp_path / "rational.yaml", model="rational_polynomial", dist=eight)),
                  dist=eight)


def test_ros_fisheye_is_refused_naming_the_model(tmp_path):
    with pytest.raises(CalibrationError, match="equidistant.*plumb_bob"):
        Camera.load_yaml(ros_yaml(tmp_path / "fish.yaml", model="equidistant", dist=[0.1, 0.0, 0.0, 0.0]))


@pytest.mark.parametrize("text", [
    "%YAML:1.0\nK: [{k}]\nD: [{d}]\nimage_width: 64\nimage_height: 48\n",
    "K:\n  - [{k0}]\n  - [{k1}]\n  - [{k2}]\ndist_coeffs: [{d}]\nwidth: 64\nheight: 48\n",  # nested rows
    "camera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [{k}]\n"
    "dist_coeffs: [{d}]\nimage_width: 64\nimage_height: 48\n",
])
def test_short_key_names_and_plain_lists(tmp_path, text):
    path = tmp_path / "cam.yaml"
    path.write_text(text.format(k=_flat(K), d=_flat(D), k0=_flat(K[0]), k1=_flat(K[1]), k2=_flat(K[2])))
    assert_camera(Camera.load_yaml(path))


@pytest.mark.parametrize("suffix", [".xml", ".json"])
def test_opencv_writer_files_with_k_and_d(tmp_path, suffix):
    """What a user's own script writes with cv2.FileStorage under the names K and D (the oracle is OpenCV's writer)."""
    path = tmp_path / f"cam{suffix}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("K", np.array(K))
    fs.write("D", np.array(D).reshape(1, -1))
    fs.write("image_width", 64)
    fs.write("image_height", 48)
    fs.release()
    assert_camera(Camera.load_yaml(path))


def test_a_file_without_image_size_takes_the_videos_and_says_so(tmp_path, capsys, config_dir):
    path = tmp_path / "kd.yaml"
    path.write_text(f"K: [{_flat(K)}]\nD: [{_flat(D)}]\n")
    with pytest.raises(CalibrationError, match="image_width, image_height: missing"):
        Camera.load_yaml(path)  # no video to take the size from: refused, naming the keys
    out = tmp_path / "rec"
    assert main(["record", "--source", str(video(tmp_path / "clip.avi")), "--calibration", str(path),
                 "--out", str(out), "--seconds", "0.3"]) == 0
    said = capsys.readouterr().out
    assert "gives no image size; taken as the frames' 64x48" in said
    assert "estimated" not in said  # the file's camera, not the estimate
    assert_camera(load_session(out).camera)


def test_a_ros_file_made_at_twice_the_size_is_scaled_to_the_video(tmp_path, config_dir):
    path = ros_yaml(tmp_path / "ros.yaml", width=128, height=96)
    out = tmp_path / "rec"
    assert main(["record", "--source", str(video(tmp_path / "clip.avi")), "--calibration", str(path),
                 "--out", str(out), "--seconds", "0.3"]) == 0
    cam = load_session(out).camera
    # the pixel-centre rule written here: c' = (c + 0.5) * s - 0.5, f' = f * s
    assert np.isclose(cam.fx, 250.0) and np.isclose(cam.cx, (31.5 + 0.5) * 0.5 - 0.5)


def test_the_caliscope_file_reads_as_its_project_wrote_it():
    cam = Camera.load_yaml(DATA / "caliscope_cam0.yml")
    assert (cam.width, cam.height) == (1280, 720)
    assert np.isclose(cam.fx, 903.55012408999903) and np.isclose(cam.dist[4], 0.066568230149576899)


@pytest.mark.parametrize("text, needles", [
    ("foo: 1\nbar: [1, 2]\n", ["no camera matrix", "camera_matrix (or K)", "dist_coeffs", "ROS camera_info",
                               "keys: foo, bar"]),
    ("hello this is: [not yaml\n", ["not a calibration file OpenCV can read", "line", "camera_matrix (or K)"]),
    ("camera_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 2, 3]\nimage_width: 64\nimage_height: 48\n",
     ["rows x cols is 3 x 3 but data holds 3"]),
    ("K: [1, 0, 2, 0, 1, 2, 0, 0]\n", ["K: must be 3x3 (9 numbers), got 8 numbers"]),
    ("K: [1, 0, 2, 0, 1, 2, 0, 0, oops]\n", ["K: item 8 is not a number"]),
])
def test_a_file_that_cannot_be_read_says_which_keys_it_expected(tmp_path, capsys, config_dir, text, needles):
    path = tmp_path / "cam.yaml"
    path.write_text(text)
    out = tmp_path / "rec"
    for argv in (["record", "--source", str(video(tmp_path / "clip.avi")), "--calibration", str(path), "--out", str(out)],
                 ["replay", str(tmp_path / "clip.avi"), "--calibration", str(path), "--out", str(out)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(path) in err[0] and "Traceback" not in err[0], err
        for needle in needles:
            assert needle in err[0], (needle, err[0])
        assert not out.exists()


def test_anchors_json_is_not_a_calibration(tmp_path, capsys, config_dir):
    """A common slip: the anchors file given as the calibration."""
    path = tmp_path / "anchors.json"
    path.write_text(json.dumps([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.05}]))
    assert main(["record", "--source", str(video(tmp_path / "clip.avi")), "--calibration", str(path),
                 "--out", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera_matrix (or K)" in err[0]
