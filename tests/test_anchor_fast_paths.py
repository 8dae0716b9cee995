"""The anchor tracker's faster computations give numpy's / OpenCV's own numbers (oracle: the plain calls)."""

import cv2
import numpy as np

from tracking.anchors.edges import _level_percentiles, _top_percentile, edge_sharpness


def test_percentiles_from_a_histogram_equal_numpys():
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 7, 50, 1001, 13520):
        img = rng.integers(0, 256, size=(1, n), dtype=np.uint8)
        if n > 10:
            img[0, : n // 3] = 17   # long runs of one level, as a marker's black and white give
        got = _level_percentiles(img, (0, 2, 50, 98, 100))
        want = np.percentile(img.astype(np.float32), [0, 2, 50, 98, 100])
        assert np.array_equal(np.array(got), want), (n, got, want)


def test_top_percentile_equals_numpys():
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 99, 100, 101, 2047, 2048, 5000, 40001):
        v = np.abs(rng.normal(size=n)) * 40.0
        if n == 40001:
            v[: n // 2] = np.round(v[: n // 2])   # ties at the sample's bound
        for q in (0, 1, 50, 97, 99, 99.9, 100):
            assert _top_percentile(v, q) == np.percentile(v, q), (n, q)
    # large values only where the strided sample looks: its bound leaves out too many, the whole array is used
    v = np.zeros(4096)
    v[::16] = np.arange(256) + 1.0
    assert _top_percentile(v, 99) == np.percentile(v, 99)


def _edge_sharpness_plain(gray, pixels, direction):
    """The rule as first written: float32 box, Sobel / 8, np.percentile."""
    h, w = gray.shape[:2]
    lo = np.maximum(np.floor(pixels.min(axis=0)).astype(int) - 4, 0)
    hi = np.minimum(np.ceil(pixels.max(axis=0)).astype(int) + 5, [w, h])
    if (hi - lo).min() < 8 or not np.linalg.norm(direction) > 0:
        return float("nan")
    roi = gray[lo[1]:hi[1], lo[0]:hi[0]].astype(np.float32)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    gx = cv2.Sobel(roi, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(roi, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    lo_i, hi_i = np.percentile(roi, [2, 98])
    if hi_i - lo_i < 10:
        return float("nan")
    return float(np.percentile(np.abs(gx * d[0] + gy * d[1]), 99) / (hi_i - lo_i))


def test_edge_sharpness_equals_the_plain_computation():
    rng = np.random.default_rng(5)
    img = np.full((240, 320), 200, np.uint8)
    cv2.rectangle(img, (100, 60), (180, 140), 30, -1)
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    img = np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)
    for k in range(20):
        pts = np.array([[100, 60], [180, 60], [180, 140], [100, 140]], float) + rng.uniform(-20, 20, (4, 2))
        d = rng.normal(size=2)
        a, b = edge_sharpness(img, pts, d), _edge_sharpness_plain(img, pts, d)
        assert a == b, (k, a, b)
    flat = np.full((100, 100), 90, np.uint8)
    assert np.isnan(edge_sharpness(flat, np.array([[10.0, 10.0], [60.0, 60.0]]), np.array([1.0, 0.0])))


def test_median_and_row_norms_equal_numpys():
    from tracking.anchors.numeric import median, row_norms

    rng = np.random.default_rng(6)
    for n in list(range(1, 12)) + [48, 101]:
        for k in range(6):
            v = rng.normal(size=n) * 10
            if k == 1:
                v = np.round(v)            # ties
            if k == 2 and n > 2:
                v[1] = np.nan
            a, b = np.median(v), median(v)
            assert (a == b or (np.isnan(a) and np.isnan(b))) and type(a) is type(b), (n, k, a, b)
            w = rng.normal(size=(n, 2))
            if k == 3:
                w[0, 1] = np.nan
            assert np.array_equal(np.median(w, axis=0), median(w), equal_nan=True), (n, k)
            assert np.array_equal(np.linalg.norm(w, axis=1), row_norms(w), equal_nan=True), (n, k)


def test_rotation_angle_equals_the_trace_formula():
    from tracking.poses import rotation_angle

    rng = np.random.default_rng(7)
    for k in range(2000):
        R = cv2.Rodrigues(rng.normal(size=3) * 10.0 ** rng.uniform(-9, 0.5))[0]
        want = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
        assert rotation_angle(R) == want, k


def test_tracker_caches_follow_their_inputs():
    """The tracker's remembered computations (marker world corners between frames, projections within a
    frame) give what computing afresh gives, also after the input changed (oracle: the plain calls)."""
    from scenes import bundled_recording

    from tracking.anchors.tracker import AnchorTracker

    frames, session = bundled_recording("board_orbit", slice(0, 3))
    at = AnchorTracker(session.anchors, session.camera)
    for t, image, _ in frames:
        res = at.process(image, t)
    assert res.raw_world_from_camera is not None
    det = at.aruco
    model = det.models[0]
    keys = [(model.index, mid) for mid in list(model.markers)[:3]]
    by_index = {m.index: m for m in det.models}
    first = det._world_corners(by_index, keys)
    assert all(np.array_equal(w, model.to_world(model.markers[mid])) for w, (_, mid) in zip(first, keys))
    # the anchor placed elsewhere: its markers' world corners move with it
    moved = np.array(model.spec.world_from_anchor, dtype=float)
    moved[:3, 3] += [0.01, -0.02, 0.03]
    model.spec.world_from_anchor = moved
    again = det._world_corners(by_index, keys)
    assert all(np.array_equal(w, model.to_world(model.markers[mid])) for w, (_, mid) in zip(again, keys))
    assert not np.array_equal(first[0], again[0])
    # projections: another pose, or other points with the same values, are not answered from the memo
    world = np.array(res.object_points, dtype=float)
    pose = res.raw_world_from_camera
    a = at._project_world(world, pose)
    assert np.array_equal(a, session.camera.project_world(world, pose))
    other = pose.copy()
    other[0, 3] += 0.05
    assert np.array_equal(at._project_world(world, other), session.camera.project_world(world, other))
    shifted = world + [0.0, 0.0, 0.01]
    assert np.array_equal(at._project_world(shifted, pose), session.camera.project_world(shifted, pose))
    assert not np.array_equal(at._project_world(shifted, pose), a)
