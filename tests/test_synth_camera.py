"""The synthesiser's webcam effects, each against a rule written here (not the renderer's own formulas):
shot + read noise, auto-exposure, white-balance drift, rolling shutter, defocus, motion blur along the
true motion, vignetting, chroma subsampling, JPEG rate control, and the hand on a marker's border."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tracking.errors import SessionError
from tracking.poses import transform_points
from tracking.synth.camera_effects import (chroma_subsample_422, defocus, frame_jpeg_quality, jpeg_roundtrip,
                                           sensor_noise)
from tracking.synth.patterns import anchor_corners, pattern_for
from tracking.synth.presets import BOARD
from tracking.synth.renderer import DeskRenderer
from tracking.synth.scene import parse_scene

MARKER = {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 5, "length": 0.06}


def scene(effects=None, anchors=None, trajectory=None, **kw):
    """A small scene with no effects but the given ones (optics_blur off unless asked for)."""
    fx = {"optics_blur": 0.0}
    fx.update(effects or {})
    data = {"anchors": anchors or [MARKER], "fps": 30, "duration": 2.0, "seed": 9,
            "trajectory": trajectory or {"kind": "static", "azimuth": -95, "distance": 0.4, "elevation": 62},
            "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": [-0.05, 0.02, 0.0, 0.0, 0.0]},
            "desk": {"size": [1.2, 1.0], "ppm": 1500, "seed": 4}, "effects": fx, "supersample": 2}
    data.update(kw)
    return parse_scene(data)


def aruco(img, dictionary=cv2.aruco.DICT_4X4_50):
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    p.relativeCornerRefinmentWinSize = 0.6
    p.cornerRefinementMinAccuracy = 0.001
    p.cornerRefinementMaxIterations = 100
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary), p)
    corners, ids, _ = det.detectMarkers(img)
    return {} if ids is None else {int(i): c.reshape(4, 2) for c, i in zip(corners, ids.ravel())}


# -- sensor ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("gain", [1.0, 2.0])
def test_noise_variance_grows_with_brightness_as_shot_plus_read_noise(gain):
    """Rule: variance (levels^2) = gain * L * 255 / full_well + (gain * read_noise)^2."""
    fw, read = 2500.0, 2.0
    rng = np.random.default_rng(0)
    for level in (10.0, 60.0, 130.0, 220.0):
        flat = np.full((300, 300, 3), level, np.float32)
        var = float(np.var(sensor_noise(flat, rng, fw, read, gain=gain) - level))
        rule = gain * level * 255.0 / fw + (gain * read) ** 2
        assert var == pytest.approx(rule, rel=0.03), (level, var, rule)


def test_rendered_noise_follows_the_rule_on_paper_and_ink():
    """Two renders of a still camera differ only by noise: var(difference) / 2 = rule + 1/12 (rounding)."""
    fw, read = 2000.0, 1.5
    r = DeskRenderer(scene({"sensor": {"full_well": fw, "read_noise": read}}))
    clean = DeskRenderer(scene()).render(0)[0].astype(np.float32)
    a, b = (r.render(0)[0].astype(np.float32) for _ in range(2))  # rng moves on between the two
    for lo, hi in ((20, 40), (200, 240)):  # the marker's ink and its paper
        sel = (clean >= lo) & (clean < hi)
        level = float(clean[sel].mean())
        var = float(np.var((a - b)[sel])) / 2
        rule = level * 255.0 / fw + read ** 2 + 1.0 / 12
        assert sel.sum() > 2000 and var == pytest.approx(rule, rel=0.1), (lo, var, rule)


# -- exposure and colour ----------------------------------------------------------------------------------
def test_auto_exposure_walks_toward_its_target_one_frame_late():
    """Rule: g_0 = initial; g_{n+1} = g_n * (target / (L * g_n)) ** speed, L the frame's luma at gain 1."""
    target, speed, g = 70.0, 0.3, 1.6
    r = DeskRenderer(scene({"auto_exposure": {"target": target, "speed": speed, "initial_gain": g}}))
    ref = DeskRenderer(scene()).render(0)[0].astype(np.float32)
    luma = float(cv2.cvtColor(ref.astype(np.uint8), cv2.COLOR_BGR2GRAY).mean())
    dev = []
    for n in range(8):
        img = r.render(n)[0].astype(np.float32)
        expected = np.clip(ref * g, 0, 255)
        assert np.abs(img - expected).mean() < 1.0, (n, g, np.abs(img - expected).mean())
        dev.append(abs(luma * g - target))
        g = g * (target / (luma * g)) ** speed
    assert dev[-1] < 0.3 * dev[0]


