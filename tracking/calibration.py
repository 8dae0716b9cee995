"""Camera calibration from views of a ChArUco board or a chessboard.

Views are collected one image at a time (`ViewCollector`): blurred views and
near-duplicates of views already kept are rejected, and the coverage of the
image by board corners is tracked. `solve` runs cv2.calibrateCamera,
drops views whose error stands out, and reports the RMS and per-view
errors. Lengths in metres, pixels with centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.anchors.kinds import AnchorSpec
from tracking.anchors.kinds.charuco import charuco_board
from tracking.camera import Camera
from tracking.errors import CalibrationError


@dataclass
class BoardSpec:
    """A calibration board. kind 'charuco' (squares_x, squares_y, square_length, marker_length, dictionary)
    or 'chessboard' (squares_x, squares_y, square_length; inner corners are (squares_x-1) x (squares_y-1))."""

    kind: str
    squares_x: int
    squares_y: int
    square_length: float
    marker_length: float | None = None
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self):
        if self.kind not in ("charuco", "chessboard"):
            raise CalibrationError(f"board kind must be 'charuco' or 'chessboard', got {self.kind!r}")
        if self.squares_x < 3 or self.squares_y < 3:
            raise CalibrationError(f"a calibration board needs at least 3x3 squares, got {self.squares_x}x{self.squares_y}")
        if self.square_length <= 0:
            raise CalibrationError("--square-length must be positive (metres)")
        if self.kind == "charuco":
            if self.marker_length is None or not 0 < self.marker_length < self.square_length:
                raise CalibrationError("a ChArUco board needs 0 < --marker-length < --square-length (metres)")
            if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
                raise CalibrationError(f"{self.dictionary!r} is not an OpenCV ArUco dictionary (e.g. DICT_5X5_100)")

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board, made as a `charuco` anchor's (tracking/anchors/kinds/charuco.py), ids from 0."""
        return charuco_board(AnchorSpec("charuco", dictionary=self.dictionary, squares_x=self.squares_x,
                                        squares_y=self.squares_y, square_length=self.square_length,
                                        marker_length=self.marker_length))

    def corner_count(self) -> int:
        return (self.squares_x - 1) * (self.squares_y - 1)


