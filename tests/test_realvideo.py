"""arapp on real footage (tests/data/realvideo), judged against plain OpenCV in the same frames.

No ground truth exists: the reference is where plain OpenCV detects the anchor's corners
(tracking/evaluation_real.py), and the floor is OpenCV's own PnP fit to them. The goals are issue 25's:
tracked >= 90 % of the frames where OpenCV sees the anchor, median corner error <= twice OpenCV's fit or
0.1 % of the image width (the larger), no frame's corners more than 3 % of the width away.

Also here: a synthetic video of a tag turned by hand in front of a fixed camera (the issue's case, rendered
with cv2.warpPerspective, corners known from cv2.projectPoints): arapp's filtered pose must draw the tag's
corners where they are, without the lag bias a constant-velocity filter has behind an accelerating target.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import realvideo_data as rv
from tracking.anchors import AnchorTracker
from tracking.camera import Camera
from tracking.evaluation_real import (GOAL_TRACKED, GOAL_WORST_WIDTH, OpenCVReference, check_pose, check_run,
                                      measure, summarise)
from tracking.recording.schema import parse_anchors


@pytest.mark.parametrize("slam", [False, True], ids=["no_slam", "slam"])
def test_screen_board_video_meets_the_goals(slam):
    """The hand-held phone around a ChArUco board on a screen (first 150 frames, 320x180, estimated
    camera): measured median 0.23-0.24 px against OpenCV's fit 0.18 px (goal 0.37 px), worst frame 0.4 % of
    the width."""
    s = measure(rv.deepcharuco(limit=150), slam=slam)
    assert s.seen >= 100
    assert s.failures() == [], s
    # a systematic bias would show as a mean offset; measured (+0.01, -0.03) px
    assert np.abs(s.offset).max() < 0.1, s.offset


def test_clipboard_tags_tracked_and_never_far():
    """30 tags on a clipboard, each its own world, every photo on its own (320x240, estimated camera).
    Measured on tags 0-9: 83 frames, all tracked, median 0.40 px against OpenCV's fit 0.15 px, outward
    +0.25 px, offset (-0.03, -0.02) px, worst frame 0.5 % of the width. The median goal (0.32 px, 0.1 % of
    the width) is missed and not asserted: OpenCV's SUBPIX corners sit about 0.25 px inside the tags (the
    outward figure), which alone takes the median past it; see test_subpix_reference_is_inside_the_edges.
    Asserted: within twice the goal."""
    seq = rv.apriltag_clipboard()
    seq.runs = seq.runs[:10]   # tags 0-9 (all 30 in the benchmark)
    s = measure(seq, slam=False)
    assert s.seen >= 60
    assert s.tracked_fraction >= GOAL_TRACKED
    assert s.worst_fraction <= GOAL_WORST_WIDTH, s
    assert s.median <= 2.0 * s.median_goal, s
    assert np.abs(s.offset).max() < 0.1, s.offset


def test_subpix_reference_is_inside_the_edges():
    """On the clipboard photos, OpenCV's CORNER_REFINE_SUBPIX corners are closer to each tag's centre than
    both arapp's and OpenCV's own edge-fitted ones (CORNER_REFINE_APRILTAG, which after its near-constant
    shift of about +0.45 px agrees with arapp on the tags' size): the outward offset of arapp's
    pose against the SUBPIX reference is the reference's bias. Measured on 138 tag views: SUBPIX 0.29 px
    inside APRILTAG's corners, arapp 0.03 px."""
    from tracking.anchors.detect import ArucoDetection
    from tracking.anchors.model import build_models

    seq = rv.apriltag_clipboard()
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)

    def detector(method):
        p = cv2.aruco.DetectorParameters()
        p.cornerRefinementMethod = method
        return cv2.aruco.ArucoDetector(d, p)

    subpix, april = detector(cv2.aruco.CORNER_REFINE_SUBPIX), detector(cv2.aruco.CORNER_REFINE_APRILTAG)
    out_subpix, out_arapp = [], []
    for _, img in seq.frames():
        gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        found = {}
        for name, det in (("subpix", subpix), ("april", april)):
            c, ids, _ = det.detectMarkers(gray)
            found[name] = {} if ids is None else {int(i): q.reshape(4, 2).astype(float) for q, i in zip(c, ids.ravel())}
        for tid, ref in found["april"].items():
            if tid not in found["subpix"] or tid >= len(seq.runs):
                continue
            radial = ref - ref.mean(axis=0)
            radial /= np.linalg.norm(radial, axis=1, keepdims=True)
            out_subpix.append(np.mean(np.sum((found["subpix"][tid] - ref) * radial, axis=1)))
            obs = ArucoDetection(build_models(seq.runs[tid]), seq.camera).detect(gray)
            if obs:
                out_arapp.append(np.mean(np.sum((obs[0].img - ref) * radial, axis=1)))
    assert len(out_subpix) >= 50 and len(out_arapp) >= 50
    assert np.mean(out_subpix) < -0.15
    assert abs(np.mean(out_arapp)) < 0.08


def test_room_photos_tracked():
    """Phone photos of tags on a wall (each tag its own world, every photo on its own, calibrated 816x612):
    on tags 0, 2, 4, 6: 16 frames, all tracked, median 0.49 px against OpenCV's fit 0.13 px (goal: 0.82 px,
    0.1 % of the width), worst 0.2 % of the width."""
    seq = rv.apriltag_room()
    seq.runs = [r for r in seq.runs if r[0].id in (0, 2, 4, 6)]
    s = measure(seq, slam=False)
    assert s.seen >= 12
    assert s.failures() == [], s


