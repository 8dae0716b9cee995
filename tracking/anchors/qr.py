"""QR-code anchors: decode once, then track the finder-pattern corners.

OpenCV's QR detectors take tens of milliseconds at 720p and give the symbol
corners only to about a pixel. So a QR anchor is decoded (text must match the
anchor's `text`) in a region predicted from the last pose, or in the whole
frame when nothing predicts it, and from then on its 36 finder-pattern
corners (three finders x outer ring, inner ring, centre square, all clean
black/white corners) are followed by pyramidal optical flow and re-found
exactly every frame by fitting lines to the edges of the finder squares (edges.py). A check of the finder patterns'
appearance (dark ring and centre, light ring between) guards against drift;
when it fails the code is decoded again.

Texts are compared with their line ends and surrounding whitespace normalised (`same_text`): common
payloads (vCard, MECARD) are encoded with CRLF line ends, an anchor's `text` is typed with LF ones.
Texts read that match no anchor are kept (`QRTracking.foreign_texts`) so that a session that tracks
nothing can say what it read (anchors/diagnose.py).

Module coordinates: u right, v down, (0,0) the symbol's top-left corner and
(N,N) its bottom-right (N modules, quiet zone excluded). The anchor frame is
docs/recording-format.md's: x = -L/2 + u L/N, y = L/2 - v L/N.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from tracking.anchors.detect import Observation
from tracking.anchors.edges import refine_squares
from tracking.anchors.kinds.qr import normal_text, same_text  # noqa: F401 - same_text: the comparison, named here too
from tracking.anchors.model import AnchorModel, square_corners
from tracking.anchors.pose import project
from tracking.camera import Camera

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
_LK = dict(winSize=(21, 21), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.03))


def finder_points(n: int) -> np.ndarray:
    """(36,2) module coordinates of the finder-pattern corners of an n-module symbol (3 finders x 3 squares x 4)."""
    pts = []
    for ox, oy in ((0, 0), (n - 7, 0), (0, n - 7)):
        for a, b in ((0, 7), (1, 6), (2, 5)):
            pts += [(ox + a, oy + a), (ox + b, oy + a), (ox + b, oy + b), (ox + a, oy + b)]
    return np.array(pts, dtype=np.float64)


def _finder_samples(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Module centres that are dark (ring + centre) and light (ring between) in the three finders."""
    dark, light = [], []
    for ox, oy in ((0, 0), (n - 7, 0), (0, n - 7)):
        for j in range(7):
            for i in range(7):
                r = max(abs(i - 3), abs(j - 3))
                (light if r == 2 else dark).append((ox + i + 0.5, oy + j + 0.5))
    return np.array(dark), np.array(light)


def _apply_h(H, pts):
    p = np.c_[pts, np.ones(len(pts))] @ H.T
    return p[:, :2] / p[:, 2:3]


