"""Benchmark: arapp against plain OpenCV on real footage nobody on this project filmed (tests/data/realvideo).

No ground truth: in every frame where plain OpenCV sees the anchor (ArucoDetector with CORNER_REFINE_SUBPIX,
or CharucoDetector), arapp's pose (the Tracker, with SLAM and without: `arapp replay` and `--no-slam`)
projects the anchor's points with cv2.projectPoints onto OpenCV's detected corners; OpenCV's own PnP fit to
the same corners is the floor (tracking/evaluation_real.py). The sequences are tests/realvideo_data.py's.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import realvideo_data as rv  # noqa: E402
from tracking.evaluation_real import (GOAL_MEDIAN_FACTOR, GOAL_MEDIAN_WIDTH, GOAL_TRACKED,  # noqa: E402
                                      GOAL_WORST_WIDTH, measure)


def _row(seq, mode: str, s, seconds: float) -> str:
    fails = s.failures()
    if not s.seen:
        goals = "no frame seen by OpenCV"
    else:
        goals = "all met" if not fails else "; ".join(fails)
    off = f"({s.offset[0]:+.2f}, {s.offset[1]:+.2f})" if s.tracked else "-"
    return (f"| {seq.name} | {mode} | {s.seen} | {s.tracked_fraction:.0%} | {s.median:.2f} / {s.p95:.2f} | "
            f"{s.opencv_median:.2f} / {s.opencv_p95:.2f} | {off} | {s.outward:+.2f} | "
            f"{s.worst_fraction * 100:.2f} % | {seconds:.0f} | {goals} |")


def run(quick: bool = False) -> str:
    # quick: the first 150 frames of the videos (the photo sets are short already)
    limit = 150 if quick else None
    sequences = [rv.deepcharuco(limit), rv.caliscope(limit), rv.apriltag_clipboard(), rv.apriltag_room()]
    lines = ["## Real video: arapp against plain OpenCV", "",
             "Real footage with no ground truth (tests/data/realvideo/SOURCES.md). In every frame where plain "
             "OpenCV sees the anchor (`cv2.aruco.ArucoDetector` with CORNER_REFINE_SUBPIX, or `CharucoDetector`), "
             "arapp's pose from the same run of frames (the `Tracker` as `arapp replay` runs it, with SLAM and "
             "`--no-slam`; mapping inline) projects the anchor's points with `cv2.projectPoints`; the distance to "
             "OpenCV's detected corners is arapp's corner error. OpenCV's fit: `cv2.solvePnP` (IPPE) on those "
             "same corners, reprojected (the floor any pose reaches on them). Offset: arapp minus OpenCV, mean "
             "(dx, dy) over tracked frames; outward: its mean part along each corner's direction from the "
             "anchor's centre (a systematic bias shows in these two). Worst: the frame whose corners are furthest "
             "off, as a percentage of the image width. Tag sets whose places relative to each other are unknown "
             "run once per tag, each its own world, pooled; photo sets are taken a second apart, so every photo "
             "is measured on its own. Goals (issue 25): tracked >= "
             f"{GOAL_TRACKED:.0%} of OpenCV's frames, median <= {GOAL_MEDIAN_FACTOR:g} x OpenCV's fit or "
             f"{GOAL_MEDIAN_WIDTH * 100:g} % of the width (the larger), worst <= {GOAL_WORST_WIDTH:.0%} of the "
             "width." + (" Quick mode: first 150 video frames." if quick else ""), "",
             "| sequence | arapp | OpenCV frames | tracked | corner error median / p95 px | OpenCV fit median / "
             "p95 px | offset px | outward px | worst | s | goals |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for seq in sequences:
        for mode, slam in (("SLAM", True), ("--no-slam", False)):
            t0 = time.perf_counter()
            s = measure(seq, slam=slam)
            lines.append(_row(seq, mode, s, time.perf_counter() - t0))
    lines += ["", "About the outward column: OpenCV's CORNER_REFINE_SUBPIX (cornerSubPix on an L-shaped corner) "
              "puts a blurred square's corners inside the square. On the synthetic renderer and on an independent "
              "warpPerspective rendering with known corners, SUBPIX sits 0.1 to 0.5 px inward (more with more "
              "blur) while arapp's edge-fitted corners sit within 0.06 px; on the AprilTag sets, OpenCV's own "
              "edge-fitting refinement (CORNER_REFINE_APRILTAG, its near-constant shift of about +0.45 px in x and y aside) "
              "agrees with arapp's scale to 0.04 px. A positive outward figure of a few tenths is that bias of "
              "the reference, not of arapp.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
