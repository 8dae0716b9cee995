"""How much detector work the anchor tracker spends where nothing can be found (issue 29, fast pans): the other
polarity is read only every few misses once a print is known, and while the caller's pose holds the frame
the markers are looked for only where it puts them.

Oracles: the rules written here (passes counted by the detector itself, `ArucoDetection.passes` and
`pixels_read`), a synthetic board rendered at a known pose, and the ground-truth pose as the caller's.
"""

import numpy as np

from tracking.anchors import AnchorTracker
from tracking.anchors.detect import ArucoDetection
from tracking.anchors.model import build_models
from tracking.anchors.render import look_at, render_view
from tracking.camera import Camera
from tracking.recording.schema import parse_anchors

CAM = Camera(np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)
BOARD = {"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3, "marker_length": 0.04,
         "separation": 0.01}
# OpenCV boards face -z (kinds/base.py): the camera looks at the board from below its plane
WFC = look_at([0.09, 0.04, -0.38], [0.08, 0.07, 0.0], up=(0, -1, 0))
ANCHORS = parse_anchors([BOARD])
NORMAL = render_view(ANCHORS, CAM, WFC)
BLANK = np.full_like(NORMAL, 128)


def test_a_known_print_reads_the_other_polarity_every_eighth_miss():
    det = ArucoDetection(build_models(ANCHORS), CAM)
    det.other_every = 8
    for _ in range(4):   # print unknown: normal on every miss, the other polarity on every second one
        assert det.detect(BLANK) == []
    assert det.passes == 4 + 2
    assert det.detect(NORMAL) and det.polarity == {0: "normal"}
    before = det.passes
    for _ in range(16):
        assert det.detect(BLANK) == []
    assert det.passes - before == 16 + 2   # misses 8 and 16 read it inverted too
    # the print turned over: still found, at the next eighth miss
    inverted = 255 - NORMAL
    found = [bool(det.detect(inverted)) for _ in range(8)]
    assert found == [False] * 7 + [True] and det.polarity == {0: "inverted"}


def test_the_plain_detector_reads_both_polarities_on_every_miss():
    det = ArucoDetection(build_models(ANCHORS), CAM)   # other_every 1: as before, for callers of the detector
    for _ in range(3):
        det.detect(BLANK)
    assert det.passes == 6


def test_the_callers_pose_limits_where_the_markers_are_looked_for():
    full = CAM.width * CAM.height
    tr = AnchorTracker(ANCHORS, CAM, filter=False, full_every=10)
    det = tr.aruco
    # the first frame is one of the whole-frame searches (every `full_every`-th)
    assert tr.process(BLANK, 0.0, reference=WFC).world_from_camera is None
    assert det.passes == 1 and det.pixels_read == full
    # nothing tracked, the caller's pose (the truth) holds the frame: a region around the board only
    res = tr.process(NORMAL, 1 / 30, reference=WFC)
    assert res.world_from_camera is not None
    assert det.passes == 2 and det.pixels_read - full < 0.7 * full
    assert np.linalg.norm(res.world_from_camera[:3, 3] - WFC[:3, 3]) < 0.002
    # the caller's pose puts the board wholly outside the image: no detector pass at all
    tr = AnchorTracker(ANCHORS, CAM, filter=False, full_every=10)
    away = WFC.copy()
    away[:3, 3] += away[:3, :3] @ np.array([1.0, 0.0, 0.0])   # a metre to the camera's right
    tr.process(BLANK, 0.0, reference=away)
    passes = tr.aruco.passes
    for k in range(1, 10):
        assert tr.process(BLANK, k / 30, reference=away).world_from_camera is None
    assert tr.aruco.passes == passes
    # ... but every `full_every`-th frame the whole frame is searched all the same
    tr.process(BLANK, 10 / 30, reference=away)
    assert tr.aruco.passes > passes
    # without the caller's pose (lost): the whole frame on every frame
    tr = AnchorTracker(ANCHORS, CAM, filter=False)
    for k in range(3):
        tr.process(BLANK, k / 30)
    assert tr.aruco.pixels_read >= 3 * full
