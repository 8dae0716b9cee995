"""Optical-flow tracking (tracking.slam.flow): rays cut with the anchors' plane, and the pose from
points followed between two motion-blurred views of a textured plane. References: cv2.projectPoints
and the true poses the views were made with."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tracking.camera import Camera
from tracking.poses import invert, make_pose, rotation_angle
from tracking.anchors.edges import edge_sharpness
from tracking.slam.flow import follow, lift_to_plane, seed_on_plane

K = np.array([[540.0, 0, 319.5], [0, 540.0, 239.5], [0, 0, 1]])
DIST = np.array([-0.08, 0.04, 0.0005, -0.0005, 0.0])
CAM = Camera(K, DIST, 640, 480)
PLAIN = Camera(K, np.zeros(5), 640, 480)
PX = 0.0005        # metres per texture pixel: a 1.2 m x 0.9 m desk
ORIGIN = (-0.6, -0.45)


def look(eye, target=(0.0, 0.0, 0.0)):
    """world_from_camera looking from eye at target (OpenCV axes, image x level with the plane)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross([0, 0, 1.0], z)
    x /= np.linalg.norm(x)
    return make_pose(np.stack([x, np.cross(z, x), z], axis=1), eye)


def cv_project(cam, pose, X):
    cw = invert(pose)
    rvec, _ = cv2.Rodrigues(cw[:3, :3])
    uv, _ = cv2.projectPoints(np.asarray(X, float), rvec, cw[:3, 3], cam.K, cam.dist)
    return uv.reshape(-1, 2)


@pytest.fixture(scope="module")
def texture():
    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(rng.integers(0, 256, (1800, 2400), dtype=np.uint8), (0, 0), 3)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
    for _ in range(400):   # blobs and strokes, a desk's worth of corners
        c = tuple(int(v) for v in rng.integers(0, [2400, 1800]))
        cv2.circle(img, c, int(rng.integers(6, 30)), int(rng.integers(0, 256)), -1)
        cv2.line(img, c, tuple(int(v) for v in rng.integers(0, [2400, 1800])), int(rng.integers(0, 256)), 3)
    return img


def view(texture, pose, velocity=None, samples=7):
    """Undistorted-camera image of the textured plane z = 0 seen from `pose`; with `velocity` (a 4x4
    motion per frame) averaged over the exposure, i.e. motion-blurred."""
    A = np.array([[PX, 0, ORIGIN[0]], [0, PX, ORIGIN[1]], [0, 0, 1]])   # texture pixel -> plane x, y
    poses = [pose] if velocity is None else [
        pose @ make_pose(Rotation.from_rotvec(Rotation.from_matrix(velocity[:3, :3]).as_rotvec() * s).as_matrix(),
                         velocity[:3, 3] * s) for s in np.linspace(-0.4, 0.4, samples)]
    acc = np.zeros((480, 640))
    for p in poses:
        cw = invert(p)
        H = K @ np.c_[cw[:3, 0], cw[:3, 1], cw[:3, 3]] @ A
        acc += cv2.warpPerspective(texture, H, (640, 480), flags=cv2.INTER_LINEAR).astype(float)
    return np.clip(acc / len(poses), 0, 255).astype(np.uint8)


def test_lift_to_plane_inverts_the_projection_with_distortion():
    pose = look([0.1, -0.3, 0.45])
    rng = np.random.default_rng(0)
    X = np.c_[rng.uniform(-0.2, 0.2, (200, 2)), np.zeros(200)]
    uv = cv_project(CAM, pose, X)
    inside = (uv[:, 0] > 0) & (uv[:, 0] < 640) & (uv[:, 1] > 0) & (uv[:, 1] < 480)
    lifted, ok = lift_to_plane(CAM, pose, uv[inside])
    assert ok.all() and inside.sum() > 100
    assert np.abs(lifted - X[inside]).max() < 1e-6
    # a camera looking level: of a pixel above the horizon and one below, only the one below meets
    # the plane (in front of the camera)
    level = look([0, -0.5, 0.1], [0, 0.5, 0.1])
    px = np.array([[320.0, 10.0], [320.0, 470.0]])
    lifted2, ok2 = lift_to_plane(CAM, level, px)
    down = (level[:3, :3] @ CAM.unproject(px).T)[2] < 0
    assert ok2.tolist() == down.tolist() and ok2.sum() == 1
    assert np.abs(cv_project(CAM, level, lifted2[ok2]) - px[ok2]).max() < 1e-6


def test_follow_recovers_the_pose_across_a_blurred_pan(texture):
    a = look([0.05, -0.25, 0.42], [0.0, 0.0, 0.0])
    # a fast pan: 3 degrees and 6 mm in one frame (about 30 px of image motion), blurred like a
    # 0.8-frame exposure
    step = make_pose(Rotation.from_rotvec([0.0, np.radians(3.0), 0.0]).as_matrix(), [0.006, 0.0, 0.0])
    b = a @ step
    img_a, img_b = view(texture, a, step), view(texture, b, step)
    tracks = seed_on_plane(PLAIN, img_a, a, n=300)
    assert len(tracks) >= 250
    assert np.abs(tracks.X[:, 2]).max() < 1e-9
    got = follow(PLAIN, tracks, img_b, predicted=a @ step @ make_pose(np.eye(3), [0.003, 0.002, 0.0]))
    assert got is not None
    pose, moved = got
    assert np.linalg.norm(pose[:3, 3] - b[:3, 3]) < 0.002
    assert np.degrees(rotation_angle(pose[:3, :3].T @ b[:3, :3])) < 0.1
    # the followed points sit where the true pose projects their world points
    assert len(moved) >= 0.8 * len(tracks)
    assert np.median(np.linalg.norm(moved.xy - cv_project(PLAIN, b, moved.X), axis=1)) < 0.5
    assert 20 < np.linalg.norm(moved.image_motion()) < 45


