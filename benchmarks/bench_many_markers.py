"""Benchmark: many lone markers in view (a sheet of tags, tags round a room) on real photos, arapp against
plain OpenCV, CPU time per frame.

All the tags of a set are the anchors at once (as a user lists them in one anchors file). arapp: the Tracker
(`--no-slam`: the photos are a second apart, so each is measured on its own) over the photos in turn. Plain
(the way OpenCV's users run it): `ArucoDetector.detectMarkers` with the predefined dictionary and
CORNER_REFINE_SUBPIX, then `solvePnP` (IPPE_SQUARE) for every anchor tag seen. Both timed with
`time.process_time()` (every thread), taking turns on each photo, best of 3 passes over the set. `placed`:
photos in which arapp gave a pose / in which OpenCV saw an anchor tag. The photo sets are
tests/realvideo_data.py's (tests/data/realvideo/SOURCES.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _p in (str(ROOT), str(ROOT / "tests")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import realvideo_data as rv  # noqa: E402

PASSES = 3
# What a change did, measured in paired runs on the same machine (kept: a later run measures only the code of its day)
HISTORY = ("Each ArUco detector on the anchors' own codes (tracking/anchors/detect.py `anchor_codes`) and every "
           "anchor's markers edge-refined in one call (`ArucoDetection._refine`), 2026-12-07, paired runs on this "
           "2-core machine, this bench: apriltag_clipboard 111.5 -> 24.4 CPU ms per photo (2.75x -> 0.80x the plain "
           "way), apriltag_room 61.6 -> 30.1 (2.44x -> 1.54x); poses the same to the last digit on the real videos "
           "(bench realvideo) and the synthetic recordings tried (bench slam_cpu's errors).")


class PlainTags:
    """detectMarkers on each anchor dictionary (predefined, SUBPIX) and a solvePnP (IPPE_SQUARE) per anchor tag
    seen: `poses(gray)` -> the number of tags it placed."""

    def __init__(self, anchors, camera):
        from tracking.anchors.dictionaries import aruco_dictionary

        self.camera = camera
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self.lengths: dict[str, dict[int, float]] = {}
        for a in anchors:
            self.lengths.setdefault(a.dictionary, {})[int(a.id)] = float(a.length)
        self.det = {d: cv2.aruco.ArucoDetector(aruco_dictionary(d), params) for d in self.lengths}

    def poses(self, gray: np.ndarray) -> int:
        from tracking.anchors.model import square_corners

        placed = 0
        for d, det in self.det.items():
            corners, ids, _ = det.detectMarkers(gray)
            for c, mid in zip(corners, [] if ids is None else ids.ravel().tolist()):
                L = self.lengths[d].get(int(mid))
                if L is None:
                    continue
                ok, _r, _t = cv2.solvePnP(square_corners(L), c.reshape(4, 2).astype(np.float64), self.camera.K,
                                          self.camera.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
                placed += bool(ok)
        return placed


def measure(seq, limit: int | None) -> dict:
    """CPU ms per photo of arapp and of the plain way (best pass of PASSES), and the photos each placed."""
    from tracking.fusion import Tracker

    anchors = [run[0] for run in seq.runs]          # every tag of the set, the first the world
    frames = [img for _t, img in seq.frames()][:limit]
    grays = [cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) for f in frames]
    peer = PlainTags(anchors, seq.camera)
    best_ours, best_plain, placed_ours, placed_plain = np.inf, np.inf, 0, 0
    for _ in range(PASSES):
        ours = plain = 0.0
        placed_ours = placed_plain = 0
        with Tracker(seq.camera, anchors, slam=False) as tr:
            for i, (img, gray) in enumerate(zip(frames, grays)):
                c0 = time.process_time()
                placed_plain += peer.poses(gray) > 0
                c1 = time.process_time()
                res = tr.process(img, float(i))   # a second apart: each photo on its own
                c2 = time.process_time()
                plain += c1 - c0
                ours += c2 - c1
                placed_ours += res.world_from_camera is not None
        best_ours, best_plain = min(best_ours, ours), min(best_plain, plain)
    n = len(frames)
    return {"name": seq.name, "size": f"{seq.camera.width}x{seq.camera.height}", "photos": n, "tags": len(anchors),
            "ours": 1000 * best_ours / n, "plain": 1000 * best_plain / n, "placed": (placed_ours, placed_plain)}


def run(quick: bool = False) -> str:
    limit = 10 if quick else 30
    rows = [measure(s, limit) for s in (rv.apriltag_clipboard(), rv.apriltag_room())]
    out = ["## Many markers in view: real photos of tag sheets and rooms", "", __doc__.split("\n\n", 1)[1].strip()
           .replace("\n", " "), "",
           "| photo set | size | photos | anchor tags | CPU ms / photo arapp / plain | ratio | placed arapp / plain |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['name']} | {r['size']} | {r['photos']} | {r['tags']} | {r['ours']:.1f} / {r['plain']:.1f} "
                   f"| {r['ours'] / r['plain']:.2f} | {r['placed'][0]} / {r['placed'][1]} |")
    out += ["", HISTORY]
    return "\n".join(out + [""])


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
