"""Tracking judged on real footage, which has no ground truth: arapp's pose against plain OpenCV in the same frame.

For every frame where plain OpenCV (cv2.aruco.ArucoDetector with CORNER_REFINE_SUBPIX, or
cv2.aruco.CharucoDetector) sees an anchor, the anchor's detected corners are the reference: arapp's
world_from_camera projects the same object points with cv2.projectPoints, and the distance to OpenCV's
corners is arapp's corner error. OpenCV's own PnP fit to those corners (cv2.solvePnP, IPPE) gives the
floor any pose reaches on them: its reprojection error. The signed mean offset (arapp minus OpenCV, x and
y) and its outward part (along each corner's direction from the anchor's centre) are the signature of a
systematic bias; the worst frame's largest corner distance, as a fraction of the image width, says how
far off the model is ever drawn.

The object points are written here from OpenCV's own board objects and the square-marker rule
(cv2.SOLVEPNP_IPPE_SQUARE's corner order: (-l/2, l/2), (l/2, l/2), (l/2, -l/2), (-l/2, -l/2)), not taken
from arapp's anchor models. Pixels are distorted image pixels (pixel centres at integers), lengths metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary
from tracking.camera import Camera
from tracking.fusion import Tracker
from tracking.poses import invert, to_rvec_tvec
from tracking.anchors.kinds import AnchorSpec

# the Done-when goals of issue 25 (BENCHMARKS.md's real-video table applies them)
GOAL_TRACKED = 0.90          # tracked fraction of the frames where plain OpenCV sees the anchor
GOAL_MEDIAN_FACTOR = 2.0     # median corner error <= this times OpenCV's own fit's ...
GOAL_MEDIAN_WIDTH = 0.001    # ... or this fraction of the image width, whichever is larger
GOAL_WORST_WIDTH = 0.03      # no frame's corners further than this fraction of the width


def _square(length: float) -> np.ndarray:
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


class OpenCVReference:
    """Plain OpenCV's view of one anchor: its detected corners (pixels) and their object points (world)."""

    def __init__(self, spec: AnchorSpec, inverted: bool = False):
        self.spec = spec
        self.kind = spec.kind
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.detectInvertedMarker = bool(inverted)   # a board printed white on black
        d = aruco_dictionary(spec.dictionary)
        self.square = self.kind == "aruco"
        if self.kind == "aruco":
            self.det = cv2.aruco.ArucoDetector(d, params)
        elif self.kind == "aruco_board":
            ids = np.array(spec.marker_ids(), np.int32)
            self.board = cv2.aruco.GridBoard((spec.markers_x, spec.markers_y), spec.marker_length,
                                             spec.separation, d, ids)
            self.det = cv2.aruco.ArucoDetector(d, params)
        elif self.kind == "charuco":
            n = (spec.squares_x * spec.squares_y) // 2
            ids = np.arange(spec.first_id, spec.first_id + n, dtype=np.int32)
            self.board = cv2.aruco.CharucoBoard((spec.squares_x, spec.squares_y), spec.square_length,
                                                spec.marker_length, d, ids)
            self.board.setLegacyPattern(bool(spec.params.get("legacy", False)))
            self.det = cv2.aruco.CharucoDetector(self.board, cv2.aruco.CharucoParameters(), params)
        else:
            raise ValueError(f"no OpenCV reference for {self.kind!r} anchors (aruco, aruco_board, charuco)")
        self.world_from_anchor = np.asarray(spec.world_from_anchor, float)

    def corners(self, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(world points (N,3), OpenCV's pixels (N,2)) of the anchor in `gray`, or None when OpenCV does not
        see it (a ChArUco board: fewer than 4 chessboard corners)."""
        if self.kind == "charuco":
            cc, ci, _, _ = self.det.detectBoard(gray)
            if ci is None or len(ci) < 4:
                return None
            obj = np.asarray(self.board.getChessboardCorners(), float)[ci.ravel()]
            img = cc.reshape(-1, 2).astype(float)
        else:
            corners, ids, _ = self.det.detectMarkers(gray)
            if ids is None:
                return None
            if self.kind == "aruco":
                hit = [c for c, i in zip(corners, ids.ravel()) if int(i) == self.spec.id]
                if len(hit) != 1:   # absent, or seen twice (ambiguous)
                    return None
                obj, img = _square(self.spec.length), hit[0].reshape(4, 2).astype(float)
            else:
                obj, img = self.board.matchImagePoints(corners, ids)
                if obj is None or len(obj) < 4:
                    return None
                obj, img = obj.reshape(-1, 3).astype(float), img.reshape(-1, 2).astype(float)
        world = obj @ self.world_from_anchor[:3, :3].T + self.world_from_anchor[:3, 3]
        return world, img


def opencv_fit_errors(camera: Camera, world: np.ndarray, img: np.ndarray, square: bool) -> np.ndarray:
    """Reprojection errors (N,) in pixels of OpenCV's own PnP fit (IPPE_SQUARE for one square marker, else
    IPPE; all anchors here are planar) to these correspondences."""
    flag = cv2.SOLVEPNP_IPPE_SQUARE if square and len(world) == 4 else cv2.SOLVEPNP_IPPE
    obj = world
    if not square:
        # IPPE needs z = 0 object points: express them in the plane's own frame (an exact rigid change)
        c = world.mean(axis=0)
        _, _, vt = np.linalg.svd(world - c)
        obj = np.c_[(world - c) @ vt[:2].T, np.zeros(len(world))]
    elif flag == cv2.SOLVEPNP_IPPE_SQUARE:
        obj = _square(float(np.linalg.norm(world[1] - world[0])))
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist, flags=flag)
    if not ok:
        return np.full(len(world), np.nan)
    px, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
    return np.linalg.norm(px.reshape(-1, 2) - img, axis=1)


@dataclass
class FrameCheck:
    """One frame where OpenCV sees the anchor. Pixels; `tracked` False: arapp gave no pose (errors empty)."""

    index: int
    tracked: bool
    opencv_errors: np.ndarray                 # (N,) OpenCV's own fit
    errors: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (N,) arapp's pose against OpenCV's corners
    offset: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))   # mean (dx, dy), arapp - OpenCV
    outward: float = float("nan")             # mean offset along the corners' directions from the centre


def check_pose(camera: Camera, world_from_camera: np.ndarray, world: np.ndarray, img: np.ndarray):
    """(errors (N,), mean signed offset (2,), mean outward offset) of the world points projected with
    cv2.projectPoints under `world_from_camera`, against the detected pixels `img` (N,2)."""
    rvec, tvec = to_rvec_tvec(invert(world_from_camera))
    px, _ = cv2.projectPoints(world.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
    d = px.reshape(-1, 2) - img
    centre = img.mean(axis=0)
    radial = img - centre
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-9)
    return np.linalg.norm(d, axis=1), d.mean(axis=0), float(np.mean(np.sum(d * radial, axis=1)))


def check_run(camera: Camera, reference: OpenCVReference, poses: Iterable[tuple[int, np.ndarray, np.ndarray | None]]
              ) -> list[FrameCheck]:
    """FrameChecks of (frame index, grey image, arapp's world_from_camera or None) triples, for the frames
    where OpenCV sees the anchor."""
    out = []
    for index, gray, pose in poses:
        seen = reference.corners(gray)
        if seen is None:
            continue
        world, img = seen
        fit = opencv_fit_errors(camera, world, img, reference.square)
        if pose is None:
            out.append(FrameCheck(index, False, fit))
            continue
        err, off, outward = check_pose(camera, pose, world, img)
        out.append(FrameCheck(index, True, fit, err, off, outward))
    return out


def track_frames(camera: Camera, anchors: list[AnchorSpec], frames: Iterable[tuple[float, np.ndarray]],
                 slam: bool = True, **settings) -> Iterator[tuple[int, np.ndarray, np.ndarray | None]]:
    """(index, grey image, world_from_camera or None) of arapp's Tracker over (t seconds, BGR image) frames,
    as `arapp replay` runs it (`slam` False: `--no-slam`); mapping inline (threaded=False) so a run repeats."""
    settings.setdefault("threaded", False)
    tracker = Tracker(camera, anchors, slam=slam, **settings)
    try:
        for i, (t, image) in enumerate(frames):
            res = tracker.process(image, t)
            gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            yield i, gray, res.world_from_camera
    finally:
        tracker.close()


@dataclass
class RealSummary:
    """A sequence's figures (pixels unless said): see the module docstring."""

    name: str
    width: int
    seen: int                 # frames (x anchors run) where plain OpenCV sees the anchor
    tracked: int              # of those, frames arapp gave a pose for
    median: float             # arapp's corner error, median over all corners of tracked frames
    p95: float
    opencv_median: float      # OpenCV's own fit
    opencv_p95: float
    offset: np.ndarray        # mean signed (dx, dy) over tracked frames
    outward: float
    worst: float              # the worst frame's largest corner distance
    worst_frame: int = -1

    @property
    def tracked_fraction(self) -> float:
        return self.tracked / self.seen if self.seen else float("nan")

    @property
    def median_goal(self) -> float:
        return max(GOAL_MEDIAN_FACTOR * self.opencv_median, GOAL_MEDIAN_WIDTH * self.width)

    @property
    def worst_fraction(self) -> float:
        return self.worst / self.width

    def failures(self) -> list[str]:
        """The Done-when goals this sequence misses, in words ([] = all met)."""
        out = []
        if not self.seen:
            return ["plain OpenCV sees the anchor in no frame"]
        if self.tracked_fraction < GOAL_TRACKED:
            out.append(f"tracked {self.tracked_fraction:.0%} of {self.seen} frames (goal {GOAL_TRACKED:.0%})")
        if not self.median <= self.median_goal:
            out.append(f"median corner error {self.median:.2f} px > {self.median_goal:.2f} px")
        if not self.worst_fraction <= GOAL_WORST_WIDTH:
            out.append(f"frame {self.worst_frame}: corners {self.worst_fraction:.1%} of the width away "
                       f"(goal {GOAL_WORST_WIDTH:.0%})")
        return out


def summarise(name: str, width: int, checks: list[FrameCheck]) -> RealSummary:
    tracked = [c for c in checks if c.tracked]
    err = np.concatenate([c.errors for c in tracked]) if tracked else np.zeros(0)
    fit = np.concatenate([c.opencv_errors for c in checks]) if checks else np.zeros(0)
    fit = fit[np.isfinite(fit)]
    pct = lambda a, q: float(np.percentile(a, q)) if len(a) else float("nan")  # noqa: E731
    worst = max(tracked, key=lambda c: float(c.errors.max()), default=None)
    return RealSummary(
        name, int(width), len(checks), len(tracked), pct(err, 50), pct(err, 95), pct(fit, 50), pct(fit, 95),
        np.mean([c.offset for c in tracked], axis=0) if tracked else np.full(2, np.nan),
        float(np.mean([c.outward for c in tracked])) if tracked else float("nan"),
        float(worst.errors.max()) if worst is not None else float("nan"),
        worst.index if worst is not None else -1)


@dataclass
class RealSequence:
    """A real sequence to measure: `frames()` yields (t seconds, BGR image); `runs` are anchor lists, each
    run separately (the first anchor of each is the world and the one judged; several runs when the
    anchors' places relative to each other are unknown, e.g. tags on a wall: one run per tag);
    `inverted`: the print is white on black (OpenCV's reference reads it so)."""

    name: str
    camera: Camera
    frames: Callable[[], Iterable[tuple[float, np.ndarray]]]
    runs: list[list[AnchorSpec]]
    inverted: bool = False
    note: str = ""


def measure(seq: RealSequence, slam: bool = True, **settings) -> RealSummary:
    """arapp (Tracker, with or without SLAM) against plain OpenCV on one sequence, all runs pooled."""
    checks: list[FrameCheck] = []
    for anchors in seq.runs:
        ref = OpenCVReference(anchors[0], inverted=seq.inverted)
        checks += check_run(seq.camera, ref, track_frames(seq.camera, anchors, seq.frames(), slam=slam, **settings))
    return summarise(seq.name, seq.camera.width, checks)


def video_frames(path, fps: float | None = None) -> Iterator[tuple[float, np.ndarray]]:
    """(t, BGR image) of a video file at frame / fps seconds (the video's own fps unless given)."""
    cap = cv2.VideoCapture(str(path))
    try:
        rate = fps or cap.get(cv2.CAP_PROP_FPS) or 30.0
        i = 0
        while True:
            ok, img = cap.read()
            if not ok:
                return
            yield i / rate, img
            i += 1
    finally:
        cap.release()


def photo_frames(paths, interval: float = 1.0) -> Iterator[tuple[float, np.ndarray]]:
    """(t, BGR image) of photos taken one after another, `interval` seconds apart (a second: far more than
    the anchor filter's gap, so each photo is measured on its own, not smoothed with the one before)."""
    for i, p in enumerate(paths):
        img = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if img is None:
            raise FileNotFoundError(f"{p}: not an image OpenCV can read")
        yield i * interval, img
