"""Detected markers outlined with their axes (pytest-qt, offscreen): with View > Show detected markers on,
the view's pixels along the marker's edges (found by OpenCV's own ArucoDetector on the frame as
captured) change colour; off, they stay the frame's. The 2-D primitives are checked against
cv2.projectPoints of the marker's corners at the same pose. The engine draws the marks into the picture
it hands over to the view, under the model, and not into the full-size composite (AR videos)."""

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
    from tracking.recording.writer import RecordingWriter
    from tracking.recording.schema import parse_anchors

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


def set_marks(qtbot, window, on: bool) -> np.ndarray:
    """Toggle View > Show detected markers while paused; the view's picture once the engine has drawn the
    paused frame again with the new setting (a frame still on its way from before the pause or the toggle,
    drawn with the old one, is not it: under load one came after the toggle and was taken for its redraw)."""
    before = window.session.last_shown
    window.marker_marks_action.setChecked(on)
    qtbot.waitUntil(lambda: window.session.last_shown is not before and window.session.last_shown.marks == on,
                    timeout=TIMEOUT_MS)
    qtbot.wait(50)
    return grab_rgb(window.view)


@pytest.mark.parametrize("engine", ["threads", "process"])
def test_detected_marker_outlined_when_on_and_not_when_off(qtbot, window, recording, engine):
    from arapp.engine.overlay_marks import marker_marks

    window.engine_kind = engine  # the in-process engine, and the shipped child-process one
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
    first = grab_rgb(window.view)  # on from the source's first frame
    off = set_marks(qtbot, window, False)
    on = set_marks(qtbot, window, True)
    marked = window.session.last_shown
    # only the view's picture has them: the full-size composite (AR videos) is the frame itself
    assert np.array_equal(marked.result.image, marked.frame)
    off_again = set_marks(qtbot, window, False)

    # on: the outline's colour along every edge; off: the same picture as before
    assert (changed_at(off, on, pts) > 60).mean() >= 0.9
    assert (changed_at(off, first, pts) > 60).mean() >= 0.9
    assert changed_at(off, off_again, pts).max() <= 2


def test_marks_only_for_markers_in_the_frame_and_none_without_detection():
    """Headless: a board seen so that its right column leaves the frame gets outlines for the markers
    wholly inside only (checked with cv2.projectPoints); no marker detected, or no pose: nothing."""
    from arapp.engine.overlay_marks import marker_marks
    from tracking.anchors.model import build_models
    from tracking.anchors.render import look_at
    from tracking.camera import Camera
    from tracking.recording.schema import parse_anchors

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


def test_marks_lie_under_the_model(qtbot, window, recording):
    """The vase stands on the marker: along the marker's edges, where the model is drawn (the composite
    with marks off differs from the frame as captured: the renderer's own picture) the view with marks on
    shows the same pixels as with marks off; elsewhere the outline shows."""
    window.open_model("models/vase.json")
    qtbot.waitUntil(lambda: window.model is not None, timeout=TIMEOUT_MS)
    window.model_panel.size.setValue(70.0)  # before the source: every frame shows this size
    window.marker_marks_action.setChecked(False)
    window.open_source(str(recording))
    qtbot.waitUntil(lambda: window.session.last_shown is not None
                    and window.session.last_shown.result.state == "marker"
                    and window.session.last_shown.result.extra.get("model_gen") == window.model_gen,
                    timeout=TIMEOUT_MS)
    window.session.pause()
    qtbot.wait(300)
    shown = window.session.last_shown
    frame, image = shown.frame, shown.result.image
    model = (np.abs(image.astype(int) - frame.astype(int)).max(axis=2) > 25).astype(np.uint8)
    model[:40, :] = 0  # the status line
    inner = cv2.erode(model, np.ones((7, 7), np.uint8)) > 0  # 3 px inside the model's drawn edge
    outer = cv2.dilate(model, np.ones((9, 9), np.uint8)) == 0  # 4 px clear of it
    samples = edge_samples(frame)
    s = np.linspace(0.05, 0.95, 40)[:, None]
    samples = np.concatenate([samples[12 * k] + s * (samples[12 * k + 11] - samples[12 * k]) for k in range(4)])
    ij = np.round(samples).astype(int)
    under, clear = inner[ij[:, 1], ij[:, 0]], outer[ij[:, 1], ij[:, 0]]
    assert under.sum() >= 10 and clear.sum() >= 20, (under.sum(), clear.sum())
    pts = to_widget(window, samples, frame.shape)
    off = grab_rgb(window.view)
    on = set_marks(qtbot, window, True)
    change = changed_at(off, on, pts)
    assert change[under].max() <= 3, change[under]  # the model, not the outline, where it covers the edge
    assert (change[clear] > 60).mean() >= 0.9  # the outline where the paper is seen


def test_marks_are_drawn_at_the_views_scale_and_under_the_model_as_the_mode_lets_through():
    """Headless: a horizontal outline edge across a frame half covered by a 'model' (the composite differs
    from the frame on the right half). In a picture at half the frame's size the line lands at half the
    frame position, OUTLINE_PX wide; where the model is, shaded keeps the model's pixels and a see-through
    mode mixes in `under` of the outline's colour (the rule under_opacity states)."""
    from arapp.engine.overlay_marks import OUTLINE_RGB, MarkerMarks, draw_marks, under_opacity

    frame = np.full((200, 400, 3), 90, np.uint8)
    composite = frame.copy()
    composite[:, 200:] = (30, 160, 30)  # the model over the right half
    marks = MarkerMarks(400, 200, quads=[np.array([[40.0, 100.0], [360.0, 100.0], [360.0, 100.0], [40.0, 100.0]])])
    cyan_bgra = np.array(OUTLINE_RGB[::-1] + (255,))

    def picture(mode):
        display = cv2.cvtColor(cv2.resize(composite, (200, 100), interpolation=cv2.INTER_LINEAR),
                               cv2.COLOR_BGR2BGRA)
        plain = display.copy()
        draw_marks(display, marks, composite, frame, under_opacity(mode))
        return plain, display

    plain, shaded = picture("shaded")
    row = np.abs(shaded.astype(int) - plain.astype(int)).max(axis=2)
    assert (row[:, 30:90].max(axis=1) > 100).sum() in (2, 3)  # OUTLINE_PX wide, antialiased
    assert row[48:52, 30:90].min() > 0 and row[:45].max() == 0 and row[56:].max() == 0  # at y = 100 / 2
    assert np.abs(shaded[49:51, 30:90].astype(int) - cyan_bgra).max() <= 60
    assert row[:, 105:170].max() == 0  # under the shaded model: the model's own pixels
    _, see_through = picture("translucent")
    u = under_opacity("translucent")
    assert 0 < u < 1
    want = plain[49:51, 105:170].astype(float) + u * (shaded[49:51, 30:90].mean(axis=1, keepdims=True)
                                                       - plain[49:51, 105:170])
    assert np.abs(see_through[49:51, 105:170].astype(float) - want).max() <= 25
