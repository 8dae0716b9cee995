"""A QR code that is not the anchor, or whose text Python cannot read, never stops tracking (issue 13).

Codes are made by segno (not by arapp or OpenCV): the anchor's text in byte mode and a Japanese text in
Kanji mode (Shift-JIS bytes, which OpenCV's Python binding fails to turn into a str). They are drawn
on a plane at known poses; the oracle is that ground truth.
"""

import cv2
import numpy as np
import pytest
import segno  # a test dependency (pyproject's test extra)

from tracking.anchors import AnchorTracker
from tracking.anchors.render import look_at
from tracking.camera import Camera
from tracking.poses import invert, rotation_angle
from tracking.recording.schema import parse_anchors

L = 0.05  # symbol side (quiet zone excluded), metres
PX = 12  # pixels per module in the flat drawing
SS = 3


def code_image(text: str, **kw) -> tuple[np.ndarray, int]:
    """Gray drawing of a QR symbol with a 4-module quiet zone, and its module count."""
    q = segno.make(text, micro=False, **kw)
    m = np.array(q.matrix, np.uint8)
    img = np.pad(np.where(m > 0, 0, 255).astype(np.uint8), 4, constant_values=255)
    return cv2.resize(img, None, fx=PX, fy=PX, interpolation=cv2.INTER_NEAREST), m.shape[0]


def draw(camera: Camera, world_from_camera, codes) -> np.ndarray:
    """Camera image of codes lying on the world plane z=0, seen from the +z side.

    codes: list of (drawing, modules n, (x, y) centre in metres). Anchor frame = world for a code at (0, 0):
    module (u, v) lies at x = -L/2 + u L/n, y = L/2 - v L/n."""
    cfw = invert(world_from_camera)
    big_from_cam = np.array([[SS, 0, (SS - 1) / 2], [0, SS, (SS - 1) / 2], [0, 0, 1.0]])
    cam_from_plane = camera.K @ np.c_[cfw[:3, 0], cfw[:3, 1], cfw[:3, 3]]
    canvas = np.full((camera.height * SS, camera.width * SS), 120, np.uint8)
    for img, n, (cx, cy) in codes:
        s = L / (n * PX)  # metres per drawing pixel
        # drawing pixel centre (i, j) covers module u = (i + 0.5) / PX - 4
        plane_from_px = np.array([[s, 0, cx - L / 2 + (0.5 - 4 * PX) * s],
                                  [0, -s, cy + L / 2 - (0.5 - 4 * PX) * s], [0, 0, 1]])
        H = big_from_cam @ cam_from_plane @ plane_from_px
        mask = cv2.warpPerspective(np.full_like(img, 255), H, canvas.shape[::-1], flags=cv2.INTER_NEAREST)
        warped = cv2.warpPerspective(img, H, canvas.shape[::-1], flags=cv2.INTER_LINEAR)
        canvas = np.where(mask > 0, warped, canvas)
    out = cv2.resize(canvas, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(out, (0, 0), 0.6)


@pytest.fixture(scope="module")
def cam():
    return Camera([[800.0, 0, 479.5], [0, 800.0, 359.5], [0, 0, 1]], None, 960, 720)


@pytest.fixture(scope="module")
def kanji():
    img, n = code_image("漢字のテキスト", mode="kanji")
    return img, n


ANCHOR = [{"kind": "qr", "text": "arapp anchor 1", "length": L}]


def test_the_foreign_code_is_kanji_that_opencv_cannot_hand_to_python(kanji):
    """The premise: OpenCV's binding raises UnicodeDecodeError on this code (if it stops, the test is moot)."""
    img, _ = kanji
    with pytest.raises(UnicodeDecodeError):
        cv2.QRCodeDetector().detectAndDecodeMulti(img)


@pytest.mark.parametrize("eye", [(0.03, -0.05, 0.32), (-0.12, 0.04, 0.30)])
def test_shift_jis_code_beside_the_anchor_does_not_stop_tracking(cam, kanji, eye):
    anchor, n = code_image("arapp anchor 1", mode="byte", error="m")
    gt = look_at(list(eye), [0.03, 0.0, 0.0], up=(0, 1, 0))
    gray = draw(cam, gt, [(anchor, n, (0.0, 0.0)), (kanji[0], kanji[1], (0.075, 0.0))])
    tr = AnchorTracker(parse_anchors(ANCHOR), cam, filter=False)
    for k in range(3):  # decode, then track the finders
        res = tr.process(gray, k / 30)
        assert res.raw_world_from_camera is not None, f"frame {k}"
        T = res.raw_world_from_camera
        # a 5 cm code ~130 px wide at 0.3 m: measured 0.1-0.5 mm and < 0.1 deg
        assert np.linalg.norm(T[:3, 3] - gt[:3, 3]) < 0.0015
        assert np.degrees(rotation_angle(T[:3, :3] @ gt[:3, :3].T)) < 0.3


def test_only_a_shift_jis_code_in_view(cam, kanji):
    gt = look_at([0.0, 0.0, 0.3], [0.0, 0.0, 0.0], up=(0, 1, 0))
    gray = draw(cam, gt, [(kanji[0], kanji[1], (0.0, 0.0))])
    tr = AnchorTracker(parse_anchors(ANCHOR), cam)
    for k in range(2):
        assert tr.process(gray, k / 30).world_from_camera is None
