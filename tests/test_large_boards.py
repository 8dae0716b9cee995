"""Boards as people print them (issue 13): a 6x6 GridBoard (36 markers) and an 11x8 ChArUco board (44 markers).

The views are drawn independently of arapp's renderer: OpenCV's own board image (generateImage) warped by
the homography of a known pose. Oracles: that pose, and OpenCV's estimate from the same image
(ArucoDetector / CharucoDetector, board.matchImagePoints, cv2.solvePnP).
"""

import cv2
import numpy as np
import pytest

from tracking.anchors import AnchorTracker
from tracking.anchors.render import look_at
from tracking.camera import Camera
from tracking.poses import from_rvec_tvec, invert, rotation_angle
from tracking.recording.schema import parse_anchors

PX_PER_M = 4000.0  # board image resolution: every length below is a whole number of pixels at it
MARGIN = 40
SS = 3  # supersampling of the warp


@pytest.fixture(scope="module")
def cam():
    return Camera([[900.0, 0, 639.5], [0, 900.0, 359.5], [0, 0, 1]], None, 1280, 720)


def draw_view(board, camera: Camera, world_from_camera: np.ndarray) -> np.ndarray:
    """Gray camera image of OpenCV's drawing of `board` (board frame = world) seen from world_from_camera."""
    if isinstance(board, cv2.aruco.CharucoBoard):
        size = np.array(board.getChessboardSize()) * board.getSquareLength()
    else:
        size = np.asarray(board.getObjPoints()).reshape(-1, 3).max(axis=0)[:2]
    wh = tuple(int(round(v * PX_PER_M)) + 2 * MARGIN for v in size)
    flat = board.generateImage(wh, marginSize=MARGIN, borderBits=1)
    # board-image pixel (centres at integers) -> board metres
    metre_from_px = np.array([[1 / PX_PER_M, 0, (0.5 - MARGIN) / PX_PER_M],
                              [0, 1 / PX_PER_M, (0.5 - MARGIN) / PX_PER_M], [0, 0, 1]])
    cfw = invert(world_from_camera)
    cam_from_metre = camera.K @ np.c_[cfw[:3, 0], cfw[:3, 1], cfw[:3, 3]]
    # supersampled camera pixels: centre of a big pixel (i + 0.5) / SS - 0.5
    big_from_cam = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1.0]])
    H = big_from_cam @ cam_from_metre @ metre_from_px
    big = cv2.warpPerspective(flat, H, (camera.width * SS, camera.height * SS), flags=cv2.INTER_LINEAR,
                              borderValue=110)
    img = cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), 0.7)


def opencv_pose(board, detector, camera: Camera, gray: np.ndarray) -> np.ndarray:
    """world_from_camera by OpenCV alone: board detection, matchImagePoints, solvePnP."""
    if isinstance(detector, cv2.aruco.CharucoDetector):
        cc, ci, _, _ = detector.detectBoard(gray)
        obj, img = board.matchImagePoints(cc, ci)
    else:
        corners, ids, _ = detector.detectMarkers(gray)
        obj, img = board.matchImagePoints(corners, ids)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist)
    assert ok
    return invert(from_rvec_tvec(rvec, tvec))


def subpix_detector(dictionary):
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(dictionary, p)


VIEWS = [look_at([0.02, 0.30, -0.42], [0.105, 0.09, 0.0], up=(0, -1, 0)),
         look_at([0.25, -0.05, -0.38], [0.105, 0.09, 0.0], up=(0, -1, 0))]


def check(pose, ref, gt):
    """arapp's pose agrees with OpenCV's, and with the truth, within what the corners allow.

    Measured on these views (about 0.5 m away, boards ~400 px wide): OpenCV's own estimate is 0.05 to 0.2 mm
    and 0.005 to 0.013 deg from the truth; the bounds are about 3 times that."""
    d_ref = np.linalg.norm(pose[:3, 3] - ref[:3, 3])
    r_ref = np.degrees(rotation_angle(pose[:3, :3] @ ref[:3, :3].T))
    d_gt = np.linalg.norm(pose[:3, 3] - gt[:3, 3])
    r_gt = np.degrees(rotation_angle(pose[:3, :3] @ gt[:3, :3].T))
    assert d_ref < 0.0006 and r_ref < 0.04, (d_ref, r_ref)
    assert d_gt < 0.0006 and r_gt < 0.04, (d_gt, r_gt)


def tracks_like_opencv(spec: dict, board, detector, cam, gt: np.ndarray, markers: int) -> None:
    """The tracker sees all `markers` of `board` drawn at ground truth `gt` and its raw pose agrees with
    both OpenCV's own pose from `detector` and the ground truth (see check)."""
    gray = draw_view(board, cam, gt)
    ref = opencv_pose(board, detector, cam, gray)
    res = AnchorTracker(parse_anchors([spec]), cam, filter=False).process(gray, 0.0)
    assert res.markers == markers
    assert res.raw_world_from_camera is not None
    check(res.raw_world_from_camera, ref, gt)


@pytest.mark.parametrize("view", range(len(VIEWS)))
def test_gridboard_6x6_tracks(cam, view):
    spec = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 6, "markers_y": 6,
            "marker_length": 0.03, "separation": 0.006, "first_id": 0}
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    board = cv2.aruco.GridBoard((6, 6), 0.03, 0.006, d)
    tracks_like_opencv(spec, board, subpix_detector(d), cam, VIEWS[view], markers=36)


@pytest.mark.parametrize("view", range(len(VIEWS)))
def test_charuco_11x8_tracks(cam, view):
    spec = {"kind": "charuco", "dictionary": "DICT_5X5_100", "squares_x": 11, "squares_y": 8,
            "square_length": 0.02, "marker_length": 0.015, "first_id": 0}
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    board = cv2.aruco.CharucoBoard((11, 8), 0.02, 0.015, d)
    tracks_like_opencv(spec, board, cv2.aruco.CharucoDetector(board), cam, VIEWS[view], markers=44)


def test_many_squares_refine_in_one_call():
    """refine_squares on 600 squares at once (a map of 600 x 1088 samples) refines them all."""
    from tracking.anchors.edges import refine_squares
    img = np.full((800, 1000), 200, np.uint8)
    quads = []
    for j in range(20):
        for i in range(30):
            x, y = 10 + 33 * i, 10 + 39 * j
            img[y:y + 20, x:x + 20] = 30
            quads.append([[x - 0.5, y - 0.5], [x + 19.5, y - 0.5], [x + 19.5, y + 19.5], [x - 0.5, y + 19.5]])
    quads = np.array(quads)
    out, ok = refine_squares(cv2.GaussianBlur(img, (0, 0), 0.8), quads + 0.6, np.full(len(quads), 4.0))
    assert ok.all()
    assert np.abs(out - quads).max() < 0.05
