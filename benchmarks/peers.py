"""The plain OpenCV peers the tracking benchmarks compare arapp with (bench_anchors, bench_slam).

- `PlainPeer`: per frame `ArucoDetector.detectMarkers` with CORNER_REFINE_SUBPIX (one detector per
  dictionary), QR codes with the fastest OpenCV QR call that decodes (`QR_CALLS`, chosen by
  `choose_qr_call` on a tuning recording), every detected corner of every anchor into one
  `cv2.solvePnP` (SOLVEPNP_ITERATIVE); no filter, no outlier handling.
- `FilteredPeer`: the plain pose through arapp's own constant-velocity SE(3) filter
  (`tracking.anchors.filter.PoseFilter`, the class and default parameters `AnchorTracker` uses), fed
  with the plain poses and the camera's distance to the world origin as the scene distance. So the
  jitter goal (arapp <= half the filtered peer's) compares like with like: the same filter kind on
  both sides, arapp's measurements against OpenCV's.
Poses are world_from_camera 4x4, metres.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary

# the synthetic scenes are test scaffolding kept in tests/ (tests/scenes.py, tests/scan_scene.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def _qr_calls() -> dict:
    """name -> (make detector, call(detector, gray) -> [(text, corners (4, 2))])."""

    def multi(det, gray):
        ok, texts, pts, _ = det.detectAndDecodeMulti(gray)
        return [(t, p.reshape(4, 2)) for t, p in zip(texts, pts)] if ok else []

    def single(det, gray):
        text, pts, _ = det.detectAndDecode(gray)
        return [(text, pts.reshape(4, 2))] if text and pts is not None else []

    return {
        "QRCodeDetector.detectAndDecode": (cv2.QRCodeDetector, single),
        "QRCodeDetector.detectAndDecodeMulti": (cv2.QRCodeDetector, multi),
        "QRCodeDetectorAruco.detectAndDecode": (cv2.QRCodeDetectorAruco, single),
        "QRCodeDetectorAruco.detectAndDecodeMulti": (cv2.QRCodeDetectorAruco, multi),
    }


QR_CALLS = _qr_calls()


def measure_qr_calls(frames, text: str) -> dict:
    """{call name: (frames whose code `text` was decoded, median ms)} over [(t, BGR image, ...)] frames.

    The calls take turns on each frame, so a change in the machine's load hits them alike.
    """
    dets = {name: (make(), call) for name, (make, call) in QR_CALLS.items()}
    ms = {name: [] for name in dets}
    hits = dict.fromkeys(dets, 0)
    for f in frames:
        g = cv2.cvtColor(f[1], cv2.COLOR_BGR2GRAY)
        for name, (det, call) in dets.items():
            t0 = time.perf_counter()
            found = call(det, g)
            ms[name].append((time.perf_counter() - t0) * 1000)
            hits[name] += any(t == text for t, _ in found)
    return {name: (hits[name], float(np.median(ms[name]))) for name in dets}


def choose_qr_call(measured: dict) -> str:
    """The fastest call among those that decode at least 90 % as many frames as the best one (OpenCV's
    ArUco-based QR detector is about twice as fast as the classic one and misses a few frames the classic
    one decodes)."""
    best = max(h for h, _ in measured.values())
    ok = [n for n, (h, _) in measured.items() if h >= 0.9 * best]
    return min(ok, key=lambda n: measured[n][1])


_CHOSEN: dict = {}


def chosen_qr_call(folder, limit: int | None = None) -> tuple[str, dict]:
    """(the QR call `choose_qr_call` picks on the QR recording `folder`, the measurements), measured once per
    process: the anchors and SLAM sections of one benchmark run use the same call."""
    key = (str(folder), limit)
    if key not in _CHOSEN:
        from scenes import load_recording

        frames, session = load_recording(folder, slice(0, limit) if limit else None)
        measured = measure_qr_calls(frames, session.anchors[0].text)
        _CHOSEN[key] = (choose_qr_call(measured), measured)
    return _CHOSEN[key]


class PlainPeer:
    """The plain OpenCV way for a session's anchors and camera: `pose(image)` -> world_from_camera or None."""

    def __init__(self, anchors, camera, qr_call: str = "QRCodeDetector.detectAndDecodeMulti"):
        from tracking.anchors.model import build_models

        self.camera = camera
        self.models = build_models(list(anchors))
        p = cv2.aruco.DetectorParameters()
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.det = {}
        for m in self.models:
            if m.anchor_kind.detector != "qr" and m.spec.dictionary_id not in self.det:
                self.det[m.spec.dictionary_id] = cv2.aruco.ArucoDetector(aruco_dictionary(m.spec.dictionary), p)
        self.qr_call = qr_call
        make, self._qr = QR_CALLS[qr_call]
        self.qr = make() if any(m.anchor_kind.detector == "qr" for m in self.models) else None

    def pose(self, image: np.ndarray) -> np.ndarray | None:
        from tracking.anchors.model import square_corners
        from tracking.poses import from_rvec_tvec, invert

        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        obj, img = [], []
        for d, det in self.det.items():
            corners, ids, _ = det.detectMarkers(gray)
            if ids is None:
                continue
            for c, mid in zip(corners, ids.ravel()):
                for m in self.models:
                    if m.anchor_kind.detector != "qr" and m.spec.dictionary_id == d and int(mid) in m.markers:
                        obj.append(m.to_world(m.markers[int(mid)]))
                        img.append(c.reshape(4, 2))
        if self.qr is not None:
            for text, p in self._qr(self.qr, gray):
                for m in self.models:
                    if m.anchor_kind.detector == "qr" and m.spec.text == text:
                        obj.append(m.to_world(square_corners(m.spec.length)))
                        img.append(p)
        if not obj:
            return None
        ok, rvec, tvec = cv2.solvePnP(np.concatenate(obj).astype(np.float64), np.concatenate(img).astype(np.float64),
                                      self.camera.K, self.camera.dist)
        return invert(from_rvec_tvec(rvec, tvec)) if ok else None


class FilteredPeer:
    """PlainPeer's poses through arapp's PoseFilter (same class, default parameters as AnchorTracker)."""

    def __init__(self):
        from tracking.anchors.filter import PoseFilter

        self.filter = PoseFilter()

    def update(self, pose: np.ndarray | None, t: float) -> np.ndarray | None:
        """Filtered pose for this frame's plain pose (None when the plain way found nothing)."""
        if pose is None:
            return None
        return self.filter.update(pose, t, distance=float(np.linalg.norm(pose[:3, 3])))
