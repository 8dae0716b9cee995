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
from tracking.anchors.kinds.charuco import charuco_board, is_legacy
from tracking.calibration_quality import (
    CORNERS,
    PARAMS,
    SPREAD_SIGMAS,
    estimate_error,
    free_params,
    image_corner_pixels,
    intrinsic_covariance,
    missing_corners,
    projection_spread,
)
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
    first_id: int = 0
    legacy: bool = False   # the ChArUco pattern of OpenCV before 4.6 (tracking/anchors/kinds/charuco.py)

    @classmethod
    def from_anchor(cls, spec: AnchorSpec, where: str = "anchors") -> "BoardSpec":
        """The board of a `charuco` anchor (an anchors file's block), e.g. what `arapp markers charuco` wrote."""
        if spec.kind != "charuco":
            raise CalibrationError(f"{where}: a {spec.kind} anchor is not a calibration board; calibrate with a "
                                   "charuco one (`arapp markers charuco` prints one and writes its anchors file)")
        return cls("charuco", spec.squares_x, spec.squares_y, spec.square_length, spec.marker_length, spec.dictionary,
                   spec.first_id, is_legacy(spec))

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
                                        marker_length=self.marker_length, first_id=self.first_id,
                                        params={"legacy": True} if self.legacy else {}))

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
    """A solved calibration. `std`: 1 sigma of each estimated parameter (tracking.calibration_quality.PARAMS
    names; from cv2.calibrateCameraExtended), `fixed`: distortion terms held at 0 by the coverage rule,
    `missing_corners`: image corner regions no view reached, `spread_centre_px` / `spread_corners_px`
    (CORNERS order): 2 sigma spread of where a ray lands, at the centre and the image corners, against
    `estimate_corners_px`, what the estimated camera is off by there; `refusal`: why the result is worse
    than the estimated camera (None when it is not)."""

    camera: Camera
    rms: float
    per_view: list[float]
    used: list[int]
    dropped: list[int]
    coverage: float
    std: dict = field(default_factory=dict)
    fixed: list[str] = field(default_factory=list)
    missing_corners: list[str] = field(default_factory=list)
    spread_centre_px: float = float("nan")
    spread_corners_px: list[float] = field(default_factory=list)
    estimate_corners_px: list[float] = field(default_factory=list)
    refusal: str | None = None

    def _pm(self, name: str, value: float, digits: int) -> str:
        if name in self.fixed:
            return f"{name} {value:.{digits}f} (fixed)"
        sd = self.std.get(name)
        return f"{name} {value:.{digits}f}" + (f" +/- {sd:.{digits}f}" if sd is not None else "")

    def report(self, names: list[str] | None = None) -> str:
        cam = self.camera
        lines = [f"RMS reprojection error {self.rms:.3f} px over {len(self.used)} views; coverage "
                 f"{self.coverage * 100:.0f} % of the image",
                 "  ".join(self._pm(n, v, 2) for n, v in zip(("fx", "fy", "cx", "cy"), (cam.fx, cam.fy, cam.cx, cam.cy))),
                 "dist " + "  ".join(self._pm(n, float(v), 5) for n, v in zip(("k1", "k2", "p1", "p2", "k3"), cam.dist))]
        if self.fixed:
            plural = "s" if len(self.missing_corners) > 1 else ""
            lines.append(f"{', '.join(self.fixed)} held fixed: no view reached the {', '.join(self.missing_corners)} "
                         f"corner{plural} of the image (show the board there to estimate {'it' if len(self.fixed) == 1 else 'them'})")
        if self.spread_corners_px:
            k = int(np.argmax(self.spread_corners_px))
            lines.append(f"projection uncertainty (2 sigma): {self.spread_centre_px:.2f} px at the centre, "
                         f"{self.spread_corners_px[k]:.2f} px at the {CORNERS[k]} corner (the estimated camera is "
                         f"off by ~{self.estimate_corners_px[k]:.0f} px there)")
        for i, e in zip(self.used, self.per_view):
            lines.append(f"  view {i:3d} {names[i] if names else '':>20s}  {e:.3f} px")
        for i in self.dropped:
            lines.append(f"  view {i:3d} {names[i] if names else '':>20s}  dropped (error stood out)")
        return "\n".join(lines)


MIN_VIEWS = 3  # fewest board views that determine fx, fy, cx, cy and five distortion terms
# held at 0 unless the views reach all four image corners (tracking.calibration_quality's coverage rule)
PARTIAL_COVERAGE_FLAGS = cv2.CALIB_FIX_K3


