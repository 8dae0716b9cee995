"""QR texts compare with line ends and surrounding whitespace normalised (issue 25.5).

vCard and MECARD payloads are encoded with CRLF line ends; an anchor's `text` typed by a person has LF
ones. Oracle: cv2.QRCodeDetector's own reading of the synthetic code (it reads the CRLF back), and the
rule that the anchor whose text differs only in line ends is the one tracked.
"""

import numpy as np
import pytest

from tracking.anchors import AnchorTracker
from tracking.anchors.render import look_at, render_view
from tracking.camera import Camera
from tracking.errors import SessionError
from tracking.recording.schema import parse_anchors

import cv2

CAM = Camera(np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)
VCARD_CRLF = "BEGIN:VCARD\r\nVERSION:3.0\r\nN:Owen;Sean\r\nTEL:+12125551212\r\nEND:VCARD\r\n"
VCARD_LF = "BEGIN:VCARD\nVERSION:3.0\nN:Owen;Sean\nTEL:+12125551212\nEND:VCARD"   # as typed (no last newline)


def picture(text):
    anchors = parse_anchors([{"kind": "qr", "text": text, "length": 0.08}])
    return render_view(anchors, CAM, look_at([0.01, -0.02, 0.3], [0, 0, 0], up=(0, 1, 0)))


def test_a_vcard_code_with_crlf_is_the_anchor_typed_with_lf():
    img = picture(VCARD_CRLF)
    ok, texts, _, _ = cv2.QRCodeDetector().detectAndDecodeMulti(img)
    assert ok and VCARD_CRLF in texts   # the oracle reads the CRLF line ends back
    tr = AnchorTracker(parse_anchors([{"kind": "qr", "text": VCARD_LF, "length": 0.08}]), CAM, filter=False)
    res = tr.process(img, 0.0)
    assert res.world_from_camera is not None and res.anchors_seen == [0]
    assert np.linalg.norm(res.world_from_camera[:3, 3] - [0.01, -0.02, 0.3]) < 0.005
    assert tr.qr.foreign_texts == []


def test_codes_of_other_texts_are_kept_once_as_read():
    img = picture(VCARD_CRLF)
    tr = AnchorTracker(parse_anchors([{"kind": "qr", "text": "arapp anchor 1", "length": 0.08}]), CAM, filter=False)
    for t in range(3):
        assert tr.process(img, t / 30).world_from_camera is None
    assert tr.qr.foreign_texts == [VCARD_CRLF]


def test_two_anchors_differing_only_in_line_ends_are_refused():
    with pytest.raises(SessionError, match=r"anchors\[1\] and anchors\[0\] are QR codes with the same text"):
        AnchorTracker(parse_anchors([{"kind": "qr", "text": VCARD_LF, "length": 0.08},
                                     {"kind": "qr", "text": VCARD_CRLF, "length": 0.08,
                                      "world_from_anchor": np.eye(4).tolist()}]), CAM)
