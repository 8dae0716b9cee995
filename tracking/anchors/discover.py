"""Anchor discovery: what printed anchors a picture shows when the configured ones are not in view.

`Discovery` looks at gray frames for markers of every predefined ArUco / AprilTag dictionary family,
in both polarities (normal: black on white; inverted: white on black), and for QR codes. It is cheap
enough to run beside tracking: at most `rate_hz` frames a second, downscaled to `max_side` pixels, and
`passes_per_frame` (dictionary family, polarity) passes per frame, round-robin, so a full round of the
21 passes takes a few seconds of live video; `look_all` does every pass on one frame (replays, tests).

What was seen is grouped into suggestions (`Suggestion`): markers of one family and polarity whose ids
and image positions fit an OpenCV GridBoard (ids row by row) or a ChArUco board (ids in the white
squares, row by row) become that board, with its layout measured from the picture (the gaps, or the
squares, relative to the marker side); otherwise the most seen marker becomes a lone `aruco` anchor;
each QR text a `qr` anchor. A suggestion carries the anchor JSON block to use (lengths in metres) with
the marker size left to the user (`DEFAULT_MARKER_M`, stated in its summary), the smallest dictionary
of the family that holds its ids, and "polarity": "inverted" when it was printed so.

No Qt and no tracker state here: tracking/anchors/diagnose.py words the why of a session that tracks
nothing from a `Discovery`'s findings; the app and the commands offer its suggestions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np


# Each family's largest predefined dictionary (a marker of a smaller one is found in it with the same id),
# most common first: a round-robin reaches those soonest.
FAMILIES = ("DICT_4X4_1000", "DICT_ARUCO_MIP_36h12", "DICT_5X5_1000", "DICT_6X6_1000", "DICT_APRILTAG_36h11",
            "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10")
POLARITIES = ("normal", "inverted")
# the passes of one round: (family, polarity), and "qr" (QR codes are read dark on light)
PASSES = tuple((f, p) for f in FAMILIES[:2] for p in POLARITIES) + (("qr", "normal"),) + tuple(
    (f, p) for f in FAMILIES[2:] for p in POLARITIES)
# the marker side a suggestion states until the user measures the print (what `arapp markers board` prints)
DEFAULT_MARKER_M = 0.04
# ids looked for in each family: OpenCV reads a candidate square against every code of the dictionary, so a
# family's 1000 (AprilTag 36h10: 2320) codes cost up to 10 times its first 250 (what boards and sheets use)
LOOKED_FOR_IDS = 250
MIN_BOARD_MARKERS = 4          # fewer markers do not pin a board's layout
FIT_TOLERANCE = 0.12           # a layout fits when marker centres land within this fraction of a marker side
UPRIGHT_COS = 0.7              # a marker axis within 45 degrees of its layout axis counts as upright (cos)


def first_markers(family: str, n: int) -> cv2.aruco.Dictionary:
    """The dictionary of `family`'s first `n` markers (ids 0 .. n-1; the same codes, the same ids)."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, family))
    return cv2.aruco.Dictionary(d.bytesList[:n].copy(), d.markerSize, d.maxCorrectionBits)


def family_of(dictionary: str) -> str | None:
    """The FAMILIES entry whose markers include `dictionary`'s (DICT_4X4_50 -> DICT_4X4_1000); None for a
    dictionary file or an unknown name."""
    name = str(dictionary).replace("H", "h") if "APRILTAG" in str(dictionary) or "MIP" in str(dictionary) else str(dictionary)
    for f in FAMILIES:
        if name in family_dictionaries(f):
            return f
    return None


def family_dictionaries(family: str) -> list[str]:
    """The predefined dictionaries of a family, smallest first (DICT_4X4_50, _100, _250, _1000)."""
    head, _, size = family.rpartition("_")
    if size == "1000" and head.startswith("DICT_") and head[5:6].isdigit():
        return [f"{head}_{n}" for n in (50, 100, 250, 1000)]
    return [family]


def smallest_dictionary(family: str, ids) -> str:
    """The smallest dictionary of `family` that holds every id in `ids` (its first ids are the family's)."""
    top = max(ids)
    for name in family_dictionaries(family):
        if top < cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0]:
            return name
    return family