def test_white_balance_drifts_blue_against_red():
    """Rule: at t the (B, G, R) gains are (1 + a sin(2 pi t / P), 1, 1 - a sin(2 pi t / P))."""
    a, period = 0.1, 2.0
    r = DeskRenderer(scene({"white_balance": {"amplitude": a, "period": period}}))
    ref = DeskRenderer(scene())
    for i in (0, 15, 45):  # t = 0, 0.5 s (sin = 1), 1.5 s (sin = -1)
        img, _, t = r.render(i)
        clean = ref.render(i)[0].astype(np.float32)
        s = a * math.sin(2 * math.pi * t / period)
        sel = (clean > 40).all(axis=2) & (clean < 200).all(axis=2)
        ratios = [float(np.median(img[..., c][sel] / clean[..., c][sel])) for c in range(3)]
        np.testing.assert_allclose(ratios, [1 + s, 1.0, 1 - s], atol=0.01)


def test_vignetting_darkens_as_the_square_of_the_radius():
    """Rule: factor 1 - v * r^2 / r_corner^2 about the principal point."""
    v = 0.3
    sc = scene({"vignette": v})
    img = DeskRenderer(sc).render(0)[0].astype(np.float32)
    clean = DeskRenderer(scene()).render(0)[0].astype(np.float32)
    cam = sc.camera
    yy, xx = np.mgrid[0:cam.height, 0:cam.width]
    rule = 1 - v * ((xx - cam.cx) ** 2 + (yy - cam.cy) ** 2) / (cam.cx ** 2 + cam.cy ** 2)
    sel = (clean > 60).all(axis=2)
    ratio = img[sel] / clean[sel]
    assert np.abs(ratio - rule[sel][:, None]).max() < 0.02
    assert rule.min() == pytest.approx(1 - v, abs=0.01)


# -- optics ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("radius", [1.0, 2.5])
def test_defocus_is_a_pillbox(radius):
    """A step through defocus follows the analytic edge-spread of a uniform disc of that radius."""
    img = np.zeros((41, 41, 3), np.float32)
    img[:, 20:] = 100.0  # the step lies on the boundary between columns 19 and 20
    out = defocus(img, radius)[20, :, 0]
    x = np.arange(41) - 19.5  # pixel centres relative to the step
    xc = np.clip(x, -radius, radius)
    # area of the disc on the bright side of the step, seen from a pixel centre at x
    esf = 0.5 + (xc * np.sqrt(radius ** 2 - xc ** 2) + radius ** 2 * np.arcsin(xc / radius)) / (math.pi * radius ** 2)
    np.testing.assert_allclose(out, 100 * esf, atol=1.0)


def test_defocus_hunts_around_its_radius():
    r = DeskRenderer(scene({"defocus": {"radius": 1.0, "swing": 0.5, "period": 2.0}}))
    assert r.defocus_radius(0.5) == pytest.approx(1.5) and r.defocus_radius(1.5) == pytest.approx(0.5)


# -- motion -----------------------------------------------------------------------------------------------
PAN = {"kind": "pan", "azimuth": -95, "distance": 0.45, "elevation": 62, "pan_deg": 20, "cycles": 1.0}


def true_pixel(renderer, world_point, t, readout):
    """Where a world point appears with a rolling shutter: the pose at the time of the row it lands on
    (row y exposed at t + readout * ((y + 0.5) / H - 0.5)), found by fixed-point iteration."""
    cam = renderer.scene.camera
    px = cam.project_world(world_point, renderer.world_from_camera(t))
    for _ in range(5):
        tr = t + readout * ((px[1] + 0.5) / cam.height - 0.5)
        px = cam.project_world(world_point, renderer.world_from_camera(tr))
    return px


