"""The SLAM tracker does not start its pose from anchors whose edges are smeared.

A 5x3 GridBoard rendered by the synthesiser (still camera, ground truth); the first frames are smeared
here along x with a 6-pixel box kernel (what a pan at ~300 px/s does over a 20 ms exposure), the rest
are sharp. OpenCV's own detector confirms the board is still found in the smeared frames."""

import cv2
import numpy as np
import pytest

from scenes import board_scene_dict, render_sequence
from tracking.tracker import Tracker

SMEARED = 4   # frames


@pytest.fixture(scope="module")
def board_frames():
    keys = [{"t": 0.0, "eye": [0.06, -0.24, 0.42], "target": [0.10, 0.06, 0.0]},
            {"t": 0.5, "eye": [0.065, -0.24, 0.42], "target": [0.10, 0.06, 0.0]}]
    sj = board_scene_dict("still_board", keys, seed=33)
    frames, scene = render_sequence(sj)
    kernel = np.ones((1, 6), np.float32) / 6
    out = [(t, cv2.filter2D(img, -1, kernel) if i < SMEARED else img, gt) for i, (t, img, gt) in enumerate(frames)]
    return out, scene


def _run(frames, scene, start_sharpness):
    errs, states = [], []
    with Tracker(scene.camera, scene.anchors, threaded=False, start_sharpness=start_sharpness) as tr:
        for t, img, gt in frames:
            res = tr.process(img, t)
            states.append(res.state)
            errs.append(np.nan if res.world_from_camera is None
                        else np.linalg.norm(res.world_from_camera[:3, 3] - gt[:3, 3]))
    return np.array(errs), states


def test_smeared_anchors_do_not_start_the_pose(board_frames):
    frames, scene = board_frames
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    for _, img, _ in frames[:SMEARED]:
        _, ids, _ = det.detectMarkers(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
        assert ids is not None and len(ids) >= 10   # the smeared board is still found
    errs, states = _run(frames, scene, 0.2)
    assert states[:SMEARED] == ["lost"] * SMEARED
    assert states[SMEARED] == "marker" and np.isfinite(errs[SMEARED:]).all()
    assert np.nanmax(errs) < 0.002
    # with the check off the smeared frames start it: measured 2.8 mm off, against 0.8 mm at most once sharp
    errs0, states0 = _run(frames, scene, 0.0)
    assert states0[0] == "marker" and np.nanmax(errs0[:SMEARED]) > 2 * np.nanmax(errs)
