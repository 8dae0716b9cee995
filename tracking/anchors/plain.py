"""The plain OpenCV way to a camera pose from the anchors (the benchmarks' baseline), and to_gray."""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.detect import detector_parameters
from tracking.anchors.dictionaries import aruco_dictionary
from tracking.anchors.model import build_models, square_corners
from tracking.camera import Camera
from tracking.poses import from_rvec_tvec, invert
from tracking.anchors.kinds import AnchorSpec


def to_gray(image: np.ndarray) -> np.ndarray:
    """uint8 gray from a gray or BGR(A) image."""
    if image.ndim == 2:
        return image
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)



class _Plain:
    """Cached detectors for plain_opencv_pose."""

    def __init__(self, anchors, camera):
        self.models = build_models(list(anchors))
        params = detector_parameters()
        self.det = {}
        for m in self.models:
            if m.anchor_kind.detector != "qr" and m.spec.dictionary_id not in self.det:
                self.det[m.spec.dictionary_id] = cv2.aruco.ArucoDetector(aruco_dictionary(m.spec.dictionary), params)
        self.qr = cv2.QRCodeDetector() if any(m.anchor_kind.detector == "qr" for m in self.models) else None


_PLAIN_CACHE: dict = {}


def plain_opencv_pose(anchors: list[AnchorSpec], camera: Camera, image: np.ndarray) -> np.ndarray | None:
    """The plain OpenCV way, the benchmark's baseline: world_from_camera (4x4) or None.

    Per frame: ArucoDetector.detectMarkers with CORNER_REFINE_SUBPIX (QR codes: QRCodeDetector
    detectAndDecodeMulti with matching text), every detected corner of every anchor into one
    cv2.solvePnP (SOLVEPNP_ITERATIVE) with camera.K and camera.dist; no filtering, no outlier handling.
    """
    key = (id(anchors), id(camera))
    plain = _PLAIN_CACHE.get(key)
    if plain is None or plain.models[0].spec is not anchors[0]:
        _PLAIN_CACHE.clear()
        plain = _PLAIN_CACHE[key] = _Plain(anchors, camera)
    gray = to_gray(image)
    obj, img = [], []
    for d, det in plain.det.items():
        corners, ids, _ = det.detectMarkers(gray)
        if ids is None:
            continue
        for c, mid in zip(corners, ids.ravel()):
            for m in plain.models:
                if m.anchor_kind.detector != "qr" and m.spec.dictionary_id == d and int(mid) in m.markers:
                    obj.append(m.to_world(m.markers[int(mid)]))
                    img.append(c.reshape(4, 2))
    if plain.qr is not None:
        ok, texts, points, _ = plain.qr.detectAndDecodeMulti(gray)
        if ok:
            for text, p in zip(texts, points):
                for m in plain.models:
                    if m.anchor_kind.detector == "qr" and m.spec.text == text:
                        obj.append(m.to_world(square_corners(m.spec.length)))
                        img.append(p.reshape(4, 2))
    if not obj:
        return None
    obj = np.concatenate(obj).astype(np.float64)
    img = np.concatenate(img).astype(np.float64)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist)
    if not ok:
        return None
    return invert(from_rvec_tvec(rvec, tvec))