def test_follow_refuses_an_unrelated_image(texture):
    a = look([0.05, -0.25, 0.42])
    tracks = seed_on_plane(PLAIN, view(texture, a), a, n=300)
    noise = np.random.default_rng(1).integers(0, 256, (480, 640), dtype=np.uint8)
    assert follow(PLAIN, tracks, noise, predicted=a) is None


def test_edge_sharpness_sees_motion_blur_along_its_direction(texture):
    sharp = texture[400:880, 400:1040].copy()
    kernel = np.zeros((1, 12), np.float32)
    kernel[0, :] = 1.0 / 12                        # 12 px of horizontal motion during the exposure
    smeared = cv2.filter2D(sharp, -1, kernel, borderType=cv2.BORDER_REFLECT)
    box = np.array([[100.0, 100.0], [500.0, 380.0]])
    across = edge_sharpness(smeared, box, np.array([1.0, 0.0]))
    along = edge_sharpness(smeared, box, np.array([0.0, 1.0]))
    assert edge_sharpness(sharp, box, np.array([1.0, 0.0])) > 0.2
    assert across < 0.1                            # smeared over 12 px: about 1/12
    assert along > 2 * across                      # edges along the motion stay sharp
    flat = np.full((480, 640), 128, np.uint8)
    assert np.isnan(edge_sharpness(flat, box, np.array([1.0, 0.0])))


def rolling_view(texture, pose_at, t, readout):
    """Image of the textured plane from a camera whose rows are read out over `readout` seconds: row y
    seen from the pose at t + readout * ((y + 0.5) / 480 - 0.5) (`pose_at(t)` gives world_from_camera)."""
    A = np.array([[PX, 0, ORIGIN[0]], [0, PX, ORIGIN[1]], [0, 0, 1]])   # texture pixel -> plane x, y
    out = np.zeros((480, 640), np.uint8)
    for y in range(480):
        cw = invert(pose_at(t + readout * ((y + 0.5) / 480 - 0.5)))
        row_from_image = np.array([[1.0, 0, 0], [0, 1, -y], [0, 0, 1]])   # this row only: cheap
        H = row_from_image @ K @ np.c_[cw[:3, 0], cw[:3, 1], cw[:3, 3]] @ A
        out[y] = cv2.warpPerspective(texture, H, (640, 1), flags=cv2.INTER_LINEAR)[0]
    return out


def test_follow_holds_a_rolling_shutter_pan_through_its_turn(texture):
    # a hand-held pan swinging +-4 degrees at 1.5 Hz (up to 38 deg/s, turning round at t = 1/6 s), read
    # out over 30 ms: the top and bottom rows see the scene up to 1.1 degrees apart, and the shear
    # changes sign at the turn. Points followed through it must give the pose at the centre row's time.
    readout, dt, amp, hz = 0.03, 1 / 30, np.radians(4.0), 1.5
    a = look([0.05, -0.25, 0.42])

    def pose_at(t):
        angle = amp * np.sin(2 * np.pi * hz * t)
        return a @ make_pose(Rotation.from_rotvec([0.0, angle, 0.0]).as_matrix(), [0.03 * angle, 0.0, 0.0])

    times = [0.05 + k * dt for k in range(8)]     # through the turn at t = 1/6 s
    images = [rolling_view(texture, pose_at, t, readout) for t in times]
    errors = {}
    for name, cam in (("readout known", Camera(K, np.zeros(5), 640, 480, readout)), ("readout unknown", PLAIN)):
        # new seeds have no motion of their own yet: the motion to the next frame's pose gives it
        tracks = seed_on_plane(cam, images[0], pose_at(times[0]), n=300, later=(pose_at(times[1]), dt))
        worst = 0.0
        for t, img in zip(times[1:], images[1:]):
            got = follow(cam, tracks, img, predicted=pose_at(t), dt=dt)
            assert got is not None
            pose, tracks = got
            worst = max(worst, np.linalg.norm(pose[:3, 3] - pose_at(t)[:3, 3]))
        errors[name] = worst
        if cam is not PLAIN:
            # the followed points carry their image velocity (pixels/s) on
            true = (cam.project_world(tracks.X, pose_at(times[-1] + 1e-4))
                    - cam.project_world(tracks.X, pose_at(times[-1] - 1e-4))) / 2e-4
            assert np.median(np.linalg.norm(tracks.velocity - true, axis=1)) < 0.25 * np.median(np.linalg.norm(true, axis=1))
    # measured: 2.1 mm with the readout, 23 mm without (each frame's shear read as a pose change)
    assert errors["readout known"] < 0.004
    assert errors["readout unknown"] > 5 * errors["readout known"]
