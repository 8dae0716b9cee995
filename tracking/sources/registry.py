"""Source specs and the one table of schemes that open them.

A spec is `SCHEME:TARGET[?calibration=CAM.yaml]`, or a plain path (the `file`
scheme): `recordings/board_orbit`, `file:clip.mp4?calibration=cam.yaml`, `photos/` (a folder of images),
`v4l2:0`, `v4l2:/dev/video2`, `depthai`, `depthai:<device id>`.
`parse_spec` is the one parser (CLI and GUI); `open_source` opens what a spec
names through its scheme's row in `SCHEMES`.

Adding a camera source: a module holding a `Source` subclass (with `kind`,
`live`, `seekable`) and, for devices, a function listing the attached ones;
plus one `Scheme(...)` row in `SCHEMES` below, whose `open(target, options)`
builds the source (a lambda or a small function here).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable
from urllib.parse import parse_qsl

from tracking.errors import SessionError, SourceError

from .base import Source
from .images import IMAGE_SUFFIXES, ImageFolderSource, image_files, is_image
from .oak import DepthAISource, list_depthai
from .recording import RecordingSource
from .v4l2 import V4L2Source, list_v4l2
from .video import VideoFileSource


@dataclass(frozen=True)
class SourceOptions:
    """What a caller may ask of any source; each scheme uses what applies to it.

    realtime/loop: recordings (pace to timestamps, start over); calibration: OpenCV YAML for video
    files and V4L2 cameras; width/height (pixels), fps, fourcc: cameras (fps also a video file's rate).
    """

    realtime: bool = False
    loop: bool = False
    calibration: str | None = None
    width: int | None = None
    height: int | None = None
    fps: float | None = None
    fourcc: str | None = "MJPG"


def _open_file(target: str, options: SourceOptions) -> Source:
    """A recording folder (or its session.json) as a RecordingSource, a folder of images without session.json
    or one image file as an ImageFolderSource, a video file as a VideoFileSource."""
    path = Path(target)
    if path.name == "session.json" and path.is_file():
        path = path.parent
    if path.is_dir() and not (path / "session.json").exists():
        if not image_files(path):
            raise SessionError(f"{path}: no session.json, so not a recording folder, and no images "
                               f"({', '.join(s[1:] for s in IMAGE_SUFFIXES)}) to play as frames; give a recording "
                               "folder, a video or a folder of images")
        return ImageFolderSource(path, options.calibration, options.fps)
    if path.is_dir():
        if options.calibration is not None:
            raise SourceError(f"{path}: a recording carries its own camera in session.json; drop --calibration")
        return RecordingSource(path, realtime=options.realtime, loop=options.loop)
    if path.is_file() and is_image(path):
        return ImageFolderSource(path, options.calibration, options.fps)
    if path.is_file():
        return VideoFileSource(path, options.calibration, options.fps)
    raise SourceError(f"{path}: no such recording folder, video or image file")


def _open_v4l2(target: str, options: SourceOptions) -> Source:
    return V4L2Source(target, options.width, options.height, options.fps, options.fourcc, options.calibration)


def _open_depthai(target: str, options: SourceOptions) -> Source:
    if options.calibration is not None:
        raise SourceError("a DepthAI camera reads its calibration from the device; drop --calibration")
    return DepthAISource(target or None, options.width or 1280, options.height or 720, options.fps or 30.0)


def _v4l2_devices() -> list[tuple[str, str]]:
    return [(d["spec"], f"V4L2 {d.get('name', '?')} ({d.get('device', '')})") for d in list_v4l2()]


def _depthai_devices() -> list[tuple[str, str]]:
    return [(d["spec"], f"DepthAI {d.get('name', '?')} {d.get('id', '')} ({d.get('state', '')})")
            for d in list_depthai()]


@dataclass(frozen=True)
class Scheme:
    """One way to name a source: `name` (the spec prefix), `open(target, options)`, whether its sources
    are `live` devices, whether a target is required after the colon, the `help` text of its specs,
    and `devices()` listing attached ones as (spec, description) (None for files)."""

    name: str
    open: Callable[[str, SourceOptions], Source]
    live: bool
    help: str
    target_required: bool = True
    target_name: str = "a target"
    devices: Callable[[], list[tuple[str, str]]] | None = None


# The registry: one row per scheme (the first is the default for plain paths).
SCHEMES: dict[str, Scheme] = {s.name: s for s in (
    Scheme("file", _open_file, RecordingSource.live, "a recording folder, video file, folder of images or image "
           "(optionally 'file:PATH', a video or images with '?calibration=CAM.yaml')"),
    Scheme("v4l2", _open_v4l2, V4L2Source.live, "'v4l2:0', 'v4l2:/dev/video2'", target_name="a device",
           devices=_v4l2_devices),
    Scheme("depthai", _open_depthai, DepthAISource.live, "'depthai' or 'depthai:<device id>'",
           target_required=False, devices=_depthai_devices),
)}
DEFAULT_SCHEME = "file"
OPTION_KEYS = ("calibration",)


def spec_help() -> str:
    """The kinds of spec, for --help texts and error messages."""
    return ", ".join(s.help for s in SCHEMES.values())


SPEC_HELP = spec_help()


@dataclass(frozen=True)
class SourceSpec:
    """A parsed spec: `scheme` (a key of SCHEMES), `target` (path, device; may be empty), `calibration`."""

    scheme: str
    target: str
    calibration: str | None = None

    @property
    def live(self) -> bool:
        """Whether the source is a live device (shown newest-first, never paced or seeked)."""
        return SCHEMES[self.scheme].live

    @property
    def text(self) -> str:
        """The spec written back canonically (what parse_spec reads to the same SourceSpec)."""
        return format_spec(self.scheme, self.target, self.calibration)

    @property
    def recording_folder(self) -> Path | None:
        """The recording folder it names (a folder holding session.json, or that file), else None."""
        if self.scheme != "file":
            return None
        p = Path(self.target)
        if p.name == "session.json":
            p = p.parent
        return p if (p / "session.json").is_file() else None

    @property
    def display_name(self) -> str:
        """A short name for menus: the recording folder's or video file's name, else the spec."""
        folder = self.recording_folder
        if folder is not None:
            return folder.name
        if self.scheme == "file":
            return Path(self.target).name
        return format_spec(self.scheme, self.target)

    def __str__(self) -> str:
        return self.text


def format_spec(scheme: str, target: str = "", calibration: str | None = None) -> str:
    """A spec string: 'v4l2:0', 'depthai', 'file:clip.mp4?calibration=cam.yaml'."""
    text = f"{scheme}:{target}" if target else scheme
    return text + (f"?calibration={calibration}" if calibration else "")


def parse_spec(spec) -> SourceSpec:
    """The one spec parser (see the module docstring); SourceError names the spec and lists the kinds."""
    if isinstance(spec, SourceSpec):
        return spec
    text = str(spec).strip()
    if not text:
        raise SourceError(f"empty source; give {SPEC_HELP}")
    calibration = None
    base = text
    if "?" in text and not Path(text).exists():  # an existing path may hold '?' in its name
        base, query = text.split("?", 1)
        for key, value in parse_qsl(query, keep_blank_values=True):
            if key not in OPTION_KEYS:
                raise SourceError(f"unknown option {key!r} in source {text!r}; the options are "
                                  f"{', '.join(OPTION_KEYS)} (e.g. file:clip.mp4?calibration=cam.yaml)")
            if not value:
                raise SourceError(f"option {key} in source {text!r} is empty; give a file, e.g. ?{key}=cam.yaml")
            calibration = value
    scheme, colon, rest = base.partition(":")
    if scheme in SCHEMES and (colon or not SCHEMES[scheme].target_required) and not Path(base).exists():
        if SCHEMES[scheme].target_required and not rest:
            raise SourceError(f"{scheme} needs {SCHEMES[scheme].target_name} after the colon: {SCHEMES[scheme].help}")
        return SourceSpec(scheme, rest, calibration)
    if colon and len(scheme) > 1 and scheme.isalnum() and not Path(base).exists():
        raise SourceError(f"unknown source kind {scheme!r} in {text!r}; give {SPEC_HELP}")
    return SourceSpec(DEFAULT_SCHEME, base, calibration)


def open_source(spec, realtime: bool = False, loop: bool = False, calibration: str | Path | None = None,
                width: int | None = None, height: int | None = None, fps: float | None = None,
                fourcc: str | None = "MJPG") -> Source:
    """Open the source a spec names (see SPEC_HELP) through its scheme. Options apply where they make sense:
    realtime/loop to recordings, calibration to video files and V4L2, size/fps to cameras."""
    parsed = parse_spec(spec)
    calib = parsed.calibration
    if calibration is not None:
        if calib is not None and str(calibration) != calib:
            raise SourceError(f"two calibrations for {parsed.text}: {calib} in the spec and {calibration}; give one")
        calib = str(calibration)
    options = SourceOptions(realtime, loop, calib, width, height, fps, fourcc)
    return SCHEMES[parsed.scheme].open(parsed.target, options)


def list_devices() -> list[tuple[str, str]]:
    """(spec, description) of every attached camera of every scheme that lists devices (DepthAI looks on
    USB, which may take a second)."""
    out: list[tuple[str, str]] = []
    for scheme in SCHEMES.values():
        if scheme.devices is not None:
            out += scheme.devices()
    return out
