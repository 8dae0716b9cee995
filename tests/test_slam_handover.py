"""Which pose carries a frame when a board leaves the view: the anchors' or the flow's (issue 13: fast pans).

One frame after a sharp board, the flow's pose is within a millimetre of the anchors' last one, while the
board's last few markers, smeared at the image edge, fit their corners to a pixel and read a centimetre
off. The flow's points would be placed on the plane again from whichever pose the frame takes, and carry
its error through the whole pan. `Handover.flow_holds_better` takes the flow when the anchors' expected
position error is the larger: their position spread at the fit's own residual, against the spread of the
anchors' last pose plus `FLOW_DRIFT_M` a frame.

Oracle: the camera position's RMS error over 200 noise draws, each pose by cv2.solvePnP (SQPnP, then
Levenberg-Marquardt), for this frame's corners and for the last frame's, against the same drift allowance.
"""

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from test_slam_start import _look
from tracking.camera import Camera
from tracking.recording.schema import parse_anchors
from tracking.fusion import Tracker
from tracking.fusion.handover import FLOW_DRIFT_M
from tracking.fusion.state import AnchorMemory

K = np.array([[530.0, 0, 319.5], [0, 530.0, 239.5], [0, 0, 1]])
BOARD = [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
          "marker_length": 0.035, "separation": 0.008}]
ALL = tuple(range(12))


def _draws(world, pose, sigma, rng, n=200):
    """(fitted world_from_camera, RMS residual px) for n noisy views of `world` (N,3) from `pose`."""
    uv = Camera(K, np.zeros(5), 640, 480).project_world(world, pose)
    out = []
    for _ in range(n):
        seen = uv + rng.normal(0.0, sigma, uv.shape)
        _, rv, tv = cv2.solvePnP(world, seen, K, None, flags=cv2.SOLVEPNP_SQPNP)
        _, rv, tv = cv2.solvePnP(world, seen, K, None, rv, tv, True, cv2.SOLVEPNP_ITERATIVE)
        cfw = np.eye(4)
        cfw[:3, :3], cfw[:3, 3] = cv2.Rodrigues(rv)[0], tv.ravel()
        rms = float(np.sqrt(np.mean((cv2.projectPoints(world, rv, tv, K, None)[0].reshape(-1, 2) - seen) ** 2)))
        out.append((np.linalg.inv(cfw), rms))
    return out


@pytest.mark.parametrize("markers, sigma, flow", [((0, 1, 4, 5), 1.0, True), ((0, 1, 4, 5), 0.15, True),
                                                  (ALL, 1.0, True), (ALL, 0.15, False)])
def test_the_flow_carries_a_frame_when_the_board_reads_worse(markers, sigma, flow):
    rng = np.random.default_rng(3)
    with Tracker(Camera(K, np.zeros(5), 640, 480), parse_anchors(BOARD), threaded=False) as tr:
        model = tr.anchor_tracker.models[0]
        corners = {i: model.to_world(model.markers[i]) for i in ALL}
        centre = np.concatenate(list(corners.values())).mean(axis=0)
        pose = _look(centre + [0.25, -0.25, 0.35], centre + [0.12, 0.02, 0.0])

        def result(world, draw):
            return SimpleNamespace(raw_world_from_camera=draw[0], anchors_seen=[0], object_points=world,
                                   reprojection_error=draw[1])

        # the last frame: the whole board, sharp (0.15 px)
        whole = np.concatenate([corners[i] for i in ALL])
        last = _draws(whole, pose, 0.15, rng)
        last_error = np.sqrt(np.mean([np.sum((p[:3, 3] - pose[:3, 3]) ** 2) for p, _ in last]))
        now_world = np.concatenate([corners[i] for i in markers])
        said, errors = [], []
        for k, draw in enumerate(_draws(now_world, pose, sigma, rng)):
            memory = AnchorMemory(t=0.0, spread=tr.handover.anchor_spread(result(whole, last[k])), since=0)
            said.append(tr.handover.flow_holds_better(result(now_world, draw), object(), 1 / 30, memory))
            errors.append(np.sum((draw[0][:3, 3] - pose[:3, 3]) ** 2))
    now_error = np.sqrt(np.mean(errors))
    assert (now_error > last_error + FLOW_DRIFT_M) == flow, (now_error, last_error)
    assert np.mean(said) > 0.9 if flow else np.mean(said) < 0.1, np.mean(said)


def test_no_hand_over_without_a_flow_or_a_board():
    with Tracker(Camera(K, np.zeros(5), 640, 480), parse_anchors(BOARD), threaded=False) as tr:
        ar = SimpleNamespace(raw_world_from_camera=np.eye(4), anchors_seen=[0], object_points=np.zeros((16, 3)),
                             reprojection_error=5.0)
        holds_better, memory = tr.handover.flow_holds_better, AnchorMemory(t=0.0, spread=0.0)
        assert holds_better(ar, object(), 1 / 30, memory)      # (the case itself: the flow holds better)
        assert not holds_better(ar, None, 1 / 30, memory)
        assert not holds_better(ar, object(), tr.config.smear_hold_s + 0.1, memory)   # too long ago
        memory.spread = None          # the last pose was not a board's
        assert not holds_better(ar, object(), 1 / 30, memory)
