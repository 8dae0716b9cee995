"""Rules of arapp/geometry/placement.py and tracking/anchors/pose.py that mutation testing found unpinned.

Oracles: matrices built by hand from the placement rules written here (largest extent -> size_mm,
centred over the anchor, standing on z = 0, offset last), OpenCV's cv2.projectPoints and
cv2.solvePnPGeneric, and angles worked out by hand. See docs/mutation-testing.md.
"""

import cv2
import numpy as np
import pytest

from arapp.geometry.model import Model
from arapp.geometry.placement import Placement, dragged_placement, placement_point_at_pixel, world_from_model
from tracking.anchors.detect import Observation
from tracking.anchors.model import square_corners
from tracking.anchors.pose import _robust_cost, planar_solutions, residuals, solve_pose
from tracking.anchors.render import look_at
from tracking.camera import Camera
from tracking.poses import invert, rotation_angle
from tracking.recording.schema import parse_anchor

CAM = Camera([[700.0, 0, 319.5], [0, 700.0, 239.5], [0, 0, 1]], [0.06, -0.04, 0.001, -0.0005, 0.0], 640, 480)

# A (2, 1, 0.5) box from the origin, turned 90 deg about z, sized 40 mm, offset (5, -3, 1) mm.
# By hand: turned, x = -y_model in [-1, 0], y = x_model in [0, 2], z in [0, 0.5]; the largest extent 2
# becomes 40 mm (20 mm per unit): x in [-20, 0], y in [0, 40], z in [0, 10]; centred over the anchor
# (+10, -20) and standing on z = 0, then the offset: mm = 20 * Rz90 @ p + (15, -23, 1).
BOUNDS = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]])
PLACE = Placement(40.0, (5.0, -3.0, 1.0), (0.0, 0.0, 90.0))
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def hand_placement_mm():
    m = np.eye(4)
    m[:3, :3] = 20.0 * RZ90
    m[:3, 3] = (15.0, -23.0, 1.0)
    return m


def test_placement_matrix_by_hand():
    mm = hand_placement_mm()
    assert np.allclose(PLACE.matrix(BOUNDS), mm)        # default unit: millimetres
    assert np.allclose(PLACE.matrix(BOUNDS, "mm"), mm)
    m = mm.copy()
    m[:3] *= 1e-3
    assert np.allclose(PLACE.matrix(BOUNDS, "m"), m)
    # a dict placement is read as Placement.from_any does; the far corner lands where worked out above
    got = Placement.from_any({"size_mm": 40, "offset": [5, -3, 1], "rotation_deg": 90}).matrix(BOUNDS.tolist())
    assert np.allclose(got @ [2.0, 1.0, 0.5, 1.0], [-5.0, 17.0, 11.0, 1.0])
    # None is the default placement: 50 mm, no offset, no turn -> 25 mm per unit, centred, on z = 0
    got = Placement.from_any(None).matrix(BOUNDS)
    assert np.allclose(got @ [2.0, 1.0, 0.5, 1.0], [25.0, 12.5, 12.5, 1.0])
    assert np.allclose(got @ [0.0, 0.0, 0.0, 1.0], [-25.0, -12.5, 0.0, 1.0])


