"""Source specs as the app uses them: thin helpers over the one parser and scheme table in
tracking.sources (`parse_spec`, `open_source`, `SCHEMES`; the syntax is documented there and in
docs/architecture.md). Whether a source is live or seekable is the source's own `live` / `seekable`.
"""

from __future__ import annotations

from pathlib import Path

from arapp.store.camera_store import attach_camera
from tracking import sources
from tracking.anchors.defaults import DEFAULT_DICTIONARY
from tracking.errors import SourceError
from tracking.sources import format_spec, parse_spec

# the app's anchors when none are chosen: what `arapp markers board` prints by default, so a first sheet is found without editing anchors
DEFAULT_ANCHORS = [{"kind": "aruco_board", "dictionary": DEFAULT_DICTIONARY, "markers_x": 4, "markers_y": 3,
                    "marker_length": 0.04, "separation": 0.01, "first_id": 0}]


def is_live(source) -> bool:
    """A camera: frames arrive in real time, shown newest-first, never paced or seeked."""
    return bool(getattr(source, "live", False))


def is_seekable(source) -> bool:
    """A recording or video with `seek()` and a known frame count."""
    return (bool(getattr(source, "seekable", False)) and not is_live(source)
            and int(getattr(source, "frame_count", 0) or 0) > 0)


def is_live_spec(spec: str) -> bool:
    """Whether a spec names a camera (before it is opened); False for one that does not parse."""
    try:
        return parse_spec(spec).live
    except SourceError:
        return False


def split_calibration(spec: str) -> tuple[str, str | None]:
    """('file:video.mp4', 'cam.yaml') from 'file:video.mp4?calibration=cam.yaml'."""
    s = parse_spec(spec)
    return format_spec(s.scheme, s.target), s.calibration


def video_spec(video: str, calibration: str | None) -> str:
    return format_spec("file", str(video), calibration)


def recording_folder(spec: str) -> Path | None:
    """The recording folder a spec names, or None when it names something else."""
    try:
        return parse_spec(spec).recording_folder
    except SourceError:
        return None


def display_name(spec: str) -> str:
    """A short name for the window: the recording's or video's name, else the spec itself."""
    try:
        return parse_spec(spec).display_name
    except SourceError:
        return str(spec)  # opening it reports what is wrong


def open_spec(spec: str):
    """Open the source a spec names, with a camera: its own, else one stored for it by the calibration
    wizard, else an estimate from its size (arapp.store.camera_store.attach_camera; the GUI shows which).
    Recordings are read as fast as asked (the player paces them itself)."""
    source = sources.open_source(spec, realtime=False, loop=False)
    attach_camera(source)
    return source


def list_devices() -> list[tuple[str, str]]:
    """(spec, description) of attached cameras; may take a second (DepthAI looks on USB)."""
    return sources.list_devices()
