"""The real photos of tests/data/realphotos and what OpenCV alone makes of them (the oracles), next to what
arapp makes of them. Used by tests/test_realphotos.py and benchmarks/bench_realphotos.py.

Cameras: the 640x480 OpenCV photos use the tutorial's camera file. The others have no calibration:
a focal length equal to the image width (SOURCES.md's guess) for the OpenCV photos; for the zxing QR
crops (240 px cut out of larger phone photos, so the width is not the field of view) the focal length
is estimated from the code's own four corners as the classic detector finds them (cv2.calibrateCamera,
one view, principal point at the centre, no distortion): the test's setup, not a parameter of arapp.
Lengths in metres, pixels in the photo's own coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracking.anchors import AnchorTracker
from tracking.anchors.detect import ArucoDetection
from tracking.anchors.model import build_models, square_corners
from tracking.camera import Camera
from tracking.poses import invert, rotation_angle
from tracking.recording.schema import parse_anchors

DATA = Path(__file__).resolve().parent / "data" / "realphotos"
DICT_FILE = DATA / "opencv" / "tutorial_dict.yml"

# photo -> the dictionary it was printed in (the tutorial's custom one for OpenCV's board tutorials)
ARUCO_PHOTOS = {
    "opencv/gbocclusion.jpg": str(DICT_FILE),
    "opencv/arucocalibration.jpg": str(DICT_FILE),
    "opencv/charucocalibration.jpg": str(DICT_FILE),
    "opencv/diamondmarkers.jpg": str(DICT_FILE),
    "opencv/singlemarkerssource.jpg": "DICT_6X6_250",
    "opencv/board.jpg": "DICT_6X6_250",  # no markers at all: nothing must be found
}
QR_PHOTOS = sorted(str(p.relative_to(DATA)) for p in (DATA / "zxing").glob("*.png"))
ALL_PHOTOS = sorted(ARUCO_PHOTOS) + QR_PHOTOS

# gbocclusion.jpg: the tutorial's 5x7 GridBoard, markers 100 and gaps 10 units (its scale is unknown:
# 0.04 m markers chosen, which scales positions only)
GB = {"kind": "aruco_board", "dictionary": str(DICT_FILE), "markers_x": 5, "markers_y": 7,
      "marker_length": 0.04, "separation": 0.004, "first_id": 0}


def opencv_dictionary(name: str) -> cv2.aruco.Dictionary:
    if name.startswith("DICT_"):
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    d = cv2.aruco.Dictionary()
    fs = cv2.FileStorage(name, cv2.FILE_STORAGE_READ)
    d.readDictionary(fs.root())
    fs.release()
    return d


def tutorial_camera() -> Camera:
    fs = cv2.FileStorage(str(DATA / "opencv" / "tutorial_camera_params.yml"), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat().ravel()
    fs.release()
    return Camera(K, dist, 640, 480)


def photo_camera(shape) -> Camera:
    """The tutorial camera for 640x480 photos, else focal length = image width, centred."""
    h, w = shape[:2]
    if (w, h) == (640, 480):
        return tutorial_camera()
    return Camera([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1]], None, w, h)


def opencv_markers(gray, dictionary: cv2.aruco.Dictionary):
    """OpenCV's detection (CORNER_REFINE_SUBPIX): list of (id, (4,2) corners)."""
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary, p).detectMarkers(gray)
    if ids is None:
        return []
    return [(int(i), c.reshape(4, 2).astype(np.float64)) for c, i in zip(corners, ids.ravel())]


@dataclass
class ArucoMatch:
    name: str
    opencv: list  # every id OpenCV finds (repeats included)
    opencv_single: set  # ids OpenCV finds exactly once
    arapp: set  # ids arapp finds
    worst_corner_fraction: float  # largest corner distance arapp-OpenCV over the marker side


