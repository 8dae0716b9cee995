"""ArUco and ChArUco detection for a session's anchors, with subpixel corners and optional regions of interest.

Corners are distorted pixel coordinates (pixel centres at integers).

Polarity: a board printed white-on-black (several calibration tools print ChArUco boards so) is found
as well as a normal one. An anchor's `polarity` (AnchorSpec.polarity) is "auto" by default: each
dictionary's anchors are looked for in the polarity they were last seen in (normal at first), and in
the other one only when none of them is found that way (a board is printed one way), on the inverted
image. So a normal board in view costs nothing extra, and its corners are exactly what they were (OpenCV's
`detectInvertedMarker` would do both in one pass for a few percent, but it picks other contours of
normal markers as well: corners moved by up to 5 px before the edge fit). The polarity each anchor was
last found in is kept in `ArucoDetection.polarity`. "normal" or "inverted" pins one: the other is
never tried. `other_every` (the anchor tracker sets it): once every anchor of a dictionary has been found
in some polarity, a miss is more likely motion blur or the anchors out of view than the print turned
over, so the other polarity is tried only on every `other_every`-th consecutive miss (1: on every miss);
before that, on every second miss.

Each detector reads only the anchors' own codes (`anchor_codes`: a dictionary of the anchors' ids alone),
not the whole dictionary: OpenCV compares every candidate square with each code of its dictionary in four
turns, which for AprilTag 36h11 (587 codes) is most of a detector pass (on the real clipboard photos a
pass took 8.2 ms with the whole dictionary and 2.5 ms with the 30 anchors' codes). The markers found are
the same: the codes of every predefined dictionary lie more than twice as many bits apart as the detector
corrects (maxCorrectionBits x errorCorrectionRate, 0.6 by default), so a square within reach of an anchor's
code is that marker whether or not the other codes are looked at, and markers of other ids were dropped
anyway. Every anchor's markers are then edge-refined in one call
(`_refine`), each on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary
from tracking.anchors.model import AnchorModel
from tracking.anchors.edges import refine_squares
from tracking.anchors.pose import project
from tracking.camera import Camera

# the detector families (AnchorKind.detector) found here; "qr" anchors are qr.py's
ARUCO_FAMILIES = ("aruco", "charuco")

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)


def anchor_codes(dictionary: cv2.aruco.Dictionary, ids) -> tuple[cv2.aruco.Dictionary, np.ndarray]:
    """(a dictionary holding only the codes of `ids`, the marker id of each of its entries): a detector on it
    finds those markers and reports entry k for marker ids[k] (sorted)."""
    ids = np.array(sorted(set(int(i) for i in ids)), int)
    return cv2.aruco.Dictionary(dictionary.bytesList[ids], dictionary.markerSize, dictionary.maxCorrectionBits), ids


def detector_parameters() -> cv2.aruco.DetectorParameters:
    """The detector settings shared by arapp and the plain baseline: subpixel corner refinement."""
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return p


@dataclass
class Observation:
    """Image points of one anchor in one frame.

    `obj`: (N,3) anchor-frame points; `img`: (N,2) distorted pixels; `groups`: (N,) int label per point
    (marker id, or -1-k for chessboard/QR points) so whole markers can be rejected together;
    `markers`: number of markers / codes behind these points.
    """

    anchor: int
    obj: np.ndarray
    img: np.ndarray
    groups: np.ndarray
    markers: int
    square: bool = False  # the 4 corners of one square marker (IPPE_SQUARE applies)


def _shortest_side(quads: np.ndarray) -> np.ndarray:
    """Each quad's (M,4,2) shortest side, pixels (as np.linalg.norm computes the lengths)."""
    d = quads - quads[:, [3, 0, 1, 2]]
    return np.sqrt(np.add.reduce(d * d, axis=2)).min(axis=1)