def id_span(ids) -> str:
    """'0-11' for a run of ids, '3, 7, 12' otherwise (at most 8 shown)."""
    ids = sorted(set(int(i) for i in ids))
    if len(ids) > 2 and ids[-1] - ids[0] + 1 == len(ids):
        return f"{ids[0]}-{ids[-1]}"
    return ", ".join(map(str, ids[:8])) + (", ..." if len(ids) > 8 else "")


@dataclass
class Suggestion:
    """An anchor seen in the picture. `block`: its anchor JSON (session.json / --anchors form, metres);
    `summary`: "a 4x3 DICT_4X4_50 board (ids 0-11)"; `size_field`: the block's field the user measures
    on the print (set to DEFAULT_MARKER_M until then, or 0.05 m for a QR code); `frames`: frames it was
    seen in; `markers`: the most markers (or codes) seen of it in one frame."""

    kind: str
    summary: str
    block: dict
    size_field: str
    frames: int = 1
    markers: int = 1
    dictionary: str | None = None
    polarity: str = "normal"
    ids: list[int] = field(default_factory=list)
    text: str | None = None

    def with_size(self, metres: float) -> dict:
        """The block with the size the user measured (metres; a board's other lengths scale with it)."""
        block = dict(self.block)
        scale = metres / block[self.size_field]
        for key in ("separation", "square_length"):
            if key in block:
                block[key] = round(block[key] * scale, 6)
        block[self.size_field] = metres
        return block


@dataclass
class Sighting:
    """One pass's find in one frame: markers of `family` read as `polarity` (ids, (N,4,2) corners in the
    full frame's pixels), or QR texts."""

    family: str
    polarity: str
    ids: np.ndarray
    quads: np.ndarray
    texts: list[str] = field(default_factory=list)