def solve(views: list[View], width: int, height: int, coverage: float = float("nan"), min_views: int = 5,
          flags: int | None = None, outlier_factor: float = 3.0, refuse: bool = True,
          guess: Camera | None = None) -> CalibrationResult:
    """cv2.calibrateCameraExtended on the views; views whose RMS error exceeds `outlier_factor` times the
    median are dropped once and the solve repeated.

    flags None: the coverage rule of tracking.calibration_quality (k1 k2 p1 p2 k3 when the views reach
    all four image corners, else k3 fixed at 0); an int: those cv2.CALIB_* flags. `guess`: a camera
    of this image size to start from (cv2.CALIB_USE_INTRINSIC_GUESS); the terms the rule fixes keep its values. With `refuse`,
    a result worse than the estimated camera (its `refusal`) raises CalibrationError saying which views
    to add."""
    if min_views < MIN_VIEWS:
        raise CalibrationError(f"min_views is {min_views}; a calibration needs at least {MIN_VIEWS} views of the "
                               "board (intrinsics and distortion are not determined by fewer)")
    if len(views) < min_views:
        raise CalibrationError(f"only {len(views)} usable views of the board; need at least {min_views}. "
                               "Show the board at more positions and angles (tilted, near the image corners)")
    used = list(range(len(views)))
    dropped: list[int] = []
    for _ in range(2):
        missing = missing_corners([views[i].img for i in used], width, height)
        run_flags = (PARTIAL_COVERAGE_FLAGS if missing else 0) if flags is None else flags
        K0, d0 = (None, None) if guess is None else (guess.K.copy(), guess.dist[:5].copy().reshape(-1, 1))
        if guess is not None:
            run_flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        obj = [views[i].obj.astype(np.float32).reshape(-1, 1, 3) for i in used]
        img = [views[i].img.astype(np.float32).reshape(-1, 1, 2) for i in used]
        rms, K, dist, rvecs, tvecs, std_in, _, _ = cv2.calibrateCameraExtended(
            obj, img, (width, height), K0, d0, flags=run_flags)
        per = _view_rms(obj, img, rvecs, tvecs, K, dist)
        med = float(np.median(per))
        bad = [used[k] for k, e in enumerate(per) if e > outlier_factor * max(med, 0.05)]
        if not bad or dropped or len(used) - len(bad) < min_views:
            break
        dropped = bad
        used = [i for i in used if i not in bad]
    dist5 = dist.ravel()[:5]
    free = free_params(run_flags)
    std = {PARAMS[i]: float(std_in.ravel()[i]) for i in free}
    fixed = [PARAMS[i] for i in (4, 5, 6, 7, 8) if i not in free]
    cov, _ = intrinsic_covariance(obj, img, rvecs, tvecs, K, dist5, run_flags)
    corners = image_corner_pixels(width, height)
    spread = SPREAD_SIGMAS * projection_spread(K, dist5, cov, free, np.vstack([corners, [(width - 1) / 2, (height - 1) / 2]]))
    est = estimate_error(width, height, corners)
    result = CalibrationResult(Camera(K, dist5, width, height), float(rms), per, used, dropped, coverage, std, fixed,
                               missing, float(spread[4]), [float(x) for x in spread[:4]], [float(x) for x in est])
    result.refusal = _refusal(result, spread, est)
    if result.refusal is not None and refuse:
        raise CalibrationError(result.refusal)
    return result


def _view_rms(obj: list[np.ndarray], img: list[np.ndarray], rvecs, tvecs, K: np.ndarray,
              dist: np.ndarray) -> list[float]:
    """Each view's RMS reprojection error (px) under the calibrated camera."""
    per = []
    for o, p, r, t in zip(obj, img, rvecs, tvecs):
        proj, _ = cv2.projectPoints(o, r, t, K, dist)
        per.append(float(np.sqrt(np.mean(np.sum((proj - p) ** 2, axis=2)))))
    return per


def _refusal(result: CalibrationResult, spread: np.ndarray, est: np.ndarray) -> str | None:
    """Why `result` is refused (which image corner a ray lands worse than the estimated camera's `est` px
    there, given the result's `spread` px, and which views to add), or None when every corner is better."""
    worse = [k for k in range(4) if not spread[k] < est[k]]
    if not worse:
        return None
    missing, std, used = result.missing_corners, result.std, result.used
    k = max(worse, key=lambda j: spread[j] / est[j])
    where = (f"add views with the board near the {', '.join(missing)} corner{'s' if len(missing) > 1 else ''} "
             "of the image" if missing else "add views with the board nearer the image corners, tilted, and "
             "at several distances")
    f_pct = 100 * SPREAD_SIGMAS * std.get("fx", 0.0) / max(result.camera.fx, 1e-9)
    return (f"calibration refused: from these {len(used)} views a ray at the {CORNERS[k]} image corner "
            f"lands within +/-{spread[k]:.0f} px (2 sigma; fx +/-{f_pct:.1f} %), worse than the estimated "
            f"camera's ~{est[k]:.0f} px there; {where}, then calibrate again")
