"""The placement frame of each anchor kind, against OpenCV's own board geometry."""

import cv2
import numpy as np

from arapp.geometry.placement import world_from_placement
from tracking.recording.schema import parse_anchor


def test_board_placement_frame_is_board_centre_with_normal_out_of_paper():
    a = parse_anchor({"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                      "marker_length": 0.04, "separation": 0.01})
    board = cv2.aruco.GridBoard((4, 3), 0.04, 0.01, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    corners = np.concatenate([np.asarray(c).reshape(-1, 3) for c in board.getObjPoints()])
    T = world_from_placement(a)
    assert np.allclose(T[:3, 3], (corners.min(0) + corners.max(0)) / 2)
    # OpenCV's board z points into the paper, so out of the paper is -z in the world.
    assert np.allclose(T[:3, 2], [0, 0, -1])
    # "up" on the printed board (towards marker 0's row) is -y of the board frame.
    assert np.allclose(T[:3, 1], [0, -1, 0])
    assert np.isclose(np.linalg.det(T[:3, :3]), 1)


def test_single_marker_placement_is_the_anchor_frame():
    a = parse_anchor({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05,
                      "world_from_anchor": [[0, -1, 0, 0.2], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})
    assert np.allclose(world_from_placement(a), a.world_from_anchor)


def test_partial_placement_dict_keeps_the_rest():
    from arapp.geometry.placement import Placement

    base = Placement(40.0, (1.0, 2.0, 0.0), (90.0, 0.0, 0.0))
    p = Placement.from_any({"size_mm": 60, "rotation_deg": 30}, base)
    assert p.size_mm == 60 and p.offset == (1.0, 2.0, 0.0) and p.rotation_deg == (0.0, 0.0, 30.0)


def _cv_pixel(camera, world_from_camera, X):
    cw = np.linalg.inv(world_from_camera)
    rvec, _ = cv2.Rodrigues(cw[:3, :3])
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 3), rvec, cw[:3, 3], camera.K, camera.dist)
    return uv.reshape(-1, 2)


def test_paper_point_under_a_pixel_inverts_opencv_projection():
    from arapp.geometry.placement import placement_point_at_pixel
    from tracking.anchors.render import look_at
    from tracking.camera import Camera

    cam = Camera(np.array([[600.0, 0, 330.0], [0, 590.0, 235.0], [0, 0, 1]]), np.array([-0.1, 0.03, 0.001, 0, 0]),
                 640, 480)
    board = parse_anchor({"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                          "marker_length": 0.04, "separation": 0.01})
    marker = parse_anchor({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05})
    for anchor in (board, marker):
        centre = world_from_placement(anchor)[:3, 3]
        pose = look_at(centre + [0.15, -0.2, 0.3] * np.array([1, 1, 1 if anchor is marker else -1]), centre)
        rng = np.random.default_rng(4)
        for xy_mm in rng.uniform(-60, 60, (20, 2)):
            X = world_from_placement(anchor) @ np.array([xy_mm[0] / 1000, xy_mm[1] / 1000, 0.0, 1.0])
            pixel = _cv_pixel(cam, pose, X[:3])[0]
            got = placement_point_at_pixel(cam, pose, anchor, pixel)
            assert got is not None and np.abs(got - xy_mm).max() < 1e-3
        # a camera looking level just above the paper: of the top and bottom rows, the one whose ray runs
        # above the horizon meets no paper
        up = 0.02 if anchor is marker else -0.02   # out of the paper
        level = look_at(centre + [0.0, -0.5, up], centre + [0.0, 0.5, up])
        hits = [placement_point_at_pixel(cam, level, anchor, px) for px in ([320.0, 5.0], [320.0, 475.0])]
        assert sum(h is None for h in hits) == 1


def test_dragging_moves_in_the_plane_and_turns_about_the_model():
    from arapp.geometry.placement import Placement
    from arapp.geometry.placement import dragged_placement

    start = Placement(40.0, (10.0, 5.0, 2.0), (90.0, 0.0, 170.0))
    moved = dragged_placement(start, (12.0, 7.0), (32.0, -3.0))
    assert moved.offset == (30.0, -5.0, 2.0) and moved.rotation_deg == start.rotation_deg and moved.size_mm == 40.0
    # a quarter turn around the model's offset, across the +-180 degree seam
    turned = dragged_placement(start, (20.0, 5.0), (10.0, 15.0), mode="turn")
    assert turned.offset == start.offset
    assert np.allclose(turned.rotation_deg, (90.0, 0.0, -100.0))
