"""`AnchorSpec`: one anchor of a session as declared in session.json (docs/recording-format.md).

The record every anchor kind parses into. Lengths in metres; `world_from_anchor` a 4x4 rigid
transform (anchor frame -> world). The fields the built-in kinds use are named attributes; a
kind with fields of its own keeps them in `params` (read as attributes too, `spec.gap`), so a new
kind needs no change here. What the fields mean is the kind's business (tracking/anchors/kinds/).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.anchors.kinds.registry import kind_named

# named fields, in the order to_dict writes them (the order of docs/recording-format.md's examples)
COMMON_FIELDS = ("dictionary", "id", "length", "markers_x", "markers_y", "marker_length", "separation",
                 "squares_x", "squares_y", "square_length", "text")


@dataclass
class AnchorSpec:
    """One anchor of a session. Lengths in metres; `world_from_anchor` a 4x4 rigid transform.

    kinds: `aruco` (id, length), `aruco_board` (markers_x, markers_y,
    marker_length, separation, first_id), `charuco` (squares_x, squares_y,
    square_length, marker_length, first_id), `qr` (text, length); other
    registered kinds keep their own fields in `params`.
    """

    kind: str
    dictionary: str | None = None
    id: int | None = None
    length: float | None = None
    markers_x: int | None = None
    markers_y: int | None = None
    marker_length: float | None = None
    separation: float | None = None
    first_id: int = 0
    squares_x: int | None = None
    squares_y: int | None = None
    square_length: float | None = None
    text: str | None = None
    world_from_anchor: np.ndarray = field(default_factory=lambda: np.eye(4))
    params: dict = field(default_factory=dict)

    def __getattr__(self, name):
        # only called when normal lookup fails: a field of a registered kind's own (see module doc)
        params = self.__dict__.get("params")
        if params is not None and not name.startswith("_") and name in params:
            return params[name]
        raise AttributeError(f"{type(self).__name__} of kind {self.__dict__.get('kind')!r} has no field {name!r}")

    @classmethod
    def create(cls, kind: str, values: dict) -> "AnchorSpec":
        """A spec of `kind` from checked field values; fields that are not named attributes go to `params`."""
        named = {k: v for k, v in values.items() if k in COMMON_FIELDS or k == "first_id"}
        params = {k: v for k, v in values.items() if k not in named}
        return cls(kind=kind, **named, params=params)

    @property
    def polarity(self) -> str:
        """"auto" (default), "normal" or "inverted" (white markers on black): which print the detector
        accepts (kinds/base.py POLARITIES; a QR anchor is always "auto")."""
        return self.params.get("polarity", "auto")

    @property
    def anchor_kind(self):
        """The registered `AnchorKind` of this spec (tracking/anchors/kinds)."""
        return kind_named(self.kind)

    def to_dict(self) -> dict:
        d = {"kind": self.kind}
        for k in COMMON_FIELDS:
            v = getattr(self, k)
            if v is not None:
                d[k] = v
        for k in self.anchor_kind.written:
            d[k] = getattr(self, k)
        d.update(self.params)
        if not np.allclose(self.world_from_anchor, np.eye(4)):
            d["world_from_anchor"] = np.asarray(self.world_from_anchor).tolist()
        return d

    @property
    def dictionary_id(self) -> int | str:
        """OpenCV's id of a predefined dictionary; for a dictionary file, its path (see anchors/dictionaries.py)."""
        return getattr(cv2.aruco, self.dictionary) if self.dictionary.startswith("DICT_") else self.dictionary

    def marker_ids(self) -> list[int]:
        """The ArUco ids this anchor uses (empty for QR)."""
        return self.anchor_kind.marker_ids(self)
