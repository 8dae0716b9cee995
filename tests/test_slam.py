"""SLAM building blocks against independent references: OpenCV projection, known geometry."""

import cv2
import numpy as np
import pytest

from tracking.camera import Camera
from tracking.poses import invert, make_pose, rotation_angle
from tracking.slam.ba import build_problem, local_bundle_adjustment
from tracking.slam.features import FeatureExtractor, Features, bucket, hamming
from tracking.slam.fusion import PoseBlender, fuse_pose
from tracking.slam.map import Map
from tracking.slam.mapping import triangulate_pair
from tracking.slam.relocalise import relocalise
from tracking.slam.frame_pose import MotionModel, match_by_projection, plausible, refine_pose
from scipy.spatial.transform import Rotation

K = np.array([[520.0, 0, 319.5], [0, 520.0, 239.5], [0, 0, 1]])
CAM = Camera(K, np.zeros(5), 640, 480)


def look(eye, target=(0, 0, 0)):
    """world_from_camera looking from eye at target (OpenCV axes, y roughly down = -world z)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0, 0, -1.0])
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_pose(np.stack([x, y, z], axis=1), eye)


def cv_project(pose, X):
    cw = invert(pose)
    rvec, _ = cv2.Rodrigues(cw[:3, :3])
    uv, _ = cv2.projectPoints(X, rvec, cw[:3, 3], K, None)
    return uv.reshape(-1, 2)


def scene_points(n=300, seed=0):
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(-0.05, 0.05, n)]


def test_refine_pose_recovers_pose_despite_outliers():
    X = scene_points()
    truth = look([0.1, -0.35, 0.4])
    uv = cv_project(truth, X) + np.random.default_rng(1).normal(0, 0.5, (len(X), 2))
    uv[:40] += np.random.default_rng(2).uniform(-60, 60, (40, 2))   # 13 % gross outliers
    start = truth @ make_pose(Rotation.from_rotvec([0.03, -0.02, 0.02]).as_matrix(), [0.02, -0.01, 0.015])
    pose, inl, rms = refine_pose(K, start, X, uv)
    assert np.linalg.norm(pose[:3, 3] - truth[:3, 3]) < 1e-3
    assert np.degrees(rotation_angle(pose[:3, :3].T @ truth[:3, :3])) < 0.1
    assert inl[40:].mean() > 0.97 and inl[:40].mean() < 0.2
    assert rms < 1.0


def test_fuse_pose_keeps_markers_dominant_over_a_biased_map():
    truth = look([0.0, -0.3, 0.4])
    corners = np.array([[-0.05, 0.05, 0], [0.05, 0.05, 0], [0.05, -0.05, 0], [-0.05, -0.05, 0]])
    cuv = cv_project(truth, corners)
    X = scene_points(200)
    muv = cv_project(truth, X)
    biased = X + [0.004, 0.0, 0.0]   # a map shifted 4 mm: markers must hold the pose near the truth
    pose, cin, _, _ = fuse_pose(K, truth, corners, cuv, biased, muv, corner_share=0.5)
    assert cin.all()
    # what the user sees: content on the marker stays on the marker
    fused_px = np.abs(cv_project(pose, corners) - cuv).max()
    map_only, _, _ = refine_pose(K, truth, biased, muv)
    map_px = np.abs(cv_project(map_only, corners) - cuv).max()
    assert map_px > 4.0 and fused_px < 0.3 * map_px


def test_match_by_projection_finds_true_correspondences():
    rng = np.random.default_rng(3)
    X = scene_points(150)
    desc = rng.integers(0, 256, (150, 32), dtype=np.uint8)
    truth = look([0.05, -0.3, 0.45])
    uv = cv_project(truth, X)
    inside = (uv[:, 0] > 0) & (uv[:, 0] < 640) & (uv[:, 1] > 0) & (uv[:, 1] < 480)
    order = rng.permutation(np.nonzero(inside)[0])
    noisy = desc[order].copy()
    flips = rng.integers(0, 32, (len(order), 3))
    for r, c in enumerate(flips):
        noisy[r, c] ^= 1                           # a few bits differ, as between views
    feats = Features(uv[order] + 0.3, uv[order] + 0.3, np.zeros(len(order), int), noisy)
    pred = truth @ make_pose(np.eye(3), [0.004, 0.0, 0.0])
    pi, fi = match_by_projection(K, 640, 480, pred, X, desc, feats, radius=15)
    assert len(pi) >= 0.95 * inside.sum()
    assert np.all(order[fi] == pi)
    assert np.all(hamming(desc[pi], noisy[fi]) <= 3)


def test_bucket_spreads_keypoints_over_the_grid():
    rng = np.random.default_rng(4)
    xy = np.r_[rng.uniform(0, 100, (900, 2)), rng.uniform(0, 640, (100, 2)) * [1, 0.75]]
    resp = np.r_[np.full(900, 10.0), np.full(100, 1.0)]   # a strong cluster in one corner
    keep = bucket(xy, resp, 640, 480, (8, 6), 200)
    assert len(keep) == 200
    cells = {(int(x // 80), int(y // 80)) for x, y in xy[keep]}
    assert len(cells) > 25


def test_feature_extractor_undistorts_keypoints():
    cam = Camera(K, [-0.1, 0.03, 0.0, 0.0, 0.0], 640, 480)
    img = (np.random.default_rng(5).random((480, 640)) * 255).astype(np.uint8)
    img = cv2.GaussianBlur(img, (5, 5), 1.5)
    f = FeatureExtractor(cam, n_features=500).extract(img)
    assert 300 <= len(f) <= 500 and f.desc.shape == (len(f), 32)
    ref = cv2.undistortPoints(f.xy.reshape(-1, 1, 2), K, cam.dist, P=K).reshape(-1, 2)
    assert np.abs(f.und - ref).max() < 1e-3
    # a flat image yields nothing rather than failing
    assert len(FeatureExtractor(cam).extract(np.full((480, 640), 128, np.uint8))) == 0


def _two_keyframes(m: Map, X, poses, noise=0.0, seed=6):
    rng = np.random.default_rng(seed)
    desc = rng.integers(0, 256, (len(X), 32), dtype=np.uint8)
    kfs = []
    for pose in poses:
        uv = cv_project(pose, X) + rng.normal(0, noise, (len(X), 2))
        f = Features(uv, uv, np.zeros(len(X), int), desc.copy())
        kfs.append(m.new_keyframe(0.0, pose, f, np.full(len(X), -1)))
    return kfs, desc


def test_triangulation_between_keyframes_matches_the_points():
    X = scene_points(200)
    m = Map()
    (a, b), _ = _two_keyframes(m, X, [look([-0.05, -0.3, 0.4]), look([0.05, -0.3, 0.4])])
    new = triangulate_pair(K, a, b)
    assert len(new) > 180
    err = [np.linalg.norm(p - X[i]) for p, i, j in new]
    assert all(i == j for _, i, j in new)
    assert max(err) < 1e-6


def test_bundle_adjustment_with_anchor_corners_restores_metric_map():
    X = scene_points(150)
    corners = np.array([[-0.05, 0.05, 0], [0.05, 0.05, 0], [0.05, -0.05, 0], [-0.05, -0.05, 0]])
    poses = [look([x, -0.3, 0.4]) for x in (-0.08, -0.02, 0.04, 0.1)]
    m = Map()
    kfs, desc = _two_keyframes(m, X, poses, noise=0.3)
    rng = np.random.default_rng(7)
    for kf, pose in zip(kfs, poses):
        kf.anchor_world = corners
        kf.anchor_uv = cv_project(pose, corners)   # exact corners: the solver must reach the truth
        kf.pose = pose @ make_pose(Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix(), rng.normal(0, 0.01, 3))
    for i in range(len(X)):
        m.add_point(X[i] + rng.normal(0, 0.01, 3), desc[i], {k.id: i for k in kfs})
    before = np.mean([np.linalg.norm(p.xyz - X[p.id]) for p in m.points.values()])
    assert build_problem(m, kfs[-1].id, window=4) is not None
    assert local_bundle_adjustment(m, kfs[-1].id, K, window=4, max_nfev=30)
    after = np.mean([np.linalg.norm(p.xyz - X[p.id]) for p in m.points.values()])
    assert after < 0.1 * before and after < 2e-3   # 0.3 px keypoint noise: ~1 mm in depth
    for kf, pose in zip(kfs, poses):
        assert np.linalg.norm(kf.pose[:3, 3] - pose[:3, 3]) < 1e-3


def test_relocalise_against_keyframes():
    X = scene_points(300)
    m = Map()
    kfs, desc = _two_keyframes(m, X, [look([0.0, -0.3, 0.4])])
    for i in range(len(X)):
        m.add_point(X[i], desc[i], {kfs[0].id: i})
    truth = look([0.04, -0.28, 0.42], (0.02, 0.0, 0.0))
    uv = cv_project(truth, X)
    keep = np.nonzero((uv[:, 0] > 0) & (uv[:, 0] < 640) & (uv[:, 1] > 0) & (uv[:, 1] < 480))[0]
    f = Features(uv[keep], uv[keep], np.zeros(len(keep), int), desc[keep])
    pose, n = relocalise(m, f, K)
    assert pose is not None and n > 100
    assert np.linalg.norm(pose[:3, 3] - truth[:3, 3]) < 1e-3
    # unrelated descriptors: no pose rather than a wrong one
    junk = Features(uv[keep], uv[keep], np.zeros(len(keep), int),
                    np.random.default_rng(9).integers(0, 256, (len(keep), 32), dtype=np.uint8))
    assert relocalise(m, junk, K)[0] is None


def test_motion_model_and_plausibility():
    mm = MotionModel()
    a = look([0, -0.3, 0.4])
    b = a.copy()
    b[:3, 3] += [0.01, 0, 0]
    mm.update(a, 0.0)
    mm.update(b, 1 / 30)
    p = mm.predict(2 / 30)
    assert np.allclose(p[:3, 3], a[:3, 3] + [0.02, 0, 0], atol=1e-9)
    far = b.copy()
    far[:3, 3] += [0.5, 0, 0]
    assert plausible(p, b, 1 / 30) and not plausible(far, b, 1 / 30)


def test_blender_fades_a_seam_over_its_frames():
    bl = PoseBlender(frames=4)
    est = look([0, -0.3, 0.4])
    prev = est @ make_pose(np.eye(3), [0.01, 0, 0])
    bl.switch(est, prev)
    outs = [bl.apply(est) for _ in range(6)]
    steps = [np.linalg.norm(o[:3, 3] - est[:3, 3]) for o in outs]
    assert steps[0] == pytest.approx(0.01, rel=1e-6)
    assert all(s1 > s2 for s1, s2 in zip(steps[:4], steps[1:4]))
    assert steps[4] == pytest.approx(0.0, abs=1e-12)
    # a real relocation (big step) is not smeared
    bl.switch(est, est @ make_pose(np.eye(3), [0.3, 0, 0]))
    assert np.allclose(bl.apply(est), est)