def test_rolling_shutter_rows_see_the_trajectory_at_their_own_time():
    readout = 0.03
    sc = scene({"rolling_shutter": readout}, anchors=[BOARD], trajectory=PAN)
    r = DeskRenderer(sc)
    a = sc.anchors[0]
    world = transform_points(a.world_from_anchor, anchor_corners(a))
    i = 30  # t = 1 s, mid-sweep: the fastest pan
    img, pose, t = r.render(i)
    found = aruco(img)
    assert len(found) >= 10
    rs_err, gs_err, flipped = [], [], []
    for mid, c in found.items():
        k = a.marker_ids().index(mid)
        for j in range(4):
            rs_err.append(np.linalg.norm(c[j] - true_pixel(r, world[k, j], t, readout)))
            gs_err.append(np.linalg.norm(c[j] - sc.camera.project_world(world[k, j], pose)))
            flipped.append(np.linalg.norm(c[j] - true_pixel(r, world[k, j], t, -readout)))
    # (a global-shutter render of this frame puts detections 0.25 px median, 0.63 px max off)
    assert np.median(rs_err) < 0.4 and max(rs_err) < 1.0, (np.median(rs_err), max(rs_err))
    # the skew is there: a global-shutter projection, or rows read bottom to top, miss by pixels
    assert np.median(gs_err) > 0.8 and np.median(flipped) > 1.5, (np.median(gs_err), np.median(flipped))


def test_motion_blur_smears_along_the_projected_motion():
    """Gradients along the image motion of the board are wiped out; across it they survive."""
    sharp = DeskRenderer(scene(anchors=[BOARD], trajectory=PAN))
    blurred = DeskRenderer(scene({"motion_blur": 1.0, "blur_samples": 9}, anchors=[BOARD], trajectory=PAN))
    i = 30  # the fastest pan
    img_b, pose, t = blurred.render(i)
    img_s = sharp.render(i)[0]
    a = sharp.scene.anchors[0]
    centre = transform_points(a.world_from_anchor, anchor_corners(a)).reshape(-1, 3).mean(axis=0)
    cam = sharp.scene.camera
    dt = 0.5 / 30
    motion = (cam.project_world(centre, sharp.world_from_camera(t + dt))
              - cam.project_world(centre, sharp.world_from_camera(t - dt)))
    px = cam.project_world(centre, pose).astype(int)
    roi = (slice(px[1] - 60, px[1] + 60), slice(px[0] - 80, px[0] + 80))

    def grads(img):
        g = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float32)[roi]
        return cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1)

    (bx, by), (sx, sy) = grads(img_b), grads(img_s)
    angles = np.radians(np.arange(0, 180, 2))
    kept = [np.sum((np.cos(a_) * bx + np.sin(a_) * by) ** 2) / np.sum((np.cos(a_) * sx + np.sin(a_) * sy) ** 2)
            for a_ in angles]
    worst = np.degrees(angles[int(np.argmin(kept))])
    along = math.degrees(math.atan2(motion[1], motion[0])) % 180
    diff = min(abs(worst - along), 180 - abs(worst - along))
    assert np.linalg.norm(motion) > 5 and diff < 12, (worst, along, motion)
    assert min(kept) < 0.5 * max(kept)


# -- link and codec ------------------------------------------------------------------------------------------
def test_chroma_422_pairs_share_colour_and_keep_luma():
    rng = np.random.default_rng(3)
    img = rng.integers(60, 190, (32, 64, 3)).astype(np.uint8)  # in gamut after chroma averaging
    out = cv2.cvtColor(chroma_subsample_422(img), cv2.COLOR_BGR2YCrCb).astype(int)
    ycc = cv2.cvtColor(img, cv2.COLOR_BGR2YCrCb).astype(int)
    assert np.abs(out[:, 0::2, 1:] - out[:, 1::2, 1:]).max() <= 3  # BGR rounding in between
    pair_mean = (ycc[:, 0::2, 1:] + ycc[:, 1::2, 1:]) / 2
    assert np.abs(out[:, 0::2, 1:] - pair_mean).mean() < 1.5
    assert np.abs(out[..., 0] - ycc[..., 0]).mean() < 2.0