def test_world_from_model_by_hand_on_a_marker_and_a_board():
    import trimesh

    model = Model("box", placement=PLACE, source_mesh=trimesh.creation.box(bounds=BOUNDS))
    wfa = np.array([[0.0, -1.0, 0.0, 0.2], [1.0, 0.0, 0.0, 0.1], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1.0]])
    marker = parse_anchor({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05,
                           "world_from_anchor": wfa.tolist()})
    placement_m = hand_placement_mm()
    placement_m[:3] *= 1e-3
    assert np.allclose(world_from_model(marker, model), wfa @ placement_m)
    # board: placement frame at the board centre (from OpenCV's own board), y and z flipped
    board = parse_anchor({"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                          "marker_length": 0.04, "separation": 0.01})
    cvb = cv2.aruco.GridBoard((4, 3), 0.04, 0.01, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    pts = np.concatenate([np.asarray(c).reshape(-1, 3) for c in cvb.getObjPoints()])
    wfp = np.diag([1.0, -1.0, -1.0, 1.0])
    wfp[:3, 3] = (pts.min(0) + pts.max(0)) / 2
    assert np.allclose(world_from_model(board, model), wfp @ placement_m)
    # the model's far top corner: 11 mm out of the paper is -z in OpenCV's board frame
    far = world_from_model(board, model) @ [2.0, 1.0, 0.5, 1.0]
    assert np.allclose(far[:3], wfp[:3, 3] + [-0.005, -0.017, -0.011])


@pytest.mark.parametrize("a0, a1, want", [
    (45.0, 135.0, 90.0),       # a quarter turn left
    (45.0, -90.0, -135.0),     # right
    (170.0, -170.0, 20.0),     # across the pointer's +-180 seam: the short way
    (-100.0, 100.0, -160.0),   # 200 deg raw is -160 the short way
])
def test_turn_is_the_angle_swept_about_the_offset(a0, a1, want):
    start = Placement(40.0, (10.0, 5.0, 2.0), (90.0, 0.0, 30.0))
    o = np.array(start.offset[:2])
    at = lambda deg, r: o + r * np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])  # noqa: E731
    got = dragged_placement(start, at(a0, 7.0), at(a1, 3.0), mode="turn")
    expect_rz = (30.0 + want + 180.0) % 360.0 - 180.0
    assert got.offset == start.offset and got.size_mm == 40.0
    assert np.allclose(got.rotation_deg, (90.0, 0.0, expect_rz), atol=1e-9)


def test_unknown_drag_mode_is_named():
    with pytest.raises(ValueError, match="'move' or 'turn'.*'spin'"):
        dragged_placement(Placement(), (0, 0), (1, 1), mode="spin")


def test_paper_point_seen_low_and_far():
    """A camera 5 cm above a marker's paper: rays down to 2 deg above the paper and 1000x the height deep
    still give the point (the GUI drags on a far, flat view); 1.5 deg does not."""
    marker = parse_anchor({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05})
    h = 0.05
    for graze_deg, seen in ((2.5, True), (1.5, False)):
        d = h / np.tan(np.radians(graze_deg))
        X = np.array([0.01, d, 0.0])
        pose = look_at([0.0, 0.0, h], X, up=(0, 0, 1))
        cw = invert(pose)
        uv, _ = cv2.projectPoints(X.reshape(1, 3), cv2.Rodrigues(cw[:3, :3])[0], cw[:3, 3], CAM.K, CAM.dist)
        got = placement_point_at_pixel(CAM, pose, marker, uv.reshape(2))
        if seen:
            assert got is not None and np.abs(got - X[:2] * 1000).max() < 0.5, (graze_deg, got)
        else:
            assert got is None


# ---- tracking/anchors/pose.py ----

def _project(world_from_camera, X):
    cw = invert(world_from_camera)
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 3), cv2.Rodrigues(cw[:3, :3])[0], cw[:3, 3],
                              CAM.K, CAM.dist)
    return uv.reshape(-1, 2)


