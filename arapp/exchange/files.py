"""The table of arapp's document formats: for each, the one reader, the error it raises (naming the
file and the field), the suffixes and where the format is described.

    read_document("printer", "my_printer.json")  ->  PrinterProfile

Readers live beside the types they build, and the layers above this one register theirs with one
`register_document(...)` line next to the reader (arapp.geometry.model: "model";
arapp.printing.profile: "printer"); the tracking formats (session, frames, camera) are registered
here. The print job file (arapp.printing.link.job) is the link's own format with its reader there.
Mesh files are arapp.exchange.meshes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError
from tracking.recording.schema import load_session
from tracking.sources import read_frames_csv


def _session(path: Path):
    """session.json, or the recording folder that holds it."""
    return load_session(path.parent if path.name == "session.json" else path)


@dataclass(frozen=True)
class DocumentFormat:
    """One document format: `what` it is, its `suffixes` (or file name), `read(path)`, the `error` that
    read raises (a ValueError naming file and field) and `described` (where the format is written down)."""

    what: str
    suffixes: tuple[str, ...]
    read: Callable[[Path], object]
    error: type[Exception]
    described: str


DOCUMENTS: dict[str, DocumentFormat] = {
    "session": DocumentFormat("recording session", ("session.json",), _session, SessionError,
                              "docs/recording-format.md"),
    "frames": DocumentFormat("recording frame times", ("frames.csv",), read_frames_csv, SessionError,
                             "docs/recording-format.md"),
    "camera": DocumentFormat("camera calibration (OpenCV FileStorage)", (".yaml", ".yml", ".xml", ".json"),
                             Camera.load_yaml, CalibrationError, "docs/recording-format.md"),
}


def register_document(kind: str, fmt: DocumentFormat) -> DocumentFormat:
    """Add a document format under `kind` (one line beside its reader); returns it."""
    DOCUMENTS[kind] = fmt
    return fmt


def read_document(kind: str, path):
    """Read `path` as a document of `kind` (a key of DOCUMENTS) with its one reader."""
    if kind not in DOCUMENTS:
        raise ValueError(f"unknown document kind {kind!r}; known: {', '.join(DOCUMENTS)}")
    return DOCUMENTS[kind].read(Path(path))
