"""Writing recordings (`arapp-recording/1`, docs/recording-format.md) and recording from a source.

`RecordingWriter` writes the video (intra-frame MJPG in an .avi by default,
or lossless FFV1 in .mkv), `frames.csv` with the real timestamps,
`session.json` and, for frames that carry depth, the depth stream (`depth/`,
16-bit PNG in millimetres, tracking.recording.depth_stream); `record()` drives it from
any source with a progress line.
"""

from __future__ import annotations

import csv
import json
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from tracking.recording import depth_stream
from tracking.camera import Camera
from tracking.anchors.defaults import DEFAULT_DICTIONARY
from tracking.errors import SourceError
from tracking.poses import write_tum
from tracking.recording.schema import FORMAT, Session, load_session, parse_anchors
from tracking.anchors.kinds import AnchorSpec

# fourcc -> (file extension, VideoWriter backends to try). FFmpeg's MJPEG encoder makes files about half
# the size of OpenCV's built-in one at similar quality; the built-in one (which honours `quality`) is the fallback.
CODECS = {
    "MJPG": (".avi", (cv2.CAP_FFMPEG, cv2.CAP_OPENCV_MJPEG)),
    "FFV1": (".mkv", (cv2.CAP_FFMPEG,)),
}
# what `arapp markers aruco` prints by default (docs/markers.md)
DEFAULT_ANCHORS = [{"kind": "aruco", "dictionary": DEFAULT_DICTIONARY, "id": 0, "length": 0.06}]