class QRTracking:
    """Decodes and tracks the QR anchors of a session. State: each anchor's last finder corners."""

    def __init__(self, models: list[AnchorModel], camera: Camera, detector: str = "aruco"):
        self.models = [m for m in models if m.anchor_kind.detector == "qr"]
        self.by_text = {normal_text(m.spec.text): m for m in self.models}   # normalised text -> anchor
        self.foreign_texts: list[str] = []   # texts read (as read) that match no anchor, first seen first
        self.camera = camera
        # The ArUco-based detector finds codes fastest; the classic one decodes some it cannot (perspective,
        # blur) and misses others, so a missing code is searched with both (`detector` says which first).
        self.decoder = cv2.QRCodeDetector()
        aruco = cv2.QRCodeDetectorAruco()
        self.detectors = (aruco, self.decoder) if detector == "aruco" else (self.decoder, aruco)
        self.reset()

    def reset(self) -> None:
        self.state: dict[int, tuple[int, np.ndarray]] = {}  # anchor -> (modules n, (36,2) pixels)
        self.prev = None
        self.decode_ms = 0.0
        self.decoded_texts: list[str] = []

    # -- geometry ----------------------------------------------------------------------------------
    def _plane(self, m: AnchorModel, mod: np.ndarray, n: int) -> np.ndarray:
        L = m.spec.length
        return np.c_[-L / 2 + mod[:, 0] * L / n, L / 2 - mod[:, 1] * L / n, np.zeros(len(mod))]

    def _refine(self, gray: np.ndarray, H: np.ndarray, n: int) -> np.ndarray | None:
        """Finder corners (36,2) re-found near the homography H (modules -> pixels); None if not a QR there."""
        mod = finder_points(n)
        guess = _apply_h(H, mod)
        h, w = gray.shape
        # the local module size in pixels bounds the search window (it must not reach the next corner)
        step = np.linalg.norm(_apply_h(H, mod + [1.0, 0.0]) - guess, axis=1)
        step = np.minimum(step, np.linalg.norm(_apply_h(H, mod + [0.0, 1.0]) - guess, axis=1))
        mpx = float(np.median(step))
        if not np.isfinite(mpx) or mpx < 2.0:
            return None
        inside = (guess[:, 0] > 3) & (guess[:, 0] < w - 4) & (guess[:, 1] > 3) & (guess[:, 1] < h - 4)
        if inside.sum() < 12:
            return None
        quads, qok = refine_squares(gray, guess.reshape(9, 4, 2), np.full(9, mpx), self.camera)
        pts = quads.reshape(-1, 2)
        ok = np.repeat(qok, 4) & inside
        if ok.sum() < 12:
            return None
        H2, _ = cv2.findHomography(mod[ok], pts[ok], 0)
        if H2 is None:
            return None
        res = np.linalg.norm(_apply_h(H2, mod) - pts, axis=1)
        ok &= res < max(0.15 * mpx, 0.75)
        if ok.sum() < 12 or not self._looks_like_finders(gray, H2, n):
            return None
        pts[~ok] = np.nan
        return pts

    @staticmethod
    def _looks_like_finders(gray: np.ndarray, H: np.ndarray, n: int) -> bool:
        dark, light = _finder_samples(n)
        pd, pl = _apply_h(H, dark).astype(np.float32), _apply_h(H, light).astype(np.float32)
        h, w = gray.shape
        allp = np.concatenate([pd, pl])
        keep = (allp[:, 0] >= 0) & (allp[:, 0] <= w - 1) & (allp[:, 1] >= 0) & (allp[:, 1] <= h - 1)
        if keep.mean() < 0.6:
            return False
        vals = cv2.remap(gray, allp[:, 0:1], allp[:, 1:2], cv2.INTER_LINEAR).ravel().astype(float)
        vd, vl = vals[: len(pd)][keep[: len(pd)]], vals[len(pd):][keep[len(pd):]]
        if len(vd) < 10 or len(vl) < 4:
            return False
        return np.percentile(vl, 10) - np.percentile(vd, 90) > 10 and vl.mean() - vd.mean() > 30

    # -- per frame ------------------------------------------------------------------------------------
    def expected(self, cfw: np.ndarray | None) -> set[int] | None:
        """QR anchors the predicted pose puts (partly) inside the image; None when there is no prediction."""
        if cfw is None:
            return None
        out = set()
        for m in self.models:
            px, z = project(self.camera, cfw, m.to_world(square_corners(m.spec.length)))
            if np.all(z > 0) and np.any((px[:, 0] >= 0) & (px[:, 0] < self.camera.width)
                                        & (px[:, 1] >= 0) & (px[:, 1] < self.camera.height)):
                out.add(m.index)
        return out

    def process(self, gray: np.ndarray, predicted_camera_from_world: np.ndarray | None,
                expected: set[int] | None = None) -> list[Observation]:
        """QR observations in this frame. `predicted_camera_from_world` (or None) places codes not yet tracked;
        `expected`: anchors the prediction puts in view (None: unknown, search the whole frame)."""
        self.decode_ms = 0.0
        out = {}
        for a, (n, prev_pts) in list(self.state.items()):
            pts = self._track(gray, n, prev_pts)
            if pts is None:
                del self.state[a]
            else:
                self.state[a] = (n, pts)
                out[a] = self._observation(self.models_by_index[a], n, pts)
        missing = [m for m in self.models if m.index not in self.state]
        if missing:
            wanted = missing if expected is None else [m for m in missing if m.index in expected]
            if wanted:
                roi = self._roi(wanted, predicted_camera_from_world, gray.shape) if expected is not None else None
                for m, n, pts, corners in self._decode(gray, roi, wanted):
                    if m.index in self.state:
                        continue
                    if pts is not None:
                        self.state[m.index] = (n, pts)
                        out[m.index] = self._observation(m, n, pts)
                    else:
                        # finders not refitted (blur, glare, curved paper): the decoder's symbol corners,
                        # not tracked (the code is decoded again next frame)
                        out[m.index] = Observation(m.index, square_corners(m.spec.length), corners,
                                                   np.full(4, -10), 1, square=True)
        self.prev = gray
        return [out[k] for k in sorted(out)]

    @property
    def models_by_index(self) -> dict[int, AnchorModel]:
        return {m.index: m for m in self.models}

    def _observation(self, m: AnchorModel, n: int, pts: np.ndarray) -> Observation:
        mod = finder_points(n)
        ok = np.isfinite(pts[:, 0])
        groups = np.repeat(np.arange(3), 12)[ok] - 10
        return Observation(m.index, self._plane(m, mod[ok], n), pts[ok], groups, 1)

    def _track(self, gray, n, prev_pts) -> np.ndarray | None:
        if self.prev is None or self.prev.shape != gray.shape:
            return None
        ok = np.isfinite(prev_pts[:, 0])
        # optical flow on a crop around the code only (pyramids of a whole 720p frame cost milliseconds)
        h, w = gray.shape
        lo, hi = prev_pts[ok].min(axis=0), prev_pts[ok].max(axis=0)
        pad = 0.5 * float((hi - lo).max()) + 40.0
        x0, y0 = np.maximum(np.floor(lo - pad), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(hi + pad), [w, h]).astype(int)
        p0 = (prev_pts[ok] - [x0, y0]).astype(np.float32).reshape(-1, 1, 2)
        p1, st, _ = cv2.calcOpticalFlowPyrLK(self.prev[y0:y1, x0:x1], gray[y0:y1, x0:x1], p0, None, **_LK)
        p1 = p1 + np.float32([x0, y0])
        st = st.ravel().astype(bool)
        if st.sum() < 8:
            return None
        mod = finder_points(n)[ok][st]
        H, _ = cv2.findHomography(mod, p1.reshape(-1, 2)[st].astype(np.float64), cv2.RANSAC, 2.0)
        if H is None:
            return None
        return self._refine(gray, H, n)

    def _roi(self, models, camera_from_world, shape):
        """Pixel box (x0, y0, x1, y1) around where the prediction puts the codes (with margin), or None."""
        if camera_from_world is None:
            return None
        pts = []
        for m in models:
            c = square_corners(m.spec.length * 1.6)  # symbol plus quiet zone plus prediction slack
            wc = c @ m.world_from_anchor[:3, :3].T + m.world_from_anchor[:3, 3]
            px, z = project(self.camera, camera_from_world, wc)
            if np.any(z <= 0):
                return None
            pts.append(px)
        pts = np.concatenate(pts)
        h, w = shape
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.25 * (hi - lo) + 16
        x0, y0 = np.maximum(np.floor(lo - pad), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(hi + pad), [w, h]).astype(int)
        if x1 - x0 < 24 or y1 - y0 < 24:
            return None
        if (x1 - x0) * (y1 - y0) > 0.6 * w * h:
            return None
        return int(x0), int(y0), int(x1), int(y1)

    def _decode(self, gray, roi, wanted=None):
        """Decoded codes matching anchors: list of (model, modules n, (36,2) finder corners or None, (4,2)
        symbol corners). The finder corners are None when the refit failed: the decoder's own corners
        (about a pixel) then carry the code, so every code OpenCV reads still gives a pose.

        Both OpenCV detectors search, the ArUco-based one first (fastest); the classic one only while a
        `wanted` anchor (default: all) is still missing, since it finds codes the other misses (blur,
        perspective) and the other way round."""
        t0 = time.perf_counter()
        x0 = y0 = 0
        img = gray
        if roi is not None:
            x0, y0, x1, y1 = roi
            img = gray[y0:y1, x0:x1]
        want = {normal_text(m.spec.text) for m in (wanted if wanted is not None else self.models)}
        codes: dict[str, tuple[np.ndarray, object]] = {}   # normalised text -> (corners, straight symbol)
        self.decoded_texts = []
        for det in self.detectors:
            for text, corners, straight in self._codes(det, img):
                if text not in self.decoded_texts:
                    self.decoded_texts.append(text)
                key = normal_text(text)
                if key not in self.by_text and text not in self.foreign_texts:
                    self.foreign_texts.append(text)
                if key not in codes or (codes[key][1] is None and straight is not None):
                    codes[key] = (corners, straight)
            if want <= codes.keys():
                break
        found = []
        for text, (corners, straight) in codes.items():
            m = self.by_text.get(text)
            if m is None:
                continue
            corners = corners.astype(np.float64) + [x0, y0]
            n = int(straight.shape[0]) if straight is not None else 0
            pts = None
            if n >= 21 and (n - 17) % 4 == 0:
                H, _ = cv2.findHomography(np.array([[0, 0], [n, 0], [n, n], [0, n]], float), corners, 0)
                if H is not None:
                    pts = self._refine(gray, H, n)
            found.append((m, n, pts, corners))
        self.decode_ms = (time.perf_counter() - t0) * 1000
        return found

    def _codes(self, det, img) -> list[tuple[str, np.ndarray, object]]:
        """(text, (4,2) corners in img, straight symbol or None) of every code `det` finds and that decodes.

        A code whose text is not UTF-8 (Shift-JIS, Kanji mode) makes OpenCV's Python binding raise
        UnicodeDecodeError for the whole call, hiding every other code of the frame; the codes are then
        decoded one at a time and that one skipped. Codes found but not decoded get a second try with the
        classic decoder in a crop around them."""
        try:
            ok, texts, points, straight = det.detectAndDecodeMulti(img)
        except UnicodeDecodeError:
            return self._codes_one_by_one(det, img)
        except cv2.error:
            return []
        if not ok or points is None:
            return []
        straight = list(straight) if straight is not None else []
        straight += [None] * (len(texts) - len(straight))
        out = []
        for text, p, st in zip(texts, points, straight):
            corners = np.asarray(p, np.float64).reshape(4, 2)
            if not text:
                text, st = self._decode_again(img, corners)
            if text:
                out.append((text, corners, st if st is not None and np.size(st) else None))
        return out

    def _codes_one_by_one(self, det, img) -> list[tuple[str, np.ndarray, object]]:
        try:
            ok, points = det.detectMulti(img)
        except cv2.error:
            return []
        if not ok or points is None:
            return []
        out = []
        for p in points:
            p = np.asarray(p, np.float32).reshape(1, 4, 2)
            try:
                text, st = det.decode(img, p)
            except (UnicodeDecodeError, cv2.error):
                continue  # a foreign code with text Python cannot read: not an anchor of ours
            if text:
                out.append((text, p.reshape(4, 2).astype(np.float64), st if st is not None and np.size(st) else None))
        return out

    def _decode_again(self, img, corners):
        """Decode one found-but-undecoded code with the classic detector in a crop around it."""
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        pad = 0.3 * (hi - lo).max() + 8
        x0, y0 = np.maximum(np.floor(lo - pad), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(hi + pad), [img.shape[1], img.shape[0]]).astype(int)
        try:
            text, _, straight = self.decoder.detectAndDecode(img[y0:y1, x0:x1])
        except (cv2.error, UnicodeDecodeError):
            return "", None
        return text, straight