def test_jpeg_quality_varies_per_frame_within_its_range_and_leaves_blocks():
    rng = np.random.default_rng(1)
    qs = [frame_jpeg_quality([40, 80], rng) for _ in range(200)]
    assert min(qs) >= 40 and max(qs) <= 80 and len(set(qs)) > 20
    assert frame_jpeg_quality(75, rng) == 75 and frame_jpeg_quality(None, rng) is None
    yy, xx = np.mgrid[0:128, 0:128].astype(np.float32)
    smooth = (100 + 60 * np.sin(xx / 9.0) * np.cos(yy / 13.0) + rng.normal(0, 4, xx.shape)).astype(np.uint8)
    out = jpeg_roundtrip(cv2.merge([smooth] * 3), 15)[..., 1].astype(float)
    step = np.abs(np.diff(out, axis=1)).mean(axis=0)  # column-to-column jumps
    across = step[7::8].mean()  # jumps across 8x8 block boundaries
    inside = np.delete(step, np.s_[7::8]).mean()
    assert across > 1.3 * inside


# -- the hand ---------------------------------------------------------------------------------------------
def skin(img):
    """Kovac et al.'s RGB skin rule (uniform daylight)."""
    b, g, r = (img[..., k].astype(int) for k in range(3))
    return ((r > 95) & (g > 40) & (b > 20) & (np.max(img, axis=2).astype(int) - np.min(img, axis=2) > 15)
            & (np.abs(r - g) > 15) & (r > g) & (r > b))


def region_masks(sc, pose):
    """(white border, black square) masks from projected geometry, each 2 px inside its edges."""
    a = sc.anchors[0]
    pat = pattern_for(a)
    m, L = pat.margin, a.length

    def poly(h):
        pts = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)
        px = sc.camera.project_world(transform_points(a.world_from_anchor, pts), pose)
        mask = np.zeros((sc.camera.height, sc.camera.width), np.uint8)
        cv2.fillPoly(mask, [np.round(px).astype(np.int32)], 1)
        return mask.astype(bool)

    paper, black = poly(L / 2 + m), poly(L / 2)
    k = np.ones((5, 5), np.uint8)  # 2 px off every edge: edge pixels mix paper with desk or ink
    border = cv2.erode(paper.astype(np.uint8), k).astype(bool) & ~cv2.dilate(black.astype(np.uint8), k).astype(bool)
    inner = cv2.erode(black.astype(np.uint8), k).astype(bool)
    return border, inner


def test_hand_enters_the_white_border_and_leaves():
    margin = 0.25 * MARKER["length"]
    occ = {"start": 0.2, "end": 1.8, "ramp": 0.5, "style": "border", "approach_deg": 10, "reach": 0.6 * margin,
           "offset": -0.012}
    sc = scene({"occluder": occ})
    r = DeskRenderer(sc)
    seen = {}
    for i in (3, 15, 30, 45, 57):  # t = 0.1 (before), 0.5, 1.0 (in place), 1.5, 1.9 (gone)
        img, pose, t = r.render(i)
        border, inner = region_masks(sc, pose)
        s = skin(img)
        seen[i] = (int((s & border).sum()), int((s & inner).sum()))
    assert seen[3] == (0, 0) and seen[57] == (0, 0)
    assert seen[30][0] > 30 and seen[30][1] == 0  # (74 px measured) fingertips on the white border, none on the black
    assert seen[15][0] <= seen[30][0]
    # rounded fingertips: the outline around the foremost tip is a half circle of the finger's radius
    from tracking.synth.hand import FINGER_WIDTH, hand_polygons
    corners = np.array([[-0.045, -0.045], [0.045, -0.045], [0.045, 0.045], [-0.045, 0.045]])
    finger = hand_polygons(corners, 0.0, 0.01, 1.0)[1][:, :2]  # the middle finger, hand coming from +x
    r = FINGER_WIDTH / 2
    tip_x = 0.045 - 0.01  # reach: the fingertip 1 cm past the sheet's edge (x = +0.045) onto the sheet
    arc = finger[finger[:, 0] < tip_x + r - 1e-9]
    centre = np.array([tip_x + r, arc[:, 1].mean()])
    assert len(arc) >= 8
    np.testing.assert_allclose(np.linalg.norm(arc - centre, axis=1), r, atol=1e-9)
    assert arc[:, 0].min() == pytest.approx(tip_x, abs=0.02 * r)


def test_effect_blocks_are_checked():
    with pytest.raises(SessionError, match="auto_exposure.tagret"):
        scene({"auto_exposure": {"tagret": 100}})
    with pytest.raises(SessionError, match="rolling_shutter"):
        scene({"rolling_shutter": -0.01})
    with pytest.raises(SessionError, match="occluder.style"):
        scene({"occluder": {"start": 0, "end": 1, "style": "glove"}})
