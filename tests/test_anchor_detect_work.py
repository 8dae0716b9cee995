"""How much detector work the anchor tracker spends where nothing can be found (issue 29, fast pans): the other
polarity is read only every few misses once a print is known; and what it must not save: a marker moved in
the room while the caller's (map's) pose holds the frame is still found where it went.

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


def test_a_marker_moved_while_the_callers_pose_holds_is_found_where_it_went():
    """A lone marker lost for a frame and back 200 px away in the image (the card was moved before a still
    webcam; in the marker's frame the camera jumped) while the caller's map still says the old pose: the
    anchors are searched for in the whole frame, not only where the caller's pose puts them."""
    card = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.03}], "anchors")
    here = look_at([0.0, 0.0, 0.45], [0.0, 0.0, 0.0], up=(0, 1, 0))   # a marker faces +z
    moved = look_at([0.15, 0.08, 0.45], [0.15, 0.08, 0.0], up=(0, 1, 0))   # the marker 200 px off
    tr = AnchorTracker(card, CAM, filter=False, full_every=10)
    assert tr.process(render_view(card, CAM, here), 0.0, reference=here).world_from_camera is not None
    assert tr.process(BLANK, 1 / 30, reference=here).world_from_camera is None
    res = tr.process(render_view(card, CAM, moved), 2 / 30, reference=here)
    assert res.world_from_camera is not None
    assert np.linalg.norm(res.world_from_camera[:3, 3] - moved[:3, 3]) < 0.01
