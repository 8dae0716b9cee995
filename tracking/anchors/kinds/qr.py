"""`qr`: a QR code whose decoded text names the anchor; frame centred on the symbol, x right, y up,
z out of the paper (tracking/anchors/qr.py finds and follows it)."""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.kinds.base import AnchorKind, mm, square_corners


def normal_text(text: str) -> str:
    """`text` with CRLF / CR line ends as LF and surrounding whitespace removed: the form QR texts are compared
    in (vCard and MECARD payloads are encoded with CRLF; an anchor's text is typed with LF)."""
    return text.replace("\r\n", "\n").replace("\r", "\n").strip()


def same_text(a: str, b: str) -> bool:
    """Whether a code's text `a` and an anchor's text `b` are the same (see normal_text)."""
    return normal_text(a) == normal_text(b)


def qr_modules(text: str) -> np.ndarray:
    """(N,N) uint8 image of a QR symbol for `text`, one pixel per module, quiet zone removed (0 black, 255 white)."""
    img = cv2.QRCodeEncoder.create().encode(text)
    if img is None or img.size == 0:
        raise ValueError(f"cannot encode {text!r} as a QR code (too long?)")
    dark = np.argwhere(img < 128)
    (y0, x0), (y1, x1) = dark.min(axis=0), dark.max(axis=0)
    return np.ascontiguousarray(img[y0:y1 + 1, x0:x1 + 1])


class QRKind(AnchorKind):
    """A QR symbol encoding `text`, side `length` (quiet zone excluded)."""

    name = "qr"
    required = {"text": str, "length": float}
    optional = {"first_id": int}   # no polarity: a QR code is read dark on light
    positive = ("length",)
    detector = "qr"
    cli_name = "qr"

    def geometry(self, spec):
        return {}, None, None

    def outline(self, spec, markers, chess):
        return square_corners(spec.length)

    def layout(self, spec, markers, margin):
        mod = qr_modules(spec.text)
        patches = [(mod, square_corners(spec.length)[:, :2])]
        return patches, [], 4 * spec.length / mod.shape[0] if margin is None else margin  # the quiet zone

    def describe(self, spec):
        return f'QR code "{spec.text}", {mm(spec.length)}'

    def caption(self, spec):
        return f"QR {spec.text!r}, symbol {mm(spec.length)} (quiet zone excluded)"

    def summary(self, spec):
        return repr(spec.text), mm(spec.length)

    def file_stem(self, spec):
        safe = "".join(c if c.isalnum() else "_" for c in spec.text)[:24]
        return f"qr_{safe}_{spec.length * 1000:g}mm"

    def cli_block(self, args):
        return {"kind": "qr", "text": args.text, "length": args.length}
