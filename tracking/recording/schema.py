"""session.json of a recording (`arapp-recording/1`) and the anchors it declares.

See docs/recording-format.md: lengths in metres; the world is the frame of
the first anchor; every other anchor carries `world_from_anchor`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracking.anchors.kinds import KINDS, AnchorSpec, kind_names
from tracking.anchors.kinds.base import aruco_dictionary_names
from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError
from tracking.jsonfile import read_json

FORMAT = "arapp-recording/1"
# The registered kind names at import time; the table itself (kinds registered later included) is KINDS.
ANCHOR_KINDS = kind_names()

__all__ = ["FORMAT", "ANCHOR_KINDS", "AnchorSpec", "aruco_dictionary_names", "parse_rigid", "parse_anchor",
           "parse_anchors", "Session", "parse_session", "load_session"]


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
    The block's `kind` picks the registered `AnchorKind` (tracking/anchors/kinds), which checks its fields.
    `folder`: where a relative dictionary-file path is read from (default: the current folder)."""
    if not isinstance(d, dict):
        raise SessionError(f"{where}: must be an object")
    kind = d.get("kind")
    if not isinstance(kind, str) or kind not in KINDS:
        raise SessionError(f"{where}.kind: must be one of {', '.join(KINDS)}, got {kind!r}")
    anchor = KINDS[kind].parse(d, where, folder)
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


def read_anchor_blocks(path: str | Path) -> list:
    """The anchor blocks of an anchors JSON file (`--anchors`): a list as in session.json, or an object
    with an "anchors" list (a session.json itself). Unparsed; SessionError naming the file when unreadable."""
    data = read_json(path, "anchors", SessionError, expect=None)
    return data.get("anchors") if isinstance(data, dict) else data


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
        data = json.loads(path.read_text(encoding="utf-8-sig"))   # (a byte-order mark, as Windows editors write)
    except json.JSONDecodeError as e:
        raise SessionError(f"{path}: invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}") from None
    except UnicodeDecodeError as e:
        raise SessionError(f"{path}: not a text file ({e.reason}); session.json is JSON") from None
    except OSError as e:
        raise SessionError(f"{path}: cannot be read ({e.strerror or e})") from None
    return parse_session(data, folder, str(path))
