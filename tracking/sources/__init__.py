"""Frame sources: recordings, video files, V4L2 cameras and OAK (DepthAI) cameras.

Every source is an iterable of `Frame(index, t, image)` (t seconds, image BGR
uint8) carrying its `camera` (tracking.camera.Camera), with `close()` and
context-manager use, and says whether it is `live` and `seekable`. A source
that ends because of damage or a vanished camera sets `.error` (a message the
caller can show) and warns with `SourceWarning` instead of raising from inside
the loop. Sources are opened with `open_source(spec)` from a spec parsed by
`parse_spec` (registry.py: the table of schemes): `file:PATH` or a plain path
(recording folder, video file or folder of images), `v4l2:0`, `v4l2:/dev/video2`, `depthai`,
`depthai:<device id>`.

Modules: base (the interface), video, images, recording, v4l2, oak (one per kind),
registry (specs and schemes).
"""

from .base import Frame, Source, SourceWarning
from .images import ImageFolderSource
from .oak import DepthAISource, list_depthai
from .recording import RecordingSource, check_frames_csv, read_frames_csv
from .registry import (
    SCHEMES,
    SPEC_HELP,
    Scheme,
    SourceOptions,
    SourceSpec,
    format_spec,
    list_devices,
    open_source,
    parse_spec,
    spec_help,
)
from .v4l2 import V4L2Source, list_v4l2
from .video import VideoFileSource

__all__ = ["Frame", "Source", "SourceWarning", "DepthAISource", "list_depthai", "RecordingSource",
           "check_frames_csv", "read_frames_csv", "SCHEMES", "SPEC_HELP", "Scheme", "SourceOptions", "SourceSpec",
           "format_spec", "list_devices", "open_source", "parse_spec", "spec_help", "V4L2Source", "list_v4l2",
           "VideoFileSource", "ImageFolderSource"]
