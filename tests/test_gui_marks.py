"""Detected markers outlined with their axes (pytest-qt, offscreen): with View > Show detected markers on,
the view's pixels along the marker's edges (found by OpenCV's own ArucoDetector on the frame as
captured) change colour; off, they stay the frame's. The 2-D primitives are checked against
cv2.projectPoints of the marker's corners at the same pose."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gui_helpers import grab_rgb

ANCHORS = [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.08}]
TIMEOUT_MS = 30000


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from tracking.anchors.render import look_at, render_view
    from tracking.camera import Camera
    from tracking.recorder import RecordingWriter
    from tracking.session import parse_anchors

    folder = tmp_path_factory.mktemp("marks") / "still"
    cam = Camera(np.array([[560.0, 0, 319.5], [0, 560.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)
    anchors = parse_anchors(ANCHORS)
    with RecordingWriter(folder, cam, 30.0, anchors=ANCHORS, source={"kind": "synthetic"}) as w:
        for i in range(6):
            pose = look_at([0.12, -0.10, 0.30 + 0.002 * i], [0.0, 0.0, 0.0])
            w.write(render_view(anchors, cam, pose, bgr=True), i / 30.0, pose)
    return folder


@pytest.fixture()
def window(threads_window):
    threads_window.full_frames = True  # the frame as captured comes with each shown frame
    threads_window.resize(1100, 700)
    return threads_window


def edge_samples(frame: np.ndarray) -> np.ndarray:
    """Points along the four edges of the marker OpenCV's ArucoDetector finds in `frame` (pixels)."""
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                  cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(frame)
    assert ids is not None and list(ids.ravel()) == [0]
    c = corners[0].reshape(4, 2)
    s = np.linspace(0.15, 0.85, 12)[:, None]
    return np.concatenate([c[k] + s * (c[(k + 1) % 4] - c[k]) for k in range(4)])


def to_widget(window, pts: np.ndarray, frame_shape) -> np.ndarray:
    rect = window.view.image_rect()
    h, w = frame_shape[:2]
    r = window.view.devicePixelRatioF()
    x = (rect.x() + (pts[:, 0] + 0.5) * rect.width() / w) * r
    y = (rect.y() + (pts[:, 1] + 0.5) * rect.height() / h) * r
    return np.stack([x, y], 1)


def changed_at(a: np.ndarray, b: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Per point: the largest colour change within 1 px of it between view pictures a and b."""
    out = []
    for x, y in np.round(pts).astype(int):
        pa = a[y - 1:y + 2, x - 1:x + 2].astype(int)
        pb = b[y - 1:y + 2, x - 1:x + 2].astype(int)
        out.append(np.abs(pa - pb).max())
    return np.array(out)


def test_detected_marker_outlined_when_on_and_not_when_off(qtbot, window, recording):
    from arapp.app.overlay_marks import marker_marks

    assert window.marker_marks_action.isChecked()  # default on
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.session.last_shown is not None
                    and window.session.last_shown.result.state == "marker", timeout=TIMEOUT_MS)
    window.session.pause()
    qtbot.wait(300)
    shown = window.session.last_shown
    frame = shown.frame
    assert frame is not None

    # the primitives: the marker's corners by cv2.projectPoints at the shown pose
    info = window.session.source_info
    marks = marker_marks(info.camera, info.anchors, shown.result.world_from_camera, shown.result.markers)
    assert len(marks.quads) == 1 and len(marks.axes) == 1
    h = 0.04
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)
    cfw = np.linalg.inv(shown.result.world_from_camera)
    rvec, _ = cv2.Rodrigues(cfw[:3, :3])
    ref, _ = cv2.projectPoints(obj, rvec, cfw[:3, 3], info.camera.K, info.camera.dist)
    assert np.abs(np.sort(marks.quads[0], 0) - np.sort(ref.reshape(4, 2), 0)).max() < 0.01

    pts = to_widget(window, edge_samples(frame), frame.shape)
    window.marker_marks_action.setChecked(False)
    qtbot.wait(100)
    off = grab_rgb(window.view)
    window.marker_marks_action.setChecked(True)
    qtbot.wait(100)
    on = grab_rgb(window.view)
    window.marker_marks_action.setChecked(False)
    qtbot.wait(100)
    off_again = grab_rgb(window.view)

    # on: the outline's colour along every edge; off: the same picture as before
    assert (changed_at(off, on, pts) > 60).mean() >= 0.9
    assert changed_at(off, off_again, pts).max() <= 2


def test_marks_only_for_markers_in_the_frame_and_none_without_detection():
    """Headless: a board seen so that its right column leaves the frame gets outlines for the markers
    wholly inside only (checked with cv2.projectPoints); no marker detected, or no pose: nothing."""
    from arapp.app.overlay_marks import marker_marks
    from tracking.anchors.model import build_models
    from tracking.anchors.render import look_at
    from tracking.camera import Camera
    from tracking.session import parse_anchors

    anchors = parse_anchors([{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                              "marker_length": 0.04, "separation": 0.01, "first_id": 0}])
    cam = Camera(np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)
    pose = look_at([0.17, 0.07, 0.2], [0.17, 0.07, 0.0], up=(0.0, 1.0, 0.0))
    cfw = np.linalg.inv(pose)
    rvec, _ = cv2.Rodrigues(cfw[:3, :3])
    inside = []
    for corners in build_models(anchors)[0].markers.values():
        uv, _ = cv2.projectPoints(np.asarray(corners, float), rvec, cfw[:3, 3], cam.K, cam.dist)
        uv = uv.reshape(4, 2)
        if ((uv >= -0.5) & (uv <= [639.5, 479.5])).all():
            inside.append(uv)
    marks = marker_marks(cam, anchors, pose, markers_seen=5)
    assert 0 < len(inside) < 12 and len(marks.quads) == len(inside)
    for got, want in zip(sorted(marks.quads, key=lambda q: tuple(q[0])), sorted(inside, key=lambda q: tuple(q[0]))):
        assert np.abs(got - want).max() < 0.01
    assert len(marks.axes) == 1
    assert not marker_marks(cam, anchors, pose, markers_seen=0).quads
    assert not marker_marks(cam, anchors, None).quads
