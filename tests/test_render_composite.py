"""The overlay's composite and framebuffer sizing: exact integer "over", and crops of any size giving the
same pixels whatever was drawn before (the framebuffers are resized to the crop between draws)."""

import cv2
import numpy as np
import pytest
import trimesh

from arapp.render import composite
from tracking.poses import make_pose


def expected_over(bg, fg, a):
    """The rule, in exact integer arithmetic: fg + bg * (255 - a) / 255 rounded half up, saturated at 255."""
    bg, fg, a = (np.asarray(x, np.int64) for x in (bg, fg, a))
    return np.minimum(fg + (2 * bg * (255 - a) + 255) // 510, 255)


@pytest.mark.parametrize("fg_rule", ["zero", "half", "equal", "above"])
def test_over_is_exact_for_every_background_and_alpha(fg_rule):
    bg, a = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    fg = {"zero": 0 * a, "half": a // 2, "equal": a, "above": np.minimum(a + 3, 255)}[fg_rule]
    # channels differ so that a BGR/RGB mix-up shows: B gets fg, G gets fg // 2, R gets fg // 3
    crop = np.dstack([fg // 3, fg // 2, fg, a]).astype(np.uint8)  # premultiplied RGBA
    frame = np.dstack([bg, 255 - bg, bg // 2]).astype(np.uint8)
    composite.over_bgr(frame, crop, 0, 0)
    assert np.array_equal(frame[..., 0], expected_over(bg, fg, a))
    assert np.array_equal(frame[..., 1], expected_over(255 - bg, fg // 2, a))
    assert np.array_equal(frame[..., 2], expected_over(bg // 2, fg // 3, a))


@pytest.mark.parametrize("layout", ["contiguous", "bgr_view_of_bgra", "flipped"])
def test_over_writes_into_the_frame_in_place(layout):
    rng = np.random.default_rng(5)
    base = rng.integers(0, 256, (30, 40, 4), dtype=np.uint8)
    frame = {"contiguous": base[..., :3].copy(), "bgr_view_of_bgra": base[..., :3], "flipped": base[::-1, :, :3]}[layout]
    before = frame.copy()
    a = rng.integers(0, 256, (8, 9), dtype=np.uint8)
    a[0] = 0
    crop = np.dstack([(rng.random((8, 9, 3)) * a[..., None]).astype(np.uint8), a])
    composite.over_bgr(frame, crop, 11, 7)
    roi = before[7:15, 11:20]
    want = np.dstack([expected_over(roi[..., c], crop[..., 2 - c], a) for c in range(3)])
    assert np.array_equal(frame[7:15, 11:20], want)
    outside = np.ones(frame.shape[:2], bool)
    outside[7:15, 11:20] = False
    assert np.array_equal(frame[outside], before[outside])
    assert np.array_equal(frame[7, 11:20], before[7, 11:20])  # alpha 0: bit-exact


def silhouette_iou(changed, mesh, T, K, w, h):
    """IoU of the pixels a draw changed with the mesh's triangles projected by cv2.projectPoints and filled."""
    pc = mesh.vertices @ T[:3, :3].T + T[:3, 3]
    px, _ = cv2.projectPoints(pc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, None)
    filled = np.zeros((h, w), np.uint8)
    for t in np.round(px.reshape(-1, 2)[mesh.faces] * 16).astype(np.int32):
        cv2.fillConvexPoly(filled, t, 1, lineType=cv2.LINE_8, shift=4)
    ref = filled > 0
    return (changed & ref).sum() / (changed | ref).sum()


def test_crops_of_any_size_render_the_same_after_others():
    from arapp.render import OverlayRenderer

    K = np.array([[600.0, 0, 321.5], [0, 590.0, 238.0], [0, 0, 1]])
    mesh = trimesh.creation.icosphere(3, radius=0.05)
    R = cv2.Rodrigues(np.array([0.3, -0.4, 0.2]))[0]
    far, near = make_pose(R, np.array([0.04, 0.02, 1.6])), make_pose(R, np.array([0.0, 0.0, 0.12]))
    frame = np.full((480, 640, 3), 255, np.uint8)  # the shading never reaches pure white: every drawn pixel changes
    with OverlayRenderer(K, None, 640, 480) as r:
        seq = [r.draw(frame, mesh, T) for T in (far, near, far)]  # small crop, near-full-frame crop, small
    for T, got in zip((far, near), seq):
        with OverlayRenderer(K, None, 640, 480) as fresh:
            assert np.array_equal(got, fresh.draw(frame, mesh, T))
        changed = (got != frame).any(axis=2)
        assert silhouette_iou(changed, mesh, T, K, 640, 480) > 0.97
    assert np.array_equal(seq[0], seq[2])
    assert (seq[1] != frame).any(axis=2).mean() > 0.5  # the near one covers most of the frame