class BoardDetector:
    """Board corners in one image: (object points (N,3) metres, image points (N,2), ids (N,)) or None."""

    def __init__(self, board: BoardSpec, min_corners: int = 6):
        self.board = board
        self.min_corners = min_corners
        if board.kind == "charuco":
            self.cb = board.charuco_board()
            self.det = cv2.aruco.CharucoDetector(self.cb)
            self.chess = np.asarray(self.cb.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        else:
            nx, ny = board.squares_x - 1, board.squares_y - 1
            g = np.mgrid[0:nx, 0:ny].T.reshape(-1, 2)
            self.chess = np.c_[g * board.square_length, np.zeros(len(g))]

    def detect(self, gray: np.ndarray):
        if self.board.kind == "charuco":
            cc, ci, _, _ = self.det.detectBoard(gray)
            if ci is None or len(ci) < self.min_corners:
                # a board printed white-on-black (as some calibration tools print them): its chessboard
                # corners lie where they lie on the inverted image
                cc, ci, _, _ = self.det.detectBoard(cv2.bitwise_not(gray))
            if ci is None or len(ci) < self.min_corners:
                return None
            ci = ci.ravel()
            return self.chess[ci], cc.reshape(-1, 2).astype(np.float64), ci
        size = (self.board.squares_x - 1, self.board.squares_y - 1)
        ok, corners = cv2.findChessboardCornersSB(gray, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY)
        if not ok:
            return None
        return self.chess.copy(), corners.reshape(-1, 2).astype(np.float64), np.arange(len(self.chess))


def sharpness(gray: np.ndarray, pts: np.ndarray) -> float:
    """Variance of the Laplacian inside the board's bounding box (higher = sharper)."""
    x0, y0 = np.maximum(np.floor(pts.min(axis=0)).astype(int), 0)
    x1, y1 = np.ceil(pts.max(axis=0)).astype(int) + 1
    roi = gray[y0:y1, x0:x1]
    if roi.size < 16:
        return 0.0
    return float(cv2.Laplacian(roi, cv2.CV_64F).var())


@dataclass
class View:
    obj: np.ndarray
    img: np.ndarray
    ids: np.ndarray
    sharpness: float
    name: str = ""


@dataclass
class ViewCollector:
    """Keeps useful views: enough corners, sharp enough, not a near-duplicate of a kept view.

    min_sharpness: Laplacian-variance floor (blurred views are rejected below it).
    min_motion: a view whose common corners moved less than this fraction of the image diagonal (mean)
    from a kept view is a near-duplicate.
    """

    board: BoardSpec
    width: int = 0
    height: int = 0
    min_sharpness: float = 30.0
    min_motion: float = 0.03
    grid: tuple[int, int] = (8, 6)
    views: list[View] = field(default_factory=list)
    rejected: dict = field(default_factory=lambda: {"no board": 0, "blurred": 0, "duplicate": 0})

    def __post_init__(self):
        self.detector = BoardDetector(self.board)
        self.cells = np.zeros(self.grid[::-1], bool)

    def add(self, image: np.ndarray, name: str = "") -> str:
        """Consider one image; returns 'kept', 'no board', 'blurred' or 'duplicate'."""
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        h, w = gray.shape
        if not self.width:
            self.width, self.height = w, h
        elif (w, h) != (self.width, self.height):
            raise CalibrationError(f"{name or 'image'} is {w}x{h} but earlier views were {self.width}x{self.height}; "
                                   "calibrate one resolution at a time")
        found = self.detector.detect(gray)
        if found is None:
            self.rejected["no board"] += 1
            return "no board"
        obj, img, ids = found
        sharp = sharpness(gray, img)
        if sharp < self.min_sharpness:
            self.rejected["blurred"] += 1
            return "blurred"
        diag = np.hypot(w, h)
        for v in self.views:
            common, a, b = np.intersect1d(v.ids, ids, return_indices=True)
            if len(common) >= 0.8 * min(len(ids), len(v.ids)):
                if np.mean(np.linalg.norm(v.img[a] - img[b], axis=1)) < self.min_motion * diag:
                    self.rejected["duplicate"] += 1
                    return "duplicate"
        self.views.append(View(obj, img, ids, sharp, name))
        gx = np.clip((img[:, 0] / w * self.grid[0]).astype(int), 0, self.grid[0] - 1)
        gy = np.clip((img[:, 1] / h * self.grid[1]).astype(int), 0, self.grid[1] - 1)
        self.cells[gy, gx] = True
        return "kept"

    @property
    def coverage(self) -> float:
        """Fraction of the image's grid cells that contain a board corner in some kept view."""
        return float(self.cells.mean())


@dataclass
class CalibrationResult:
    camera: Camera
    rms: float
    per_view: list[float]
    used: list[int]
    dropped: list[int]
    coverage: float

    def report(self, names: list[str] | None = None) -> str:
        lines = [f"RMS reprojection error {self.rms:.3f} px over {len(self.used)} views; coverage "
                 f"{self.coverage * 100:.0f} % of the image",
                 f"fx {self.camera.fx:.2f}  fy {self.camera.fy:.2f}  cx {self.camera.cx:.2f}  cy {self.camera.cy:.2f}",
                 "dist " + " ".join(f"{d:.5f}" for d in self.camera.dist)]
        for i, e in zip(self.used, self.per_view):
            lines.append(f"  view {i:3d} {names[i] if names else '':>20s}  {e:.3f} px")
        for i in self.dropped:
            lines.append(f"  view {i:3d} {names[i] if names else '':>20s}  dropped (error stood out)")
        return "\n".join(lines)


MIN_VIEWS = 3  # fewest board views that determine fx, fy, cx, cy and five distortion terms


def solve(views: list[View], width: int, height: int, coverage: float = float("nan"), min_views: int = 5,
          flags: int = 0, outlier_factor: float = 3.0) -> CalibrationResult:
    """cv2.calibrateCamera on the views (k1 k2 p1 p2 k3); views whose RMS error exceeds `outlier_factor`
    times the median are dropped once and the solve repeated."""
    if min_views < MIN_VIEWS:
        raise CalibrationError(f"min_views is {min_views}; a calibration needs at least {MIN_VIEWS} views of the "
                               "board (intrinsics and distortion are not determined by fewer)")
    if len(views) < min_views:
        raise CalibrationError(f"only {len(views)} usable views of the board; need at least {min_views}. "
                               "Show the board at more positions and angles (tilted, near the image corners)")
    used = list(range(len(views)))
    dropped: list[int] = []
    for _ in range(2):
        obj = [views[i].obj.astype(np.float32).reshape(-1, 1, 3) for i in used]
        img = [views[i].img.astype(np.float32).reshape(-1, 1, 2) for i in used]
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, (width, height), None, None, flags=flags)
        per = []
        for o, p, r, t in zip(obj, img, rvecs, tvecs):
            proj, _ = cv2.projectPoints(o, r, t, K, dist)
            per.append(float(np.sqrt(np.mean(np.sum((proj - p) ** 2, axis=2)))))
        med = float(np.median(per))
        bad = [used[k] for k, e in enumerate(per) if e > outlier_factor * max(med, 0.05)]
        if not bad or dropped or len(used) - len(bad) < min_views:
            break
        dropped = bad
        used = [i for i in used if i not in bad]
    return CalibrationResult(Camera(K, dist.ravel()[:5], width, height), float(rms), per, used, dropped, coverage)
