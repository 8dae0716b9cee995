"""session.json of a recording (`arapp-recording/1`) and the anchors it declares.

See docs/recording-format.md: lengths in metres; the world is the frame of
the first anchor; every other anchor carries `world_from_anchor`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError

FORMAT = "arapp-recording/1"
ANCHOR_KINDS = ("aruco", "aruco_board", "charuco", "qr")


def aruco_dictionary_names() -> list[str]:
    """Names of OpenCV's predefined ArUco dictionaries (`DICT_4X4_50`, ...)."""
    return sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and isinstance(getattr(cv2.aruco, n), int))


@dataclass
class AnchorSpec:
    """One anchor of a session. Lengths in metres; `world_from_anchor` a 4x4 rigid transform.

    kinds: `aruco` (id, length), `aruco_board` (markers_x, markers_y,
    marker_length, separation, first_id), `charuco` (squares_x, squares_y,
    square_length, marker_length, first_id), `qr` (text, length).
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

    def to_dict(self) -> dict:
        d = {"kind": self.kind}
        for k in ("dictionary", "id", "length", "markers_x", "markers_y", "marker_length", "separation",
                  "squares_x", "squares_y", "square_length", "text"):
            v = getattr(self, k)
            if v is not None:
                d[k] = v
        if self.kind in ("aruco_board", "charuco"):
            d["first_id"] = self.first_id
        if not np.allclose(self.world_from_anchor, np.eye(4)):
            d["world_from_anchor"] = np.asarray(self.world_from_anchor).tolist()
        return d

    @property
    def dictionary_id(self) -> int | str:
        """OpenCV's id of a predefined dictionary; for a dictionary file, its path (see anchors/dictionaries.py)."""
        return getattr(cv2.aruco, self.dictionary) if self.dictionary.startswith("DICT_") else self.dictionary

    def marker_ids(self) -> list[int]:
        """The ArUco ids this anchor uses (empty for QR)."""
        if self.kind == "aruco":
            return [self.id]
        if self.kind == "aruco_board":
            return list(range(self.first_id, self.first_id + self.markers_x * self.markers_y))
        if self.kind == "charuco":
            return list(range(self.first_id, self.first_id + (self.squares_x * self.squares_y) // 2))
        return []


_REQUIRED = {
    "aruco": {"dictionary": str, "id": int, "length": float},
    "aruco_board": {"dictionary": str, "markers_x": int, "markers_y": int, "marker_length": float,
                    "separation": float},
    "charuco": {"dictionary": str, "squares_x": int, "squares_y": int, "square_length": float,
                "marker_length": float},
    "qr": {"text": str, "length": float},
}
_OPTIONAL = {"first_id": int, "world_from_anchor": list, "kind": str}


def _check_type(value, typ, where):
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


def parse_rigid(value, where: str) -> np.ndarray:
    """A 4x4 row-major rigid transform from JSON, checked (orthonormal rotation, last row 0 0 0 1)."""
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SessionError(f"{where}: must be a 4x4 array of numbers") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise SessionError(f"{where}: must be a 4x4 array of finite numbers, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0 or not np.allclose(T[3], [0, 0, 0, 1]):
        raise SessionError(f"{where}: must be a rigid transform (orthonormal rotation, last row 0 0 0 1)")
    return T


def parse_anchor(d: dict, where: str = "anchors[0]", folder: str | Path | None = None) -> AnchorSpec:
    """An `AnchorSpec` from its JSON block; every error names the field, e.g. `anchors[1].length`.
    `folder`: where a relative dictionary-file path is read from (default: the current folder)."""
    if not isinstance(d, dict):
        raise SessionError(f"{where}: must be an object")
    kind = d.get("kind")
    if kind not in _REQUIRED:
        raise SessionError(f"{where}.kind: must be one of {', '.join(ANCHOR_KINDS)}, got {kind!r}")
    spec = {}
    for key, typ in _REQUIRED[kind].items():
        if key not in d:
            raise SessionError(f"{where}.{key}: missing (a {kind} anchor needs {', '.join(_REQUIRED[kind])})")
        spec[key] = _check_type(d[key], typ, f"{where}.{key}")
    for key in d:
        if key not in _REQUIRED[kind] and key not in _OPTIONAL:
            raise SessionError(f"{where}.{key}: unknown key for a {kind} anchor")
    if "first_id" in d:
        spec["first_id"] = _check_type(d["first_id"], int, f"{where}.first_id")
    for key in ("length", "marker_length", "square_length"):
        if key in spec and spec[key] <= 0:
            raise SessionError(f"{where}.{key}: must be positive (metres), got {spec[key]}")
    for key in ("markers_x", "markers_y", "squares_x", "squares_y"):
        if key in spec and spec[key] < 1:
            raise SessionError(f"{where}.{key}: must be at least 1, got {spec[key]}")
    if "separation" in spec and spec["separation"] < 0:
        raise SessionError(f"{where}.separation: must not be negative")
    if "dictionary" in spec:
        from tracking.anchors.dictionaries import dictionary_size, is_custom
        names = aruco_dictionary_names()
        if is_custom(spec["dictionary"]):  # a dictionary file (custom markers), relative to the recording folder
            spec["dictionary"] = str((Path(folder or ".") / spec["dictionary"]).resolve())
        elif spec["dictionary"] not in names:
            raise SessionError(
                f"{where}.dictionary: {spec['dictionary']!r} is not an OpenCV ArUco dictionary; "
                f"use one of {', '.join(names[:6])}, ... or a dictionary file (.yml)"
            )
        size = dictionary_size(spec["dictionary"], f"{where}.dictionary")
        a = AnchorSpec(kind=kind, **spec)
        ids = a.marker_ids()
        if ids and (min(ids) < 0 or max(ids) >= size):
            raise SessionError(f"{where}: marker ids {min(ids)}..{max(ids)} do not fit {spec['dictionary']}, "
                               f"which has ids 0..{size - 1}")
    anchor = AnchorSpec(kind=kind, **spec)
    if "world_from_anchor" in d:
        anchor.world_from_anchor = parse_rigid(d["world_from_anchor"], f"{where}.world_from_anchor")
    return anchor


def parse_anchors(blocks, where: str = "anchors", folder: str | Path | None = None) -> list[AnchorSpec]:
    """The `anchors` list of a session; the first anchor defines the world (its transform must be identity)."""
    if not isinstance(blocks, list) or not blocks:
        raise SessionError(f"{where}: must be a non-empty list of anchors")
    anchors = [parse_anchor(b, f"{where}[{i}]", folder) for i, b in enumerate(blocks)]
    if not np.allclose(anchors[0].world_from_anchor, np.eye(4), atol=1e-9):
        raise SessionError(f"{where}[0].world_from_anchor: the first anchor defines the world and must be the identity")
    return anchors


@dataclass
class Session:
    """A parsed session.json; `folder` is the recording folder."""

    folder: Path
    video: str
    fps: float
    camera: Camera
    anchors: list[AnchorSpec]
    source: dict = field(default_factory=lambda: {"kind": "file"})

    @property
    def video_path(self) -> Path:
        return self.folder / self.video

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "video": self.video,
            "fps": self.fps,
            "camera": self.camera.to_dict(),
            "anchors": [a.to_dict() for a in self.anchors],
            "source": self.source,
        }

    def save(self) -> Path:
        path = self.folder / "session.json"
        tmp = path.with_name(".session.json.tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        tmp.replace(path)  # a crash never leaves half a session.json
        return path


def parse_session(data: dict, folder: Path, where: str = "session.json") -> Session:
    """Validate a session dict; errors are `SessionError`s naming the file and field."""
    if not isinstance(data, dict):
        raise SessionError(f"{where}: must be a JSON object")
    if data.get("format") != FORMAT:
        raise SessionError(f"{where}: format must be {FORMAT!r}, got {data.get('format')!r}")
    video = data.get("video")
    if not isinstance(video, str) or not video:
        raise SessionError(f"{where}: video: must name the video file in the recording folder")
    fps = data.get("fps")
    if not isinstance(fps, (int, float)) or isinstance(fps, bool) or not (fps > 0 and math.isfinite(fps)):
        raise SessionError(f"{where}: fps: must be a positive number, got {fps!r}")
    try:
        camera = Camera.from_dict(data.get("camera"), "camera")
    except CalibrationError as e:
        raise SessionError(f"{where}: {e}") from None
    try:
        anchors = parse_anchors(data.get("anchors"), folder=folder)
    except SessionError as e:
        raise SessionError(f"{where}: {e}") from None
    source = data.get("source", {"kind": "file"})
    if not isinstance(source, dict):
        raise SessionError(f"{where}: source: must be an object such as {{\"kind\": \"synthetic\"}}")
    return Session(Path(folder), video, float(fps), camera, anchors, source)


def load_session(folder: str | Path) -> Session:
    """Read and validate `<folder>/session.json`."""
    folder = Path(folder)
    path = folder / "session.json"
    if not folder.is_dir():
        raise SessionError(f"{folder}: not a recording folder (it does not exist or is not a folder)")
    if not path.is_file():
        raise SessionError(f"{folder}: no session.json; a recording folder needs session.json and its video")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise SessionError(f"{path}: invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}") from None
    except UnicodeDecodeError as e:
        raise SessionError(f"{path}: not a text file ({e.reason}); session.json is JSON") from None
    except OSError as e:
        raise SessionError(f"{path}: cannot be read ({e.strerror or e})") from None
    return parse_session(data, folder, str(path))