def prepare_folder(folder: str | Path, force: bool = False) -> Path:
    """Create the recording folder; refuse to overwrite an existing recording unless `force`."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise FileExistsError(f"{folder}: exists and is not a folder; choose another --out")
    if folder.is_dir() and any(folder.iterdir()):
        if not force:
            raise FileExistsError(f"{folder}: already holds files (a recording?); use --force to overwrite it")
        for name in ("session.json", "frames.csv", "groundtruth.tum"):
            (folder / name).unlink(missing_ok=True)
        for p in folder.glob("video.*"):
            p.unlink()
        depth_dir = folder / depth_stream.FOLDER
        if depth_dir.is_dir():
            for p in depth_dir.glob("*.png"):
                p.unlink()
    folder.mkdir(parents=True, exist_ok=True)
    return folder


class RecordingWriter:
    """Writes one recording folder frame by frame.

    `write(image, t)`: BGR uint8 frame of the camera's size, t in seconds (any
    origin; frames.csv stores t minus the first frame's t). `close()` finishes
    the video and writes frames.csv, session.json and, if poses were given,
    groundtruth.tum. `write(..., depth=)` adds that frame's depth (float metres, aligned to the
    image) to the depth stream; session.json declares the stream when any frame had depth.
    Use as a context manager; closing twice is harmless.
    """

    def __init__(self, folder: str | Path, camera: Camera, fps: float, anchors: list | None = None,
                 source: dict | None = None, fourcc: str = "MJPG", quality: int = 90, force: bool = False):
        if fourcc not in CODECS:
            raise SourceError(f"video codec {fourcc!r} not supported for recordings; use one of {', '.join(CODECS)}")
        blocks = [a.to_dict() if isinstance(a, AnchorSpec) else a for a in (anchors or DEFAULT_ANCHORS)]
        self.anchors = parse_anchors(blocks)
        self.anchor_blocks = blocks
        self.folder = prepare_folder(folder, force)
        self.camera = camera
        self.fps = float(fps)
        self.source = dict(source or {"kind": "file"})
        ext, apis = CODECS[fourcc]
        self.video_name = "video" + ext
        path = self.folder / self.video_name
        for api in apis:
            self._writer = cv2.VideoWriter(str(path), api, cv2.VideoWriter_fourcc(*fourcc), self.fps,
                                           (camera.width, camera.height))
            if self._writer.isOpened():
                self._writer.set(cv2.VIDEOWRITER_PROP_QUALITY, int(quality))  # ignored by FFmpeg's writer
                break
        else:
            raise SourceError(f"{path}: OpenCV cannot write {fourcc} video here (check the folder is writable)")
        self.times: list[float] = []
        self.poses: list[np.ndarray] = []
        self.depth_frames = 0  # frames written with depth
        self._t0: float | None = None
        self.closed = False

    @property
    def frame_count(self) -> int:
        return len(self.times)

    def write(self, image: np.ndarray, t: float, world_from_camera: np.ndarray | None = None,
              depth: np.ndarray | None = None) -> None:
        """Append a frame captured at time t (seconds); `world_from_camera` adds a ground-truth pose,
        `depth` (float HxW, metres along the camera's z, 0 = none, on the image's pixels) its depth."""
        if self.closed:
            raise SourceError(f"{self.folder}: recording already closed")
        h, w = image.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            raise SourceError(f"frame of {w}x{h} does not match the camera size "
                              f"{self.camera.width}x{self.camera.height} of {self.folder}")
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if depth is not None:
            if depth.shape != (h, w):
                raise SourceError(f"depth of shape {depth.shape} does not match the frame's {h}x{w} pixels "
                                  f"({self.folder}); depth must be aligned to the image")
            if self.depth_frames == 0:
                (self.folder / depth_stream.FOLDER).mkdir(exist_ok=True)
            depth_stream.write_png(self.folder / depth_stream.FOLDER / depth_stream.file_name(len(self.times)), depth)
            self.depth_frames += 1
        if self._t0 is None:
            self._t0 = float(t)
        self._writer.write(np.ascontiguousarray(image))
        self.times.append(float(t) - self._t0)
        if world_from_camera is not None:
            self.poses.append(np.asarray(world_from_camera, float))

    def session(self) -> Session:
        return Session(self.folder, self.video_name, self.fps, self.camera, self.anchors, self.source)

    def close(self) -> Session:
        """Finish the video and write frames.csv, session.json (and groundtruth.tum)."""
        if self.closed:
            return self.session()
        self.closed = True
        self._writer.release()
        with open(self.folder / "frames.csv", "w", newline="") as f:
            wr = csv.writer(f)
            wr.writerow(["frame", "t"])
            for i, t in enumerate(self.times):
                wr.writerow([i, f"{t:.6f}"])
        if self.poses:
            if len(self.poses) != len(self.times):
                raise SourceError("ground-truth poses given for some frames only; give one per frame")
            write_tum(self.folder / "groundtruth.tum", self.times, self.poses)
        data = {"format": FORMAT, "video": self.video_name, "fps": self.fps, "camera": self.camera.to_dict(),
                "anchors": self.anchor_blocks, "source": self.source}
        if self.depth_frames:
            data["depth"] = depth_stream.block()
        (self.folder / "session.json").write_text(json.dumps(data, indent=2) + "\n")
        return load_session(self.folder)  # validates what was written

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


@contextmanager
def _stop_on_ctrl_c() -> Iterator[dict]:
    """{"flag": False}, set True by Ctrl-C (SIGINT) while inside, so that a recording finishes its file instead
    of dying mid-write; the previous handler is back on leaving. Not the main thread: Ctrl-C cannot be caught
    there, and the flag stays False."""
    stop = {"flag": False}

    def on_sigint(signum, frame):  # finish the file instead of dying mid-write
        stop["flag"] = True

    previous = None
    installed = False
    try:
        previous = signal.signal(signal.SIGINT, on_sigint)
        installed = True
    except ValueError:  # not the main thread: Ctrl-C cannot be caught here
        pass
    try:
        yield stop
    finally:
        if installed:
            signal.signal(signal.SIGINT, previous)


def _write_frames(source, writer: RecordingWriter, stop: dict, seconds: float | None, max_frames: int | None,
                  progress: Callable[[str], None], depth: bool, name: str) -> int:
    """Write the source's frames (with their depth when `depth`) until it ends, `seconds` of frame time or
    `max_frames` have passed or `stop["flag"]` is set, telling `progress` twice a second; returns the
    frames dropped (gaps in the source's frame indices)."""
    dropped, last_index, wall0, last_print = 0, None, time.monotonic(), 0.0
    for frame in source:
        if last_index is not None and frame.index > last_index + 1:
            dropped += frame.index - last_index - 1
        last_index = frame.index
        writer.write(frame.image, frame.t, depth=getattr(frame, "depth", None) if depth else None)
        n = writer.frame_count
        now = time.monotonic()
        if now - last_print > 0.5:
            last_print = now
            rate = n / max(now - wall0, 1e-6)
            progress(f"\rrecording {name}: {n} frames, {rate:5.1f} fps, {dropped} dropped ")
        if stop["flag"] or (max_frames and n >= max_frames) or (seconds and writer.times[-1] >= seconds):
            break
    return dropped


def record(source, folder: str | Path, anchors: list | None = None, seconds: float | None = None,
           max_frames: int | None = None, force: bool = False, fourcc: str = "MJPG", quality: int = 90,
           progress: Callable[[str], None] | None = None, depth: bool = True,
           name: str | Path | None = None) -> Session:
    """Record frames from `source` (a tracking.sources Source) into `folder` until it ends,
    `seconds` of frame time or `max_frames` have passed, or Ctrl-C (which finishes the file cleanly).

    `anchors` (session.json blocks or AnchorSpecs) defaults to the source's own session
    (when it is a recording), else DEFAULT_ANCHORS.
    Timestamps are the source's own (capture times for cameras). Dropped frames
    are counted from gaps in the source's frame indices. Frames that carry depth
    (depth cameras, recordings with a depth stream) are recorded with it unless
    `depth` is False. `name`: the folder as the progress lines and errors call it (default `folder`; a
    caller recording into a staging folder names the one it becomes). Returns the written Session.
    """
    name = str(folder if name is None else name)
    if anchors is None and getattr(source, "session", None) is not None:
        anchors = source.session.anchors  # re-recording a recording keeps its anchors
    info = dict(getattr(source, "info", {}) or {})
    info.setdefault("kind", getattr(source, "kind", "file"))
    fps = float(getattr(source, "fps", 0) or 30.0)
    writer = RecordingWriter(folder, source.camera, fps, anchors, info, fourcc, quality, force)
    if progress is None:
        progress = lambda s: print(s, end="", file=sys.stderr, flush=True)  # noqa: E731
    try:
        with _stop_on_ctrl_c() as stop:
            dropped = _write_frames(source, writer, stop, seconds, max_frames, progress, depth, name)
            err = getattr(source, "error", None)
    finally:
        session = writer.close()
    n = writer.frame_count
    with_depth = f", {writer.depth_frames} with depth" if writer.depth_frames else ""
    progress(f"\rrecorded {name}: {n} frames{with_depth}, {dropped} dropped"
             + (" (stopped by Ctrl-C)" if stop["flag"] else "") + "\n")
    if n == 0:
        raise SourceError(f"{name}: the source delivered no frames" + (f" ({err})" if err else ""))
    if err:
        progress(f"warning: the source ended with an error: {err}\n")
    return session
