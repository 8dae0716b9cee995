"""A camera calibration in steps, for the GUI's wizard (no Qt here).

The user prints a ChArUco board (`write_board_sheet`), shows it to the
camera, and `CalibrationSession.feed` looks at each frame: board corners found
(drawn on the view by `draw_feedback`), the view kept or why not (no board,
blurred, near-duplicate), the image coverage (a grid of cells that kept
views' corners reached) and the tilt coverage (the board seen facing the
camera and tilted towards each of four sides). `solve` runs
tracking.calibration.solve (cv2.calibrateCamera) and gives the RMS
reprojection error with a verdict. Lengths in metres, pixels with centres at
integers.

The board is the one `arapp calibrate` expects by default: 7 x 5 squares of
30 mm, 22 mm DICT_5X5_100 markers (fits an A4 page in landscape).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from tracking.calibration import BoardSpec, CalibrationResult, ViewCollector, solve
from tracking.calibration_quality import CORNER_FRACTION, CORNERS, missing_corners
from tracking.default_intrinsics import estimated_camera
from tracking.errors import CalibrationError
from tracking.printables import write_sheet
from tracking.anchors.kinds import AnchorSpec

DEFAULT_BOARD = BoardSpec("charuco", 7, 5, 0.03, 0.022, "DICT_5X5_100")

# The board's tilt relative to the image plane, binned: facing (under FACING_DEG) and tilted (over
# TILTED_DEG) towards one of four sides. Views between the two count for the image coverage only.
FACING_DEG = 15.0
TILTED_DEG = 20.0
TILT_BINS = ("facing", "left", "right", "top", "bottom")

# Verdict thresholds on the RMS reprojection error (pixels): under GOOD_RMS_PX a webcam calibration is
# as good as its corners allow; over USABLE_RMS_PX the board was blurred, bent or misprinted.
GOOD_RMS_PX = 0.5
USABLE_RMS_PX = 1.0
GOOD_COVERAGE = 0.5


def board_anchor(board: BoardSpec = DEFAULT_BOARD) -> AnchorSpec:
    """The board as a `charuco` anchor (what tracking.printables prints)."""
    return AnchorSpec(kind="charuco", dictionary=board.dictionary, squares_x=board.squares_x,
                      squares_y=board.squares_y, square_length=board.square_length,
                      marker_length=board.marker_length, first_id=0)


def write_board_sheet(folder: str | Path, board: BoardSpec = DEFAULT_BOARD, page: str = "A4",
                      dpi: float = 300.0) -> list[Path]:
    """The board to print at true scale: calibration_board.png / .pdf (and .anchors.json) in `folder`."""
    return write_sheet(board_anchor(board), folder, "calibration_board", dpi=dpi, page=page)


def describe_board(board: BoardSpec = DEFAULT_BOARD) -> str:
    return (f"ChArUco {board.squares_x} x {board.squares_y} squares of {board.square_length * 1000:g} mm, "
            f"{board.marker_length * 1000:g} mm {board.dictionary} markers")


@dataclass
class Feedback:
    """What one frame gave: `verdict` ('kept', 'no board', 'blurred', 'duplicate', 'full'), the board
    corners found (N,2 pixels) or None, views kept so far, image and tilt coverage (0..1), and the tilt
    bin of this view (None when not kept or between bins): the side of the image where the board is
    nearer the camera, or 'facing'."""

    verdict: str
    corners: np.ndarray | None
    kept: int
    coverage: float
    tilt_coverage: float
    tilt_bin: str | None = None
    image: np.ndarray | None = field(default=None, repr=False)  # the frame looked at (not copied)


@dataclass
class SessionResult:
    """A solved calibration with its verdict: `quality` 'good', 'usable' or 'poor', `advice` one line."""

    result: CalibrationResult
    quality: str
    advice: str

    @property
    def camera(self):
        return self.result.camera

    @property
    def rms(self) -> float:
        return self.result.rms


def corners_wanted(missing: list[str]) -> str:
    """'the top-left and bottom-right corners of the image' for missing corner regions (CORNERS names)."""
    names = " and ".join(missing) if len(missing) <= 2 else ", ".join(missing[:-1]) + " and " + missing[-1]
    return f"the {names} corner{'s' if len(missing) > 1 else ''} of the image"


def verdict(rms: float, coverage: float, tilt_coverage: float, missing: list[str] | None = None) -> tuple[str, str]:
    """('good' | 'usable' | 'poor', advice) for a solved calibration; `missing`: image corner regions no
    view reached (tracking.calibration_quality)."""
    missing = list(missing or [])
    if rms > USABLE_RMS_PX:
        return "poor", (f"RMS {rms:.2f} px is high: keep the sheet flat, well lit and sharp, check it was "
                        "printed at 100 %, and calibrate again")
    if rms <= GOOD_RMS_PX and coverage >= GOOD_COVERAGE and tilt_coverage >= 0.6 and not missing:
        return "good", f"RMS {rms:.2f} px over {coverage * 100:.0f} % of the image: a good calibration"
    wanted = []
    if missing:
        wanted.append(f"near {corners_wanted(missing)} (the k3 distortion term is held fixed without them)")
    elif coverage < GOOD_COVERAGE:
        wanted.append("near the image edges and corners")
    if tilt_coverage < 0.6:
        wanted.append("tilted towards each side")
    more = f"; for better accuracy add views {' and '.join(wanted)}" if wanted else ""
    return "usable", f"RMS {rms:.2f} px: usable{more}"


class CalibrationSession:
    """Collects views of `board` frame by frame and solves. `min_views` are needed to solve; after
    `max_views` kept views further frames are reported 'full'."""

    def __init__(self, board: BoardSpec = DEFAULT_BOARD, min_views: int = 8, max_views: int = 40,
                 min_sharpness: float = 30.0):
        self.board = board
        self.min_views, self.max_views = int(min_views), int(max_views)
        self.collector = ViewCollector(board, min_sharpness=min_sharpness)
        self.tilts: dict[str, int] = {b: 0 for b in TILT_BINS}
        self.frames_seen = 0

    @property
    def kept(self) -> int:
        return len(self.collector.views)

    @property
    def ready(self) -> bool:
        return self.kept >= self.min_views

    @property
    def coverage(self) -> float:
        return self.collector.coverage

    @property
    def cells(self) -> np.ndarray:
        """Image coverage grid (rows, cols) of booleans, True where a kept view had a corner."""
        return self.collector.cells

    @property
    def missing_corners(self) -> list[str]:
        """The image corner regions (tracking.calibration_quality.CORNERS) no kept view has reached yet;
        all four are needed before the k3 distortion term is estimated."""
        c = self.collector
        if not c.views:
            return list(CORNERS)
        return missing_corners([v.img for v in c.views], c.width, c.height)

    @property
    def tilt_coverage(self) -> float:
        return sum(1 for n in self.tilts.values() if n) / len(TILT_BINS)

    def feed(self, image: np.ndarray, name: str = "") -> Feedback:
        """Consider one frame (BGR or gray); see Feedback."""
        self.frames_seen += 1
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if self.kept >= self.max_views:
            found = self.collector.detector.detect(gray)
            return Feedback("full", None if found is None else found[1], self.kept, self.coverage,
                            self.tilt_coverage, None, image)
        verdict_ = self.collector.add(gray, name or f"frame {self.frames_seen - 1}")
        corners, tilt = None, None
        if verdict_ == "kept":
            view = self.collector.views[-1]
            corners = view.img
            tilt = self._tilt_bin(view.obj, view.img, gray.shape[1], gray.shape[0])
            if tilt is not None:
                self.tilts[tilt] += 1
        elif verdict_ != "no board":
            found = self.collector.detector.detect(gray)
            corners = None if found is None else found[1]
        return Feedback(verdict_, corners, self.kept, self.coverage, self.tilt_coverage, tilt, image)

    @staticmethod
    def _tilt_bin(obj: np.ndarray, img: np.ndarray, width: int, height: int) -> str | None:
        """The tilt bin of a board view, from its pose under the estimated camera (the tilt angle barely
        depends on the focal length guess at these angles; it only sorts views into bins)."""
        cam = estimated_camera(width, height)
        ok, rvec, _ = cv2.solvePnP(obj.astype(np.float64), img.astype(np.float64), cam.K, None)
        if not ok:
            return None
        R, _ = cv2.Rodrigues(rvec)
        n = R[:, 2]  # the board's normal in the camera frame (x right, y down, z forward)
        tilt = np.degrees(np.arccos(min(1.0, abs(n[2]))))
        if tilt < FACING_DEG:
            return "facing"
        if tilt < TILTED_DEG:
            return None
        nx, ny = (n[0], n[1]) if n[2] < 0 else (-n[0], -n[1])  # the normal pointing back at the camera
        if abs(nx) >= abs(ny):
            return "left" if nx > 0 else "right"
        return "top" if ny > 0 else "bottom"

    def solve(self) -> SessionResult:
        """cv2.calibrateCamera on the kept views (raises CalibrationError with advice when too few)."""
        c = self.collector
        if not c.views:
            raise CalibrationError("no view of the board was kept yet; show the printed board to the camera")
        res = solve(c.views, c.width, c.height, c.coverage, min_views=self.min_views)
        quality, advice = verdict(res.rms, c.coverage, self.tilt_coverage, res.missing_corners)
        return SessionResult(res, quality, advice)


def collect_from_source(source, session: CalibrationSession, every: int = 1,
                        cancel: threading.Event | None = None,
                        progress: Callable[[int, int | None, Feedback], None] | None = None) -> int:
    """Feed every `every`-th frame of a tracking.sources source to `session` until the source ends, the
    session is full or `cancel` is set; `progress(frame index, frame count or None, feedback)` after each
    frame looked at. Returns the number of frames looked at."""
    total = getattr(source, "frame_count", None)
    looked = 0
    for frame in source:
        if cancel is not None and cancel.is_set():
            break
        if frame.index % max(1, every):
            continue
        fb = session.feed(frame.image, f"frame {frame.index}")
        looked += 1
        if progress is not None:
            progress(frame.index, total, fb)
        if fb.verdict == "full":
            break
    return looked


def draw_feedback(image: np.ndarray, session: CalibrationSession, fb: Feedback | None) -> np.ndarray:
    """A copy of the frame with the coverage grid shaded green where views reached, the image corner
    regions no view reached yet outlined in orange, and the board corners found in this frame (green
    when kept, yellow when seen but not kept)."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    h, w = out.shape[:2]
    cells = session.cells
    rows, cols = cells.shape
    shade = out.copy()
    for r in range(rows):
        for c in range(cols):
            if cells[r, c]:
                x0, y0 = int(c * w / cols), int(r * h / rows)
                x1, y1 = int((c + 1) * w / cols), int((r + 1) * h / rows)
                cv2.rectangle(shade, (x0, y0), (x1 - 1, y1 - 1), (0, 160, 0), -1)
    out = cv2.addWeighted(shade, 0.25, out, 0.75, 0)
    # the image corners no view has reached yet, outlined: the board must be shown there (k3 needs them)
    cw, ch = int(CORNER_FRACTION * w), int(CORNER_FRACTION * h)
    boxes = {"top-left": (0, 0), "top-right": (w - cw, 0), "bottom-left": (0, h - ch), "bottom-right": (w - cw, h - ch)}
    for name in session.missing_corners:
        x0, y0 = boxes[name]
        cv2.rectangle(out, (x0 + 2, y0 + 2), (x0 + cw - 3, y0 + ch - 3), (0, 200, 255), 2, cv2.LINE_AA)
    if fb is not None and fb.corners is not None:
        colour = (0, 220, 0) if fb.verdict == "kept" else (0, 220, 255)
        for x, y in np.asarray(fb.corners).reshape(-1, 2):
            cv2.circle(out, (int(round(x)), int(round(y))), 4, colour, 2, cv2.LINE_AA)
    return out