def _board_points():
    b = cv2.aruco.GridBoard((4, 3), 0.04, 0.01, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    obj = np.concatenate([np.asarray(c).reshape(-1, 3) for c in b.getObjPoints()])
    return obj, np.repeat(np.asarray(b.getIds()).ravel(), 4)


GT = look_at([0.05, 0.25, -0.4], [0.09, 0.07, 0.0], up=(0, -1, 0))   # board frame: z into the paper


def test_residuals_give_behind_points_the_big_value():
    cfw = invert(GT)
    pts = np.array([[0.09, 0.07, 0.0], [0.05, 0.25, -0.5]])   # on the board; behind the camera
    img = _project(GT, pts[:1])
    r = residuals(CAM, cfw, pts, np.vstack([img, img]))
    assert r[0] < 1e-6 and r[1] == 1e6


def test_robust_cost_is_truncated_squares():
    assert _robust_cost(np.array([1.0, 2.0, 5.0]), 3.0) == pytest.approx(1 + 4 + 9)


def test_planar_solutions_are_opencvs_ippe():
    obj = square_corners(0.05)
    gt = look_at([0.12, -0.05, 0.4], [0, 0, 0], up=(0, 1, 0))
    img = _project(gt, obj) + np.random.default_rng(1).normal(0, 0.3, (4, 2))
    # a square marker: IPPE_SQUARE on the distorted pixels, as OpenCV gives it
    n, rv, tv, _ = cv2.solvePnPGeneric(obj, img, CAM.K, CAM.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    sols = planar_solutions(Observation(0, obj, img, np.zeros(4, int), 1, square=True), CAM)
    assert len(sols) == n == 2
    for s, r, t in zip(sols, rv, tv):
        assert np.allclose(cv2.Rodrigues(s[:3, :3])[0].ravel(), r.ravel(), atol=1e-9)
        assert np.allclose(s[:3, 3], t.ravel(), atol=1e-9)
    # four points that are not a marker's corners (square=False): plain IPPE; exact points give the pose
    quad = np.array([[0.0, 0.0, 0.0], [0.07, 0.01, 0.0], [0.05, 0.06, 0.0], [-0.01, 0.04, 0.0]])
    sols = planar_solutions(Observation(0, quad, _project(gt, quad), np.zeros(4, int), 1), CAM)
    assert np.allclose(invert(sols[0]), gt, atol=1e-6)


def test_a_misdetected_marker_is_dropped_and_the_board_decides():
    """A second anchor's marker found 40 px off (a mis-detection): its own IPPE pose fits it exactly, but
    scored on all points the board's pose wins; the marker's corners are outliers, dropped as a whole,
    and one board marker with bad corners is dropped too (11 of 12 markers used)."""
    obj, ids = _board_points()
    img = _project(GT, obj)
    img[ids == 5] += [9.0, -7.0]                     # board marker 5: corners off
    wfm = np.diag([1.0, -1.0, -1.0, 1.0])            # the marker lies on the same sheet, right of the board
    wfm[:3, 3] = (0.25, 0.05, 0.0)
    mobj = square_corners(0.05)
    mimg = _project(GT, mobj @ wfm[:3, :3].T + wfm[:3, 3]) + [40.0, 0.0]
    obs = [Observation(1, mobj, mimg, np.full(4, 7), 1, square=True),
           Observation(0, obj, img, ids, 12)]
    sol = solve_pose(obs, [np.eye(4), wfm], CAM)
    assert sol is not None
    assert np.linalg.norm(sol.world_from_camera[:3, 3] - GT[:3, 3]) < 1e-6
    assert np.degrees(rotation_angle(sol.world_from_camera[:3, :3] @ GT[:3, :3].T)) < 1e-5
    want = np.r_[np.zeros(4, bool), ids != 5]
    assert sol.inliers.dtype == bool and np.array_equal(sol.inliers, want)
    assert sol.markers == 11 and sol.anchors == [0] and sol.rms < 1e-6


def test_anchors_too_small_alone_start_from_the_prediction():
    """Two anchors with 3 points each: neither has its own IPPE pose; with a prediction (0.05 deg, 0.5 mm
    off: within the 3 px inlier gate) the 6 points together give the pose; without one there is nothing
    to start from."""
    obj, ids = _board_points()
    a, b = obj[ids == 0][:3], obj[ids == 11][:3]
    obs = [Observation(0, a, _project(GT, a), np.zeros(3, int), 1),
           Observation(1, b, _project(GT, b), np.full(3, 11), 1)]
    wfa = [np.eye(4), np.eye(4)]
    assert solve_pose(obs, wfa, CAM) is None
    off = np.eye(4)
    off[:3, :3] = cv2.Rodrigues(np.radians([0.03, -0.04, 0.0]))[0]
    off[:3, 3] = (0.0005, 0.0, 0.0)
    sol = solve_pose(obs, wfa, CAM, predicted_camera_from_world=invert(GT @ off))
    assert sol is not None and np.linalg.norm(sol.world_from_camera[:3, 3] - GT[:3, 3]) < 1e-6


def test_second_pass_drops_a_corner_off_by_one_and_a_half_pixels():
    """The second inlier pass gates at 4 robust sigmas of the residuals, never below 1 px: on exact points
    (sigma ~ 0) a corner 1.5 px off, kept by the first 3 px pass, is dropped there alone (its marker keeps
    3 of 4 corners, so the marker stays)."""
    obj, ids = _board_points()
    img = _project(GT, obj)
    bad = np.flatnonzero(ids == 3)[1]
    img[bad] += [1.5, 0.0]
    sol = solve_pose([Observation(0, obj, img, ids, 12)], [np.eye(4)], CAM)
    want = np.ones(len(obj), bool)
    want[bad] = False
    assert np.array_equal(sol.inliers, want) and sol.markers == 12
    assert np.linalg.norm(sol.world_from_camera[:3, 3] - GT[:3, 3]) < 1e-6


def test_a_marker_with_most_corners_off_is_dropped_whole():
    """Whole-marker rejection: marker 7 with 3 of 4 corners 6 px off loses its 4th corner too; marker 9
    with 2 of 4 off (not fewer than half in) keeps its 2 good corners."""
    obj, ids = _board_points()
    img = _project(GT, obj)
    m7, m9 = np.flatnonzero(ids == 7), np.flatnonzero(ids == 9)
    img[m7[:3]] += [6.0, 0.0]
    img[m9[:2]] += [0.0, -6.0]
    sol = solve_pose([Observation(0, obj, img, ids, 12)], [np.eye(4)], CAM)
    want = np.ones(len(obj), bool)
    want[m7] = False
    want[m9[:2]] = False
    assert np.array_equal(sol.inliers, want) and sol.markers == 11
    assert np.linalg.norm(sol.world_from_camera[:3, 3] - GT[:3, 3]) < 1e-6