def aruco_match(name: str) -> ArucoMatch:
    """arapp's markers (ArucoDetection with one anchor per id of the photo's dictionary) against OpenCV's."""
    dname = ARUCO_PHOTOS[name]
    gray = cv2.imread(str(DATA / name), cv2.IMREAD_GRAYSCALE)
    d = opencv_dictionary(dname)
    ocv = opencv_markers(gray, d)
    ids = [i for i, _ in ocv]
    single = {i: c for i, c in ocv if ids.count(i) == 1}
    n = d.bytesList.shape[0]
    an = parse_anchors([{"kind": "aruco", "dictionary": dname, "id": i, "length": 0.05,
                         "world_from_anchor": [[1, 0, 0, i], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}
                        for i in range(n)])
    obs = ArucoDetection(build_models(an), photo_camera(gray.shape)).detect(gray)
    found = {int(o.groups[0]): o.img for o in obs}
    worst = 0.0
    for i, c in found.items():
        if i in single:
            side = float(np.linalg.norm(np.diff(np.r_[single[i], single[i][:1]], axis=0), axis=1).mean())
            worst = max(worst, float(np.linalg.norm(c - single[i], axis=1).max()) / side)
    return ArucoMatch(name, ids, set(single), set(found), worst)


def pose_sigma(obj, img, rvec, tvec, K, dist, min_px: float = 0.5) -> tuple[float, float]:
    """(rotation deg, translation m) standard deviations of a PnP pose from its corner residuals
    (first-order, cv2.projectPoints' Jacobian), the corner noise taken as at least `min_px`."""
    proj, J = cv2.projectPoints(obj, rvec, tvec, K, dist)
    r = (proj.reshape(-1, 2) - img.reshape(-1, 2)).ravel()
    s2 = max(float(r @ r) / max(len(r) - 6, 1), min_px ** 2)
    cov = s2 * np.linalg.inv(J[:, :6].T @ J[:, :6])
    return float(np.degrees(np.sqrt(np.trace(cov[:3, :3])))), float(np.sqrt(np.trace(cov[3:, 3:])))


@dataclass
class PoseCheck:
    what: str
    markers: int
    opencv_markers: int
    position_diff: float  # m, camera_from_world translation, arapp - OpenCV
    rotation_diff_deg: float
    position_sigma: float
    rotation_sigma_deg: float


def _compare(what, T, rvec, tvec, obj, img, cam, markers, opencv_markers) -> PoseCheck:
    cfw = invert(T)
    R = cv2.Rodrigues(rvec)[0]
    rs, ts = pose_sigma(obj, img, rvec, tvec, cam.K, cam.dist)
    return PoseCheck(what, markers, opencv_markers, float(np.linalg.norm(cfw[:3, 3] - tvec.ravel())),
                     float(np.degrees(rotation_angle(cfw[:3, :3] @ R.T))), ts, rs)


def board_pose_check() -> PoseCheck:
    """gbocclusion.jpg: arapp's raw board pose against OpenCV's (matchImagePoints, solvePnP: IPPE for the
    start, then SOLVEPNP_ITERATIVE; the iterative solver alone converges to a wrong minimum on this photo)."""
    gray = cv2.imread(str(DATA / "opencv/gbocclusion.jpg"), cv2.IMREAD_GRAYSCALE)
    cam = tutorial_camera()
    rvec, tvec, obj, img, n = opencv_gb_pose(gray, cam)
    res = AnchorTracker(parse_anchors([GB]), cam, filter=False).process(gray, 0.0)
    assert res.raw_world_from_camera is not None, "arapp found no board pose in gbocclusion.jpg"
    return _compare("gbocclusion board", res.raw_world_from_camera, rvec, tvec, obj, img, cam, res.markers, n)


def opencv_gb_pose(gray, cam: Camera):
    """OpenCV's board pose of a gbocclusion-like view: (rvec, tvec, obj, img, markers) or None."""
    d = opencv_dictionary(str(DICT_FILE))
    ocv = opencv_markers(gray, d)
    if len(ocv) < 2:
        return None
    board = cv2.aruco.GridBoard((5, 7), GB["marker_length"], GB["separation"], d)
    corners = tuple(c.reshape(1, 4, 2).astype(np.float32) for _, c in ocv)
    obj, img = board.matchImagePoints(corners, np.array([[i] for i, _ in ocv], np.int32))
    _, rvec, tvec = cv2.solvePnP(obj, img, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
    _, rvec, tvec = cv2.solvePnP(obj, img, cam.K, cam.dist, rvec, tvec, useExtrinsicGuess=True)
    return rvec, tvec, obj, img, len(ocv)


def opencv_board_positions(video) -> np.ndarray:
    """(frames, 3) camera positions in the board frame by OpenCV, for each frame of a gbocclusion video."""
    cap = cv2.VideoCapture(str(video))
    cam = tutorial_camera()
    out = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        rvec, tvec, *_ = opencv_gb_pose(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), cam)
        out.append((-cv2.Rodrigues(rvec)[0].T @ tvec).ravel())
    cap.release()
    return np.array(out)


def single_marker_checks() -> list[PoseCheck]:
    """singlemarkerssource.jpg: each marker as a lone `aruco` anchor against IPPE_SQUARE on OpenCV's corners."""
    gray = cv2.imread(str(DATA / "opencv/singlemarkerssource.jpg"), cv2.IMREAD_GRAYSCALE)
    cam = photo_camera(gray.shape)
    L = 0.05
    obj = square_corners(L)
    out = []
    for mid, c in opencv_markers(gray, opencv_dictionary("DICT_6X6_250")):
        _, rvec, tvec = cv2.solvePnP(obj, c, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        an = parse_anchors([{"kind": "aruco", "dictionary": "DICT_6X6_250", "id": mid, "length": L}])
        res = AnchorTracker(an, cam, filter=False).process(gray, 0.0)
        assert res.raw_world_from_camera is not None, f"arapp found no pose for marker {mid}"
        out.append(_compare(f"marker {mid}", res.raw_world_from_camera, rvec, tvec, obj, c, cam, res.markers, 1))
    return out


def qr_focal(corners: np.ndarray, w: int, h: int) -> float:
    """Focal length (px) that makes the four symbol corners a square: one-view calibration, principal point
    at the centre, no distortion; kept within 0.5 to 10 image widths (a nearly frontal code says little)."""
    K0 = np.array([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1.0]])
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    _, K, _, _, _ = cv2.calibrateCamera([square_corners(1.0).astype(np.float32)],
                                        [corners.astype(np.float32).reshape(-1, 1, 2)], (w, h), K0, np.zeros(5),
                                        flags=flags)
    return float(np.clip(K[0, 0], 0.5 * w, 10 * w))


@dataclass
class QRCheck:
    name: str
    text: str
    classic: bool  # cv2.QRCodeDetector decodes the code's text
    arapp: bool  # arapp gives a pose with the code as its anchor
    ms: float = 0.0  # arapp's time for the photo (one frame: search, decode, pose)


def qr_anchor_check(name: str) -> QRCheck:
    """One zxing photo: does the classic detector decode its text, does arapp make it an anchor pose."""
    gray = cv2.imread(str(DATA / name), cv2.IMREAD_GRAYSCALE)
    text = (DATA / name).with_suffix(".txt").read_text(encoding="utf-8")
    h, w = gray.shape
    ok, texts, points, _ = cv2.QRCodeDetector().detectAndDecodeMulti(gray)
    classic = bool(ok) and text in texts
    if classic:
        f = qr_focal(points[list(texts).index(text)], w, h)
    else:
        f = float(w)
    cam = Camera([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], None, w, h)
    tracker = AnchorTracker(parse_anchors([{"kind": "qr", "text": text, "length": 0.05}]), cam, filter=False)
    res = tracker.process(gray, 0.0)
    return QRCheck(name, text, classic, res.raw_world_from_camera is not None and res.anchors_seen == [0], res.ms)
