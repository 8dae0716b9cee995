"""The placement frame of each anchor kind, against OpenCV's own board geometry."""

import cv2
import numpy as np

from arapp.placement import placement_from_any, world_from_placement
from tracking.session import parse_anchor


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
    from arapp.geometry.model import Placement

    base = Placement(40.0, (1.0, 2.0, 0.0), (90.0, 0.0, 0.0))
    p = placement_from_any({"size_mm": 60, "rotation_deg": 30}, base)
    assert p.size_mm == 60 and p.offset == (1.0, 2.0, 0.0) and p.rotation_deg == (0.0, 0.0, 30.0)
