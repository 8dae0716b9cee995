"""`AnchorKind`: what one kind of printed anchor is, in one place.

A kind says which fields its session.json block has and how they are checked
(`parse`, errors naming the file and field), where its detectable corners lie
in its own frame (`geometry`, metres, z = 0 on the paper), which detector
finds it (`detector`), how it is drawn on a sheet or in a synthetic view
(`layout`), where a model sits on it (`anchor_from_placement`) and how it is
described to the user (`describe`, `caption`, `summary`). Subclasses are in
this package, one module per kind, registered in its `__init__.py`.
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path

import cv2
import numpy as np

from tracking.anchors.dictionaries import aruco_dictionary, dictionary_size, is_custom
from tracking.anchors.kinds.spec import AnchorSpec
from tracking.errors import SessionError

# Keys every anchor block may carry besides its kind's own fields (session.py reads world_from_anchor).
ANY_KIND_KEYS = ("kind", "world_from_anchor")

# `polarity` of a marker-based anchor: "normal" (black markers on white paper), "inverted" (white on black,
# as some calibration tools print boards) or "auto" (the default: both are looked for, see anchors/detect.py)
POLARITIES = ("auto", "normal", "inverted")


# the largest length (metres) an anchor's field may have: a poster-sized board, with room
MAX_LENGTH_M = 5.0


def mm(metres: float) -> str:
    """'50 mm' for 0.05 (metres shown in millimetres, as users measure prints)."""
    return f"{metres * 1000:g} mm"


def square_corners(length: float) -> np.ndarray:
    """(4,3) corners of a square of side `length` centred at the origin, OpenCV order TL, TR, BR, BL, y up."""
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def aruco_dictionary_names() -> list[str]:
    """Names of OpenCV's predefined ArUco dictionaries (`DICT_4X4_50`, ...)."""
    return sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and isinstance(getattr(cv2.aruco, n), int))


def marker_bits(dictionary: str, marker_id: int) -> np.ndarray:
    """(n+2, n+2) uint8 image of an ArUco marker with its one-cell black border, one pixel per cell."""
    d = aruco_dictionary(dictionary)
    n = d.markerSize + 2
    return cv2.aruco.generateImageMarker(d, int(marker_id), n, borderBits=1)


def check_type(value, typ, where):
    """`value` as `typ` (float: any finite number; int: not bool); SessionError naming `where` otherwise."""
    if typ is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if not ok:
            raise SessionError(f"{where}: must be a number, got {value!r}")
        return float(value)
    if typ is int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise SessionError(f"{where}: must be an integer, got {value!r}")
        return value
    if not isinstance(value, typ):
        raise SessionError(f"{where}: must be a {typ.__name__}, got {value!r}")
    return value


