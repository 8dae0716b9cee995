"""Calibration recovers known intrinsics from rendered ChArUco / chessboard views."""

import numpy as np
import pytest

from tracking.anchors.render import look_at, render_view
from tracking.calibration import BoardSpec, ViewCollector, solve
from tracking.camera import Camera
from tracking.errors import CalibrationError
from tracking.recording.schema import parse_anchors

TRUE = Camera([[610.0, 0, 322.0], [0, 605.0, 236.0], [0, 0, 1]], [-0.12, 0.06, 0.0005, -0.0008, 0.0], 640, 480)
CHARUCO = {"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 7, "squares_y": 5,
           "square_length": 0.03, "marker_length": 0.022}


def views(n, rng):
    """Camera poses around the board (board frame: y down, z into the paper): tilted, off-centre."""
    centre = np.array([0.105, 0.075, 0.0])
    out = []
    for k in range(n):
        tilt = np.radians(rng.uniform(10, 40))
        az = rng.uniform(0, 2 * np.pi)
        d = rng.uniform(0.3, 0.45)
        eye = centre + d * np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)])
        target = centre + np.r_[rng.uniform(-0.05, 0.05, 2), 0]
        out.append(look_at(eye, target, up=(0, -1, 0)))
    return out


@pytest.fixture(scope="module")
def charuco_images():
    an = parse_anchors([CHARUCO])
    rng = np.random.default_rng(5)
    return [render_view(an, TRUE, T, noise_std=1.5, rng=rng) for T in views(18, rng)]


def test_charuco_calibration_recovers_intrinsics(charuco_images):
    board = BoardSpec("charuco", 7, 5, 0.03, 0.022, "DICT_5X5_100")
    col = ViewCollector(board)
    for i, img in enumerate(charuco_images):
        col.add(img, f"view{i}")
    assert len(col.views) >= 12
    res = solve(col.views, col.width, col.height, col.coverage)
    for got, want in ((res.camera.fx, TRUE.fx), (res.camera.fy, TRUE.fy), (res.camera.cx, TRUE.cx),
                      (res.camera.cy, TRUE.cy)):
        assert abs(got - want) / want < 0.005, (got, want)
    assert res.rms < 0.5
    assert len(res.per_view) == len(res.used)
    assert 0 < col.coverage <= 1
    assert "RMS reprojection error" in res.report()


def test_collector_rejects_duplicates_and_blur(charuco_images):
    import cv2
    board = BoardSpec("charuco", 7, 5, 0.03, 0.022, "DICT_5X5_100")
    col = ViewCollector(board)
    assert col.add(charuco_images[0]) == "kept"
    assert col.add(charuco_images[0]) == "duplicate"
    blurred = cv2.GaussianBlur(charuco_images[1], (0, 0), 4.0)
    assert col.add(blurred) in ("blurred", "no board")
    assert col.add(np.full((480, 640), 128, np.uint8)) == "no board"
    with pytest.raises(CalibrationError, match="need at least"):
        solve(col.views, 640, 480)
    with pytest.raises(CalibrationError, match="marker-length"):
        BoardSpec("charuco", 7, 5, 0.03, 0.04)


def test_calibrate_command_writes_yaml(charuco_images, tmp_path, capsys):
    import cv2

    from arapp.cli import main

    for i, img in enumerate(charuco_images):
        cv2.imwrite(str(tmp_path / f"v{i:02d}.png"), img)
    out = tmp_path / "camera.yaml"
    assert main(["calibrate", "--images", str(tmp_path), "--board", "charuco", "--squares-x", "7", "--squares-y", "5",
                 "--square-length", "0.03", "--marker-length", "0.022", "--dictionary", "DICT_5X5_100",
                 "-o", str(out)]) == 0
    cam = Camera.load_yaml(out)
    assert abs(cam.fx - TRUE.fx) / TRUE.fx < 0.005 and (cam.width, cam.height) == (640, 480)
    text = capsys.readouterr().out
    assert "RMS reprojection error" in text and "coverage" in text and "duplicate" in text
    assert main(["calibrate", "--images", str(tmp_path / "missing"), "-o", str(out)]) == 2
    assert "not a folder" in capsys.readouterr().err
