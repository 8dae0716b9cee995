"""A hand resting its fingertips on a lone marker's white border (the foremost a little onto the black edge,
near a corner) for seconds while the hand-held camera moves: the pose must stay steady, not only close.

Frames come from the synthesiser with exact ground truth (a slow hand-held orbit, sensor noise, a soft
lens); the fingers are painted here where cv2.projectPoints puts the marker's corners for the true pose,
so the oracles are the true pose and the painted cover, not the code under test. Jitter is the figure
the benchmark reports: the RMS change of the camera's position error between consecutive frames.
"""

import cv2
import numpy as np
import pytest

from tracking.anchors import AnchorTracker
from tracking.anchors.model import build_models
from tracking.poses import invert
from scene_book import book_frames
from scenes import SKIN_BGR, marker_side

COVER_FROM = 24  # frame from which the fingers rest on the border


def true_quad(scene, pose):
    """The marker's corners (4,2 pixels) where cv2.projectPoints puts them for the true world_from_camera."""
    m = build_models(scene.anchors)[0]
    world = m.to_world(m.markers[3])
    cfw = invert(pose)
    rvec, _ = cv2.Rodrigues(cfw[:3, :3])
    px, _ = cv2.projectPoints(world, rvec, cfw[:3, 3], scene.camera.K, scene.camera.dist)
    return px.reshape(4, 2)


def paint_resting_hand(img, quad, side=1):
    """Four rounded fingers from outside side `side` (corners side, side+1) of `quad`, their tips on the
    white margin; the one nearest corner side+1 reaches a third of a cell (of 6 across) onto the black
    border a fifth of the side from that corner. Anti-aliased at 4x, a soft shadow beside them."""
    mid, out, along, length, cell = marker_side(quad, side)
    s = 4
    mask = np.zeros((img.shape[0] * s, img.shape[1] * s), np.uint8)

    def P(p):
        return int(round((p[0] + 0.5) * s - 0.5)), int(round((p[1] + 0.5) * s - 0.5))

    # (position along the side from its middle, fingertip distance outside the black border in cells)
    for off, reach in ((0.3, -0.33), (0.0, 0.45), (-0.3, 0.7), (-0.58, 1.2)):
        tip = mid + along * off * length + out * reach * cell
        width = 0.24 * length
        base = tip + out * width / 2
        cv2.line(mask, P(base), P(base + out * 600), 255, int(width * s), cv2.LINE_AA)
        cv2.circle(mask, P(base), int(width / 2 * s), 255, -1, cv2.LINE_AA)
    mask = cv2.resize(mask, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_AREA)
    al = (mask.astype(np.float64) / 255.0)[..., None]
    shadow = cv2.GaussianBlur(np.roll(mask, (4, 3), axis=(0, 1)), (0, 0), 4).astype(np.float64)[..., None] / 255.0
    shaded = img * (1.0 - 0.35 * shadow * (1 - al))
    return np.clip(shaded * (1 - al) + al * SKIN_BGR * 0.85, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def resting_hand():
    """3 s at ~0.44 m from a lone 5.8 cm marker, the camera orbiting slowly with a hand's shake; from
    frame COVER_FROM on a hand rests its fingertips on the border on the marker's right."""
    frames, scene = book_frames("resting_hand")   # tests/scene_book.py
    out = []
    for i, (t, img, gt) in enumerate(frames):
        if i >= COVER_FROM:
            img = paint_resting_hand(img, true_quad(scene, gt))
        out.append((t, img, gt))
    return out, scene


def _errors(frames, scene):
    """Position errors (N,3, metres) of AnchorTracker's output against the true pose; NaN where none."""
    at = AnchorTracker(scene.anchors, scene.camera)
    errs = []
    for t, img, gt in frames:
        res = at.process(img, t)
        errs.append(np.full(3, np.nan) if res.world_from_camera is None else res.world_from_camera[:3, 3] - gt[:3, 3])
    return np.array(errs)


def _jitter(errs):
    d = np.linalg.norm(np.diff(errs, axis=0), axis=1)
    return float(np.sqrt(np.mean(d[np.isfinite(d)] ** 2)))


def test_the_painted_hand_covers_the_border_and_reaches_the_black_edge(resting_hand):
    """The scene is what it claims: OpenCV's own detector still finds the marker under the hand, and the
    black border under the foremost fingertip is skin, not black (the painted cover, checked on pixels)."""
    frames, scene = resting_hand
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    found = 0
    for t, img, gt in frames[COVER_FROM:]:
        _, ids, _ = det.detectMarkers(img)
        found += ids is not None and 3 in ids.ravel()
    assert found >= 0.8 * len(frames[COVER_FROM:])
    t, img, gt = frames[-1]
    q = true_quad(scene, gt)
    a, b = q[1], q[2]
    cell = np.linalg.norm(b - a) / 6
    out = (a + b) / 2 - q.mean(axis=0)
    out /= np.linalg.norm(out)
    p = (a + b) / 2 + (b - a) * 0.3 - out * 0.15 * cell   # just inside the black border, under the fingertip
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    assert gray[int(round(p[1])), int(round(p[0]))] > 100


def test_fingertips_resting_on_the_border_do_not_make_the_pose_jitter(resting_hand):
    frames, scene = resting_hand
    errs = _errors(frames, scene)
    assert np.isfinite(errs).all()
    held = _jitter(errs[COVER_FROM + 6:])   # the hand in place (a fifth of a second to settle)
    free = _jitter(errs[6:COVER_FROM])      # the same camera motion, no hand
    # measured: 0.64 mm while the fingers rest (0.46 mm before they came), at most 6.6 mm off; before the
    # lone marker's wider edge fit, the filter's orbit mode and the relaxed cover weight: 0.86 mm (0.55 mm
    # before), 11.5 mm off
    assert held < 0.75e-3, (held, free)
    assert np.linalg.norm(errs[COVER_FROM:], axis=1).max() < 0.009