class Discovery:
    """Looks for markers of every dictionary family in both polarities and for QR codes (see module doc).

    rate_hz: frames looked at per second of frame time (`feed`); max_side: frames are downscaled so their
    longer side is at most this many pixels; passes_per_frame: (family, polarity) passes per looked-at frame."""

    def __init__(self, rate_hz: float = 4.0, max_side: int = 960, passes_per_frame: int = 2):
        self.rate_hz = float(rate_hz)
        self.max_side = int(max_side)
        self.passes_per_frame = max(1, int(passes_per_frame))
        params = cv2.aruco.DetectorParameters()
        self._detectors = {f: cv2.aruco.ArucoDetector(first_markers(f, LOOKED_FOR_IDS), params) for f in FAMILIES}
        self._qr = cv2.QRCodeDetector()
        self.reset()

    def reset(self) -> None:
        self._next = 0
        self._last_t: float | None = None
        self.frames_looked = 0
        self.rounds = 0.0   # full rounds of PASSES done (fractional)
        # (family, polarity) -> {id: frames seen}; best board fit per key: (markers, Suggestion)
        self._ids: dict[tuple[str, str], dict[int, int]] = {}
        self._frames: dict[tuple[str, str], int] = {}
        self._boards: dict[tuple[str, str], Suggestion] = {}
        self._texts: dict[str, int] = {}

    # -- looking ----------------------------------------------------------------------------------
    def feed(self, gray: np.ndarray, t: float) -> bool:
        """Look at this frame (time `t`, seconds) if `1 / rate_hz` has passed since the last one looked at;
        True when it was looked at."""
        if self._last_t is not None and 0 <= t - self._last_t < 1.0 / self.rate_hz:
            return False
        self._last_t = t
        # a lone marker seen once counts only when seen again (markers_seen): its pass comes first in the next
        # frame looked at, not a whole round (five seconds) later, which a short clip never reaches
        again = [k for k, ids in self._ids.items() if self._frames[k] == 1 and len(ids) == 1][:1]
        passes = list(again)
        while len(passes) < self.passes_per_frame:
            p = PASSES[self._next]
            self._next = (self._next + 1) % len(PASSES)
            if p not in passes:
                passes.append(p)
        self._look(gray, passes, rounds=(len(passes) - len(again)) / len(PASSES))
        return True

    def look_all(self, gray: np.ndarray) -> None:
        """Every pass (all families, both polarities, QR) on this frame."""
        self._look(gray, PASSES)

    def _look(self, gray: np.ndarray, passes, rounds: float | None = None) -> None:
        """Run `passes` on the frame; `rounds`: the part of a round of PASSES they count for (default: all)."""
        gray = gray if gray.ndim == 2 else cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        scale = min(1.0, self.max_side / max(gray.shape))
        small = gray if scale >= 1.0 else cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        negative = None
        sightings = []
        for family, polarity in passes:
            if family == "qr":
                sightings.append(Sighting("qr", "normal", np.zeros(0, int), np.zeros((0, 4, 2)), self._qr_texts(small)))
                continue
            if polarity == "inverted" and negative is None:
                negative = cv2.bitwise_not(small)
            corners, ids, _ = self._detectors[family].detectMarkers(negative if polarity == "inverted" else small)
            if ids is None:
                continue
            quads = np.concatenate(corners).reshape(-1, 4, 2).astype(np.float64) / scale
            sightings.append(Sighting(family, polarity, ids.ravel().astype(int), quads))
        self.frames_looked += 1
        self.rounds += len(passes) / len(PASSES) if rounds is None else rounds
        for s in _claim(sightings):
            self._add(s, gray)

    def _qr_texts(self, gray) -> list[str]:
        try:
            ok, texts, _, _ = self._qr.detectAndDecodeMulti(gray)
        except (cv2.error, UnicodeDecodeError):
            return []
        return [t for t in texts if t] if ok else []

    def _add(self, s: Sighting, gray: np.ndarray) -> None:
        if s.family == "qr":
            for t in s.texts:
                self._texts[t] = self._texts.get(t, 0) + 1
            return
        key = (s.family, s.polarity)
        seen = self._ids.setdefault(key, {})
        for i in set(s.ids.tolist()):
            seen[i] = seen.get(i, 0) + 1
        self._frames[key] = self._frames.get(key, 0) + 1
        best = self._boards.get(key)
        if len(s.ids) >= MIN_BOARD_MARKERS and (best is None or len(s.ids) > best.markers):
            # the layout is measured on subpixel corners (the detector's own lie up to a pixel inside)
            quads = cv2.cornerSubPix(gray, s.quads.reshape(-1, 1, 2).astype(np.float32), (3, 3), (-1, -1),
                                     (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
            board = board_from_markers(s.family, s.polarity, s.ids, quads.reshape(-1, 4, 2).astype(np.float64))
            if board is not None:
                self._boards[key] = board

    # -- findings ---------------------------------------------------------------------------------
    @property
    def markers_seen(self) -> dict[tuple[str, str], list[int]]:
        """(family, polarity) -> the ids seen, sorted; only markers seen in two frames or more, or with
        another marker of theirs (one square seen once is more likely a look-alike: a circuit board's chip
        reads as an inverted DICT_4X4_1000 marker)."""
        return {k: sorted(v) for k, v in self._ids.items() if self._frames[k] >= 2 or len(v) >= 2}

    @property
    def texts_seen(self) -> list[str]:
        """QR texts read, as read (most often read first)."""
        return sorted(self._texts, key=lambda t: -self._texts[t])

    def suggestions(self) -> list[Suggestion]:
        """What to use, best first: boards (most markers), then lone markers and QR codes (most frames).
        A lone marker seen in one frame only is left out (a look-alike square is more likely)."""
        out = []
        for key in self.markers_seen:
            family, polarity = key
            ids, frames = self._ids[key], self._frames[key]
            board = self._boards.get(key)
            if board is not None:
                board.frames = frames
                out.append(board)
                continue
            mid = max(ids, key=lambda i: (ids[i], -i))
            out.append(lone_marker(family, polarity, mid, frames, sorted(ids)))
        for text, n in self._texts.items():
            out.append(Suggestion("qr", f'a QR code "{_short(text)}"',
                                  {"kind": "qr", "text": text, "length": 0.05}, "length", frames=n, text=text))
        return sorted(out, key=lambda s: (s.kind not in ("aruco_board", "charuco"), -s.markers, -s.frames))


def _short(text: str, n: int = 40) -> str:
    one = " ".join(text.split())
    return one if len(one) <= n else one[: n - 3] + "..."


def _claim(sightings: list[Sighting]) -> list[Sighting]:
    """Markers of one frame found by several passes at the same place (a square that decodes in two
    families) kept by the pass that found the most markers in the frame."""
    marks = [s for s in sightings if s.family != "qr"]
    if len(marks) < 2:
        return sightings
    order = sorted(range(len(marks)), key=lambda k: -len(marks[k].ids))
    taken: list[np.ndarray] = []
    kept = {}
    for k in order:
        s = marks[k]
        centres = s.quads.mean(axis=1)
        side = np.sqrt(np.abs(_area(s.quads)))
        keep = np.ones(len(s.ids), bool)
        for c in taken:
            if len(c):
                d = np.linalg.norm(centres[:, None] - c[None], axis=2).min(axis=1)
                keep &= d > 0.3 * side
        if keep.any():
            kept[id(s)] = Sighting(s.family, s.polarity, s.ids[keep], s.quads[keep])
            taken.append(centres[keep])
    return [s for s in sightings if s.family == "qr"] + [kept[id(s)] for s in marks if id(s) in kept]


def _area(quads: np.ndarray) -> np.ndarray:
    x, y = quads[..., 0], quads[..., 1]
    return 0.5 * (x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y).sum(axis=1)


# -- layouts ------------------------------------------------------------------------------------------
def _fit(grid: np.ndarray, quads: np.ndarray) -> tuple[float, np.ndarray | None]:
    """(worst miss of the marker centres in marker sides, homography grid -> pixels) of one layout guess."""
    centres = quads.mean(axis=1)
    if len(grid) < 4 or np.linalg.matrix_rank(np.c_[grid, np.ones(len(grid))]) < 3:
        return np.inf, None
    H, _ = cv2.findHomography(grid.astype(np.float64), centres, 0)
    if H is None:
        return np.inf, None
    p = np.c_[grid, np.ones(len(grid))] @ H.T
    if np.any(np.abs(p[:, 2]) < 1e-12):
        return np.inf, None
    p = p[:, :2] / p[:, 2:3]
    side = np.sqrt(np.abs(_area(quads)))
    return float((np.linalg.norm(p - centres, axis=1) / side).max()), H


def _in_layout(H: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """The quads' (N,4,2) pixel corners in layout units, through the inverse of H (layout -> pixels)."""
    p = np.c_[quads.reshape(-1, 2), np.ones(quads.size // 2)] @ np.linalg.inv(H).T
    return (p[:, :2] / p[:, 2:3]).reshape(-1, 4, 2)


def _upright(H: np.ndarray, quads: np.ndarray) -> bool:
    """Whether the markers stand in the layout as OpenCV's boards print them: each marker's own x axis (its
    corner 0 -> 1) along the layout's +x and its y axis (corner 1 -> 2) along +y (rows downward). Ids that
    fit a grid turned or mirrored against the markers (a sheet of tags numbered up its columns) are no
    OpenCV board: no pose fits them, however well their centres line up (a homography may mirror)."""
    q = _in_layout(H, quads)
    ax, ay = q[:, 1] - q[:, 0], q[:, 2] - q[:, 1]
    cos_x = ax[:, 0] / np.maximum(np.linalg.norm(ax, axis=1), 1e-12)
    cos_y = ay[:, 1] / np.maximum(np.linalg.norm(ay, axis=1), 1e-12)
    return bool(np.median(cos_x) > UPRIGHT_COS and np.median(cos_y) > UPRIGHT_COS)


def _marker_fraction(H: np.ndarray, quads: np.ndarray) -> float:
    """The markers' median side in layout units (the layout's pitch is 1), through the inverse homography."""
    q = _in_layout(H, quads)
    return float(np.median(np.linalg.norm(q - np.roll(q, -1, axis=1), axis=2)))


@lru_cache(maxsize=256)
def _charuco_centres(sx: int, sy: int, legacy: bool = False) -> np.ndarray:
    """Centres (in squares) of the markers of an OpenCV sx x sy ChArUco board, in id order (`legacy`: in the
    pattern of OpenCV before 4.6, tracking/anchors/kinds/charuco.py)."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_1000)
    b = cv2.aruco.CharucoBoard((sx, sy), 1.0, 0.5, d, np.arange((sx * sy) // 2, dtype=np.int32))
    b.setLegacyPattern(legacy)
    return np.asarray(b.getObjPoints(), float).reshape(-1, 4, 3).mean(axis=1)[:, :2]


def board_from_markers(family: str, polarity: str, ids: np.ndarray, quads: np.ndarray) -> Suggestion | None:
    """The GridBoard or ChArUco board (ids from 0) whose layout the markers (ids, (N,4,2) pixels) fit, or None.

    Every markers_x (GridBoard: id k at column k % x, row k // x) and squares_x (ChArUco: id k in the k-th
    white square) is tried; the one whose homography puts every marker centre within FIT_TOLERANCE marker
    sides of its place, with the markers upright in it (`_upright`), wins (the fewest columns on a tie). Its
    rows are as many as the highest id needs."""
    ids = np.asarray(ids, int)
    if len(ids) < MIN_BOARD_MARKERS or len(set(ids.tolist())) != len(ids):
        return None
    top = int(ids.max())
    if top > 250 or top + 1 > 4 * len(ids) + 8:
        return None   # ids too sparse for a board in view (or far beyond any printed one)
    best = None
    for x in range(2, top + 2):
        grid = np.c_[ids % x, ids // x].astype(float)
        err, H = _fit(grid, quads)
        if err < FIT_TOLERANCE and (best is None or err < best[0] - 0.02) and _upright(H, quads):
            best = (err, "aruco_board", x, -(-(top + 1) // x), H)
    for sx in range(3, 2 * top + 4):
        sy = 2
        while (sx * sy) // 2 < top + 1:
            sy += 1
        # the legacy pattern (OpenCV before 4.6) differs from today's only with an even number of rows
        for legacy in (False, True) if sy % 2 == 0 else (False,):
            err, H = _fit(_charuco_centres(sx, sy, legacy)[ids], quads)
            if err < FIT_TOLERANCE and (best is None or err < best[0] - 0.02) and _upright(H, quads):
                best = (err, "charuco-legacy" if legacy else "charuco", sx, sy, H)
    if best is None:
        return None
    _, kind, nx, ny, H = best
    legacy = kind == "charuco-legacy"
    kind = "charuco" if legacy else kind
    frac = _marker_fraction(H, quads)
    dictionary = smallest_dictionary(family, ids.tolist())
    L = DEFAULT_MARKER_M
    inverted = ", printed inverted (white on black)" if polarity == "inverted" else ""
    if kind == "aruco_board":
        sep = round(L * max(1.0 / frac - 1.0, 0.0) * 2000) / 2000   # to half a millimetre
        block = {"kind": "aruco_board", "dictionary": dictionary, "markers_x": nx, "markers_y": ny,
                 "marker_length": L, "separation": sep, "first_id": 0}
        summary = f"a {nx}x{ny} {dictionary} board (ids 0-{nx * ny - 1}){inverted}"
    else:
        frac = min(frac, 0.95)
        square = round(L / frac * 2000) / 2000
        block = {"kind": "charuco", "dictionary": dictionary, "squares_x": nx, "squares_y": ny,
                 "square_length": square, "marker_length": L, "first_id": 0}
        old = ""
        if legacy:
            block["legacy"] = True
            old = " in the legacy pattern (OpenCV before 4.6)"
        summary = f"a {nx}x{ny} ChArUco {dictionary} board{old} (ids 0-{(nx * ny) // 2 - 1}){inverted}"
    if polarity == "inverted":
        block["polarity"] = "inverted"
    return Suggestion(kind, summary, block, "marker_length", markers=len(ids), dictionary=dictionary,
                      polarity=polarity, ids=sorted(ids.tolist()))


def lone_marker(family: str, polarity: str, marker_id: int, frames: int, ids: list[int]) -> Suggestion:
    """An `aruco` anchor for one marker (the most seen one when several were seen that fit no board)."""
    dictionary = smallest_dictionary(family, [marker_id])
    block = {"kind": "aruco", "dictionary": dictionary, "id": int(marker_id), "length": DEFAULT_MARKER_M}
    if polarity == "inverted":
        block["polarity"] = "inverted"
    inverted = ", printed inverted" if polarity == "inverted" else ""
    others = f" (also seen: ids {id_span([i for i in ids if i != marker_id])})" if len(ids) > 1 else ""
    return Suggestion("aruco", f"a {dictionary} marker, id {marker_id}{inverted}{others}", block, "length",
                      frames=frames, dictionary=dictionary, polarity=polarity, ids=list(ids))