class AnchorKind:
    """One kind of anchor. Subclass, set the class attributes, override what differs; lengths in metres.

    Class attributes:
      name        the `kind` string of session.json
      required    field -> type (float, int, str) that a block must have, in the order errors list them
      optional    field -> type a block may have
      written     optional fields to_dict always writes (first_id of boards)
      positive, counts, non_negative   fields that must be > 0 (metres), >= 1, >= 0
      detector    "aruco": dictionary markers (cv2.aruco.ArucoDetector); "charuco": those plus the
                  chessboard corners between them (cv2.aruco.CharucoDetector); "qr": a QR symbol
      single_square  the anchor is the 4 corners of one square (IPPE_SQUARE pose, margin cover check)
      face        +1 when the printed side faces the anchor frame's +z, -1 when it faces -z (OpenCV boards)
      size_fields    the fields that set its scale (named by diagnose when its distance disagrees)
      layout_fields  the fields that set its layout (named when it does not fit itself), None for one square
      cli_name    the `arapp markers KIND` name, None when `arapp markers` does not print it
    """

    name = ""
    required: dict = {}
    optional: dict = {"first_id": int, "polarity": str}
    written: tuple = ()
    positive: tuple = ()
    counts: tuple = ()
    non_negative: tuple = ()
    detector = "aruco"
    single_square = False
    face = 1.0
    size_fields = "length"
    layout_fields: str | None = None
    cli_name: str | None = None

    # -- session.json ----------------------------------------------------------------------------
    def parse(self, block: dict, where: str, folder: str | Path | None = None) -> AnchorSpec:
        """The spec of one anchor block (the kind already known); errors name `where`.field.
        `folder`: where a relative dictionary-file path is read from (default: the current folder)."""
        values = {}
        for key, typ in self.required.items():
            if key not in block:
                raise SessionError(f"{where}.{key}: missing (a {self.name} anchor needs {', '.join(self.required)})")
            values[key] = check_type(block[key], typ, f"{where}.{key}")
        for key in block:
            if key not in self.required and key not in self.optional and key not in ANY_KIND_KEYS:
                raise SessionError(f"{where}.{key}: unknown key for a {self.name} anchor")
        for key, typ in self.optional.items():
            if key in block:
                values[key] = check_type(block[key], typ, f"{where}.{key}")
        for key in self.positive:
            if values[key] <= 0:
                raise SessionError(f"{where}.{key}: must be positive (metres), got {values[key]}")
        for key in self.counts:
            if values[key] < 1:
                raise SessionError(f"{where}.{key}: must be at least 1, got {values[key]}")
        for key in self.non_negative:
            if values[key] < 0:
                raise SessionError(f"{where}.{key}: must not be negative")
        for key in self.positive + self.non_negative:
            if key in values and values[key] > MAX_LENGTH_M:
                # a length typed in millimetres (40 for a 40 mm marker) would put the camera hundreds of metres off
                raise SessionError(f"{where}.{key}: {values[key]:g} m is larger than any printed anchor; lengths are "
                                   f"in metres ({values[key]:g} mm is {values[key] / 1000:g})")
        if values.get("polarity", "auto") not in POLARITIES:
            raise SessionError(f"{where}.polarity: must be one of {', '.join(POLARITIES)} (\"inverted\": white "
                               f"markers on black), got {values['polarity']!r}")
        if "dictionary" in values:
            values["dictionary"] = self._dictionary(values["dictionary"], where, folder)
        spec = AnchorSpec.create(self.name, values)
        self.check(spec, where)
        return spec

    @staticmethod
    def _dictionary(name: str, where: str, folder) -> str:
        if is_custom(name):  # a dictionary file (custom markers), relative to the recording folder
            return str((Path(folder or ".") / name).resolve())
        names = aruco_dictionary_names()
        if name not in names:
            # a name typed by hand is most often right but for its case or its prefix (DICT_6x6_50, 4X4_50)
            near = [n for n in names if n.upper() in (name.upper(), "DICT_" + name.upper())]
            near = near or difflib.get_close_matches(name.upper(), names, n=1, cutoff=0.8)
            hint = f"did you mean {near[0]!r}? Or use" if near else "use"
            raise SessionError(f"{where}.dictionary: {name!r} is not an OpenCV ArUco dictionary; "
                               f"{hint} one of {', '.join(names[:6])}, ... or a dictionary file (.yml)")
        return name

    def check(self, spec: AnchorSpec, where: str) -> None:
        """Checks across fields, after each field's own; default: the marker ids fit the dictionary."""
        if spec.dictionary is None:
            return
        size = dictionary_size(spec.dictionary, f"{where}.dictionary")
        ids = self.marker_ids(spec)
        if ids and (min(ids) < 0 or max(ids) >= size):
            raise SessionError(f"{where}: marker ids {min(ids)}..{max(ids)} do not fit {spec.dictionary}, "
                               f"which has ids 0..{size - 1}")

    # -- geometry (anchor frame, metres) -----------------------------------------------------------
    def marker_ids(self, spec: AnchorSpec) -> list[int]:
        """The ArUco ids this anchor uses (empty when it has no ArUco markers)."""
        return []

    def geometry(self, spec: AnchorSpec) -> tuple[dict[int, np.ndarray], np.ndarray | None, object]:
        """(ArUco id -> (4,3) corners in OpenCV order, (M,3) chessboard corners or None, OpenCV board or None)."""
        raise NotImplementedError(f"{self.name}: geometry")

    def outline(self, spec: AnchorSpec, markers: dict, chess) -> np.ndarray:
        """(K,3) anchor-frame points spanning the anchor (regions of interest, scan outlines)."""
        pts = list(markers.values()) + ([chess] if chess is not None else [])
        return np.concatenate(pts, axis=0)

    def anchor_from_placement(self, spec: AnchorSpec) -> np.ndarray:
        """4x4: the placement frame (pattern centre, z out of the paper) in the anchor frame."""
        return np.eye(4)

    def extent(self, spec: AnchorSpec) -> tuple[float, float]:
        """(side of the smallest marker that must be read, side of the whole pattern), metres."""
        return spec.length, spec.length

    # -- drawing -----------------------------------------------------------------------------------
    def layout(self, spec: AnchorSpec, markers: dict, margin: float | None):
        """What to draw, in the anchor plane (metres): (patches [(bits image, (4,2) corners TL,TR,BR,BL)],
        black quads [(4,2)], white margin around the pattern). Default: the ArUco markers of `markers`,
        a margin of one marker cell (at least 2 mm)."""
        patches = [(marker_bits(spec.dictionary, mid), c[:, :2]) for mid, c in markers.items()]
        if margin is None:
            cells = aruco_dictionary(spec.dictionary).markerSize + 2
            margin = max(self.extent(spec)[0] / cells, 0.002)
        return patches, [], margin

    # -- words -------------------------------------------------------------------------------------
    def describe(self, spec: AnchorSpec) -> str:
        """The anchor as a user checks it against the printed sheet ('ArUco id 40, DICT_4X4_50, 50 mm')."""
        return spec.kind

    def caption(self, spec: AnchorSpec) -> str:
        """One line printed under the pattern on its sheet, sizes in mm."""
        return self.describe(spec)

    def summary(self, spec: AnchorSpec) -> tuple[str, str]:
        """(ids, size) for a table of anchors, sizes in mm."""
        ids = self.marker_ids(spec)
        text = f"{ids[0]}..{ids[-1]}" if len(ids) > 3 else ", ".join(str(i) for i in ids)
        return text, mm(spec.length) if spec.length is not None else ""  # boards: their subclass says the size

    def file_stem(self, spec: AnchorSpec) -> str:
        """File name stem of its printable sheet."""
        return f"{self.name}_{spec.dictionary}"

    def cli_block(self, args) -> dict:
        """The session.json block `arapp markers` prints from its arguments (see arapp/commands/markers.py)."""
        raise NotImplementedError(f"{self.name}: arapp markers does not print it")