class ArucoDetection:
    """Finds the ArUco markers (and ChArUco corners) of the anchors; one OpenCV detector per dictionary."""

    def __init__(self, models: list[AnchorModel], camera: Camera):
        self.camera = camera
        self.models = [m for m in models if m.anchor_kind.detector in ARUCO_FAMILIES]
        # (dictionary name (or file), polarity "auto" / "normal" / "inverted") -> id -> anchor
        self.by_dict: dict[tuple[str, str], dict[int, AnchorModel]] = {}
        for m in self.models:
            ids = self.by_dict.setdefault((m.spec.dictionary, m.spec.polarity), {})
            for mid in m.markers:
                ids[mid] = m
        # Corners come from edge fitting (edges.py), more exact than the detector's own subpixel step.
        params = detector_parameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        # marker side in cells (bits + black border), by dictionary name; also by AnchorSpec.dictionary_id,
        # the key other modules use (for a dictionary file that is its path, the same as the name)
        self.bits = {d: aruco_dictionary(d).markerSize + 2 for d, _ in self.by_dict}
        self.bits.update({m.spec.dictionary_id: self.bits[m.spec.dictionary] for m in self.models})
        # one detector per dictionary and polarity pin, on the anchors' codes alone (`anchor_codes`; `entry_ids`
        # turns its entries back into marker ids); inverted markers are read on the inverted image
        self.detectors, self.entry_ids = {}, {}
        for key, ours in self.by_dict.items():
            codes, self.entry_ids[key] = anchor_codes(aruco_dictionary(key[0]), ours)
            self.detectors[key] = cv2.aruco.ArucoDetector(codes, params)
        # anchor index -> "normal" / "inverted": the polarity its markers had when last detected
        self.polarity: dict[int, str] = {}
        # a lone marker's edges are sampled over its sides from this fraction on (edges.refine_squares
        # end_margin, weak steps left out); None: as a board's, 0.2 (set by AnchorTracker)
        self.lone_end_margin: float | None = None
        self.charuco = {}
        for m in self.models:
            if m.anchor_kind.detector == "charuco":
                cp = cv2.aruco.CharucoParameters()
                cp.cameraMatrix = camera.K
                cp.distCoeffs = camera.dist.reshape(1, -1)
                cp.minMarkers = 1
                self.charuco[m.index] = cv2.aruco.CharucoDetector(m.board, cp, params)
        # the other polarity on every `other_every`-th consecutive miss once each anchor's print is known
        self.other_every = 1
        self._misses: dict[tuple[str, str], int] = {}   # (dictionary, pin) -> consecutive misses
        # detector passes run and the pixels they read, since construction (benchmarks, diagnostics)
        self.passes = 0
        self.pixels_read = 0
        self._world_cache: dict = {}  # (anchor, id) -> (world_from_anchor bytes, world corners): _world_corners

    def detect(self, gray: np.ndarray, roi: tuple[int, int, int, int] | None = None) -> list[Observation]:
        """Observations of the ArUco-based anchors in `gray`, optionally only inside roi=(x0, y0, x1, y1)."""
        x0 = y0 = 0
        full = gray
        if roi is not None:
            x0, y0, x1, y1 = roi
            gray = gray[y0:y1, x0:x1]
        per_anchor: dict[int, list] = {}
        self._negative = None
        for (d, pin) in self.detectors:
            ours = self.by_dict[(d, pin)]
            first = pin if pin != "auto" else self._last_polarity(ours)
            found = self._markers((d, pin), gray, first, (x0, y0))
            if not found and pin == "auto" and self._try_other((d, pin), ours):
                # none of them in the polarity they were last seen in: the other print
                first = "inverted" if first == "normal" else "normal"
                found = self._markers((d, pin), gray, first, (x0, y0))
            self._misses[(d, pin)] = 0 if found else self._misses.get((d, pin), 0) + 1
            for mid, c in found:
                self.polarity[ours[mid].index] = first
                per_anchor.setdefault(ours[mid].index, []).append((mid, c, d))
        # every anchor's markers refined in one call (a call's fixed cost is most of a lone marker's)
        kept = []
        for m in self.models:
            found = per_anchor.get(m.index)
            if not found:
                continue
            # A marker id seen twice is ambiguous (a reflection, a second print): drop both.
            seen = [mid for mid, _, _ in found]
            found = [(mid, c, d) for mid, c, d in found if seen.count(mid) == 1]
            if found:
                kept.append((m, found))
        if not kept:
            return []
        refined = iter(self._refine(full, [(m, d, c) for m, found in kept for _, c, d in found]))
        out = []
        for m, found in kept:
            found = [(mid, next(refined)) for mid, _, _ in found]
            if m.anchor_kind.detector == "charuco":
                obs = self._charuco(m, full, found)
                if obs is not None:
                    out.append(obs)
                    continue
            obj = np.concatenate([m.markers[mid] for mid, _ in found])
            img = np.concatenate([c for _, c in found])
            groups = np.repeat([mid for mid, _ in found], 4)
            out.append(Observation(m.index, obj, img, groups, len(found), square=m.anchor_kind.single_square))
        return out

    def _refine(self, full: np.ndarray, markers: list[tuple[AnchorModel, str, np.ndarray]]) -> np.ndarray:
        """The detector's corners (M,4,2) of `markers` ((anchor, dictionary, (4,2) corners) each) refined on
        their edges (edges.refine_squares), or where the edges fail (cut by the image border, blur) by
        gradient (cornerSubPix); each marker's corners are refined on their own, whatever else is in the call."""
        quads = np.array([c for _, _, c in markers])
        cell = _shortest_side(quads) / np.array([self.bits[d] for _, d, _ in markers])
        refined, ok = refine_squares(full, quads, cell, self.camera, **self._edge_span([m for m, _, _ in markers]))
        if not ok.all():
            rest = quads[~ok].reshape(-1, 1, 2).astype(np.float32)
            rest = cv2.cornerSubPix(full, rest, (3, 3), (-1, -1), _SUBPIX)
            refined[~ok] = rest.reshape(-1, 4, 2)
        return refined

    def _try_other(self, key: tuple[str, str], ours: dict[int, AnchorModel]) -> bool:
        """Whether to read the other polarity after a miss in the usual one: on every `other_every`-th miss in
        a row (this miss counted) once every anchor of this dictionary was found in some polarity, on every
        second one while some anchor's print is unknown (a board coming into view is read normal first, on
        every frame; an inverted one is seen at most a frame later)."""
        if self.other_every <= 1:
            return True
        every = 2 if any(m.index not in self.polarity for m in ours.values()) else self.other_every
        return (self._misses.get(key, 0) + 1) % every == 0

    def _last_polarity(self, ours: dict[int, AnchorModel]) -> str:
        """The polarity most of these anchors were last found in ("normal" when none was found yet)."""
        seen = [self.polarity[i] for i in {m.index for m in ours.values()} if i in self.polarity]
        return "inverted" if 2 * seen.count("inverted") > len(seen) else "normal"

    def _markers(self, key: tuple[str, str], gray: np.ndarray, polarity: str,
                 offset: tuple[int, int]) -> list[tuple[int, np.ndarray]]:
        """[(id, (4,2) corners in full-image pixels)] of the anchors' markers that the detector of `key`
        (dictionary, pin) finds in `gray` read as `polarity` ("inverted": on the inverted image, kept for the
        frame)."""
        if polarity == "inverted":
            if self._negative is None:
                self._negative = cv2.bitwise_not(gray)
            gray = self._negative
        corners, entries, _ = self.detectors[key].detectMarkers(gray)
        self.passes += 1
        self.pixels_read += gray.shape[0] * gray.shape[1]
        if entries is None:
            return []
        # all markers' corners in full-image pixels at once
        quads = np.concatenate(corners).reshape(-1, 4, 2).astype(np.float64) + offset
        return list(zip(self.entry_ids[key][entries.ravel()].tolist(), quads))

    def _edge_span(self, models: list[AnchorModel]) -> dict:
        """refine_squares' end_margin / strong_only for quads of these anchors (lone markers: `lone_end_margin`)."""
        lone = np.array([m.anchor_kind.single_square for m in models], bool)
        if self.lone_end_margin is None or not lone.any():
            return {}
        return {"end_margin": np.where(lone, self.lone_end_margin, 0.2), "strong_only": lone}

    def track(self, gray: np.ndarray, keys: set[tuple[int, int]], camera_from_world: np.ndarray,
              min_fraction: float = 0.6) -> list[Observation] | None:
        """Re-find known markers (anchor, id) where a predicted pose puts them, without detecting.

        Each marker's border is projected with `camera_from_world` and refined on its edges (edges.py);
        edge fitting finds the true border when the prediction is within about half a marker cell.
        Returns None (detect instead) when fewer than `min_fraction` of the markers are re-found, or when
        a ChArUco board is among them (its chessboard corners need the detector).
        """
        keys = sorted(keys)
        if not keys:
            return None
        by_index = {m.index: m for m in self.models}
        if any(by_index[a].anchor_kind.detector == "charuco" for a, _ in keys if a in by_index):
            return None
        keys = [(a, mid) for a, mid in keys if a in by_index]
        world = np.concatenate(self._world_corners(by_index, keys))
        px, z = project(self.camera, camera_from_world, world)
        if np.any(z <= 0.01):
            return None
        quads = px.reshape(-1, 4, 2)
        side = _shortest_side(quads)
        cell = side / np.array([self.bits[by_index[a].spec.dictionary] for a, _ in keys])
        refined, ok = refine_squares(gray, quads, cell, self.camera, **self._edge_span([by_index[a] for a, _ in keys]))
        if ok.sum() < max(1, min_fraction * len(keys)):
            return None
        per_anchor: dict[int, list] = {}
        for (a, mid), q, good in zip(keys, refined, ok):
            if good:
                per_anchor.setdefault(a, []).append((mid, q))
        out = []
        for m in self.models:
            found = per_anchor.get(m.index)
            if found:
                obj = np.concatenate([m.markers[mid] for mid, _ in found])
                img = np.concatenate([q for _, q in found])
                out.append(Observation(m.index, obj, img, np.repeat([mid for mid, _ in found], 4), len(found),
                                       square=m.anchor_kind.single_square))
        return out

    def _world_corners(self, by_index: dict, keys: list[tuple[int, int]]) -> list[np.ndarray]:
        """Each marker's (anchor, id) corners (4,3) in world metres, as AnchorModel.to_world gives them;
        kept between frames while the anchor's world_from_anchor stays the same."""
        placed = {a: np.asarray(by_index[a].world_from_anchor, dtype=float).tobytes() for a in {a for a, _ in keys}}
        out = []
        for a, mid in keys:
            hit = self._world_cache.get((a, mid))
            if hit is None or hit[0] != placed[a]:
                hit = self._world_cache[(a, mid)] = (placed[a], by_index[a].to_world(by_index[a].markers[mid]))
            out.append(hit[1])
        return out

    def _charuco(self, m: AnchorModel, gray, found) -> Observation | None:
        """Chessboard corners of a ChArUco board (more precise than marker corners); None under 4 corners."""
        mc = tuple(c.reshape(1, 4, 2).astype(np.float32) for _, c in found)
        mi = np.array([[mid] for mid, _ in found], np.int32)
        cc, ci, _, _ = self.charuco[m.index].detectBoard(gray, markerCorners=mc, markerIds=mi)
        if ci is None or len(ci) < 4:
            return None
        ci = ci.ravel()
        return Observation(m.index, m.chess[ci], cc.reshape(-1, 2).astype(np.float64),
                           -1 - np.zeros(len(ci), int), len(found))