# -- the case: a tag turned by hand before a fixed camera, 640x360 ----------------------------------
W, H, F = 640, 360, 520.0
TAG = 0.05
CAMERA = Camera([[F, 0, 321.3], [0, F, 178.2], [0, 0, 1]], None, W, H)


def _tag_video(n: int = 90, seed: int = 3):
    """(t, BGR frame, camera_from_anchor (4x4)) of a DICT_APRILTAG_16h5 tag turned and moved by hand,
    rendered by cv2.warpPerspective at 4x and averaged down (pixel (i, j) covers [i-0.5, i+0.5] x
    [j-0.5, j+0.5] at every scale; corners from cv2.projectPoints), blurred (sigma 0.8 px) and noisy."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_16h5)
    cells, cpx, marg = 6, 40, 80
    tag = cv2.aruco.generateImageMarker(d, 3, cells * cpx, borderBits=1)
    src = np.full((cells * cpx + 2 * marg,) * 2, 255, np.uint8)
    src[marg:marg + cells * cpx, marg:marg + cells * cpx] = tag
    n_src = src.shape[0]
    corners_src = np.array([[0, 0], [n_src, 0], [n_src, n_src], [0, n_src]], float) - 0.5
    # the same corners in the anchor frame (x right, y up, z out of the paper)
    scale = TAG / (cells * cpx)
    corners_anchor = np.c_[(corners_src[:, 0] - (marg - 0.5)) * scale - TAG / 2,
                           TAG / 2 - (corners_src[:, 1] - (marg - 0.5)) * scale, np.zeros(4)]
    rng = np.random.default_rng(seed)
    s = 4
    for k in range(n):
        t = k / 30.0
        rvec = np.array([np.pi + 0.3 * np.sin(2 * np.pi * t / 2.2 + 1), 0.5 * np.sin(2 * np.pi * t / 3.0),
                         0.2 * np.sin(2 * np.pi * t / 4.0)])
        tvec = np.array([0.03 * np.sin(t), 0.02 * np.cos(1.3 * t), 0.35 + 0.05 * np.sin(0.7 * t)])
        px, _ = cv2.projectPoints(corners_anchor, rvec, tvec, CAMERA.K, CAMERA.dist)
        Hm = cv2.getPerspectiveTransform(corners_src.astype(np.float32), ((px.reshape(4, 2) + 0.5) * s - 0.5).astype(np.float32))
        big = cv2.warpPerspective(src.astype(np.float32), Hm, (W * s, H * s), flags=cv2.INTER_LINEAR, borderValue=90)
        img = cv2.GaussianBlur(cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA), (0, 0), 0.8)
        img = np.clip(img + rng.normal(0, 1.5, img.shape), 0, 255).astype(np.uint8)
        cfa = np.eye(4)
        cfa[:3, :3], cfa[:3, 3] = cv2.Rodrigues(rvec)[0], tvec
        yield t, cv2.cvtColor(img, cv2.COLOR_GRAY2BGR), cfa


def test_hand_turned_tag_is_drawn_where_it_is():
    """Filtered poses against the true corners: measured median 0.18 px, p95 0.27 px, mean offset
    (+0.05, +0.02) px (without the hold on the corners, hold_sigmas=0: 0.43 / 0.64 px, offset
    (+0.23, +0.08)); the frame's own solution: median 0.01 px."""
    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_APRILTAG_16h5", "id": 3, "length": TAG}])
    h = TAG / 2
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
    tracker = AnchorTracker(anchors, CAMERA)
    errs, offs = [], []
    for t, img, cfa in _tag_video():
        res = tracker.process(img, t)
        assert res.world_from_camera is not None
        truth, _ = cv2.projectPoints(obj, cv2.Rodrigues(cfa[:3, :3])[0], cfa[:3, 3], CAMERA.K, CAMERA.dist)
        e, off, _ = check_pose(CAMERA, res.world_from_camera, obj, truth.reshape(4, 2))
        errs.append(e)
        offs.append(off)
    errs = np.concatenate(errs)
    assert np.median(errs) < 0.25, np.median(errs)
    assert np.percentile(errs, 95) < 0.4, np.percentile(errs, 95)
    assert np.abs(np.mean(offs, axis=0)).max() < 0.1, np.mean(offs, axis=0)


def test_measurement_sees_a_shifted_pose():
    """The measurement itself: a pose that draws the corners 1.5 px to the right is reported as such."""
    frames = list(_tag_video(n=5))
    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_APRILTAG_16h5", "id": 3, "length": TAG}])

    def poses():
        for i, (_, img, cfa) in enumerate(frames):
            shift = np.eye(4)
            shift[0, 3] = 1.5 / F * cfa[2, 3]   # the tag's centre 1.5 px to the right in the image
            yield i, cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), np.linalg.inv(shift @ cfa)

    s = summarise("shifted", W, check_run(CAMERA, OpenCVReference(anchors[0]), poses()))
    assert s.seen == s.tracked == 5
    assert s.offset[0] == pytest.approx(1.5, abs=0.25) and abs(s.offset[1]) < 0.25
    assert s.median == pytest.approx(1.5, abs=0.3)
