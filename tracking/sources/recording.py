"""Recording folders (`arapp-recording/1`, spec `file:FOLDER` or the folder's path): frames at the
timestamps of frames.csv, checked against the video, with their depth when the recording has a depth
stream (tracking.recording.depth_stream)."""

from __future__ import annotations

import csv
import json
import time
import warnings
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from tracking.recording import depth_stream
from tracking.errors import SessionError, SourceError
from tracking.recording.schema import Session, load_session

from .base import Frame, Source, SourceWarning, _as_bgr, _open_capture, _probe_first_frame, _seek_capture

# Some containers (MKV/FFV1) give an estimated frame count; a difference this small is not reported.
FRAME_COUNT_SLACK = 1


def read_frames_csv(path: Path) -> np.ndarray:
    """Timestamps (seconds) from a recording's frames.csv (`frame,t`, one row per frame, in order)."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as e:
        raise SessionError(f"{path}: cannot be read ({e.strerror})") from None
    if not rows or [c.strip() for c in rows[0]] != ["frame", "t"]:
        raise SessionError(f"{path}: first line must be the header 'frame,t'")
    times = []
    for lineno, row in enumerate(rows[1:], 2):
        if not row or not "".join(row).strip():
            continue
        if len(row) != 2:
            raise SessionError(f"{path}:{lineno}: expected 'frame,t', got {','.join(row)!r}")
        try:
            frame, t = int(row[0]), float(row[1])
        except ValueError:
            raise SessionError(f"{path}:{lineno}: frame must be an integer and t a number, got {row!r}") from None
        if frame != len(times):
            raise SessionError(f"{path}:{lineno}: frame {frame} out of order; expected {len(times)}")
        if not np.isfinite(t) or (times and t < times[-1]):
            raise SessionError(f"{path}:{lineno}: t must be finite and not decrease, got {t}")
        times.append(t)
    return np.asarray(times, float)


def check_frames_csv(times: np.ndarray, video_frames: int | None, csv_path: Path, video_path: Path) -> str | None:
    """None when frames.csv has one row per video frame (as far as the container's count tells), else the
    problem in one line. Policy: a frames.csv with fewer rows than the video is replayed (the frames it
    lists) with this warning, since its timestamps are all there is; one with more rows ends at the
    video's last frame (reported by the replay as a decoding stop)."""
    if video_frames is None or abs(len(times) - video_frames) <= FRAME_COUNT_SLACK:
        return None
    if len(times) < video_frames:
        return (f"{csv_path}: lists {len(times)} frames but {video_path.name} has {video_frames}; frames "
                f"{len(times)}..{video_frames - 1} have no timestamp and are not replayed (frames.csv was cut "
                "short: re-record, or add their rows)")
    return (f"{csv_path}: lists {len(times)} frames but {video_path.name} has only {video_frames}; the replay "
            f"ends at frame {video_frames - 1} (the video was cut short)")


class RecordingSource(Source):
    """A recording folder (`arapp-recording/1`): frames at their recorded timestamps.

    realtime: pace frames to their timestamps (sleeping, no busy wait) from the
    moment the first one is taken, scaled by `speed`; else as fast as possible.
    loop: start over after the last frame (`index` and `t` restart; `.loops`
    counts the restarts). `seek(frame=)` / `seek(t=)` sets the next frame.
    depth: read the recording's depth stream when it has one (`has_depth`): each
    frame's `depth` is then float32 metres on the image's pixels (None for a
    frame without a depth file). The depth files are checked when the recording
    is opened (names, sizes, 16-bit greyscale PNG); one that then fails to
    decode ends the replay with `.error` naming it.
    """

    kind = "recording"
    seekable = True

    def __init__(self, folder: str | Path, realtime: bool = False, loop: bool = False, speed: float = 1.0,
                 depth: bool = True):
        super().__init__()
        self.folder = Path(folder)
        self.session: Session = load_session(self.folder)
        self._camera = self.session.camera
        self.fps = self.session.fps
        self.realtime, self.loop, self.speed = bool(realtime), bool(loop), float(speed)
        if self.speed <= 0:
            raise SourceError(f"replay speed must be positive, got {speed}")
        self.video_path = self.session.video_path
        if not self.video_path.is_file():
            raise SourceError(f"{self.video_path}: missing; {self.folder / 'session.json'} names video "
                              f"{self.session.video!r} but the folder has no such file")
        self._cap = _open_capture(self.video_path)
        first = _probe_first_frame(self._cap, self.video_path)
        h, w = first.shape[:2]
        if (w, h) != (self.camera.width, self.camera.height):
            self._cap.release()
            raise SessionError(f"{self.folder / 'session.json'}: camera is {self.camera.width}x{self.camera.height} "
                               f"but {self.video_path.name} has {w}x{h} frames")
        self._pos = 1  # the capture's next frame
        csv_path = self.folder / "frames.csv"
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.video_frame_count = n if n > 0 else None  # the container's count (estimated for some, e.g. MKV)
        self.notice: str | None = None  # a problem the recording has that does not stop it (shown, warned)
        if csv_path.is_file():
            self.times = read_frames_csv(csv_path)
            self.notice = check_frames_csv(self.times, self.video_frame_count, csv_path, self.video_path)
            if self.notice:
                warnings.warn(self.notice, SourceWarning, stacklevel=2)
        else:
            if n <= 0:
                raise SourceError(f"{self.video_path}: frame count unknown and no frames.csv; add frames.csv")
            self.times = np.arange(n) / self.fps
        self.frame_count = len(self.times)
        self.depth: depth_stream.DepthStream | None = None
        if depth:
            try:
                self.depth = self._open_depth()
            except SessionError:
                self._cap.release()
                raise
        self._next = 0
        self._pace_origin: float | None = None
        self._first_img = first
        self.loops = 0
        self.info = {"kind": "file", "recording": str(self.folder), **{k: v for k, v in self.session.source.items()
                                                                      if k != "kind"}}

    def _open_depth(self) -> depth_stream.DepthStream | None:
        """The depth stream session.json declares (checked), or None. The session reader
        (tracking.recording.schema) ignores the block, so it is read here from the file itself."""
        path = self.folder / "session.json"
        data = json.loads(path.read_text(encoding="utf-8"))  # load_session has read it already: valid JSON
        spec = depth_stream.parse_block(data.get("depth"), self.folder, str(path))
        if spec is None:
            return None
        return depth_stream.DepthStream(spec, self.frame_count, self.camera.width, self.camera.height)

    @property
    def has_depth(self) -> bool:
        """Whether frames carry depth (the recording has a depth stream and it is read)."""
        return self.depth is not None

    def describe(self) -> str:
        return f"recording {self.folder}"

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if self.frame_count else 0.0

    def seek(self, frame: int | None = None, t: float | None = None) -> int:
        """Make `frame` (or the first frame at or after time `t`, seconds) the next one; returns its index."""
        if (frame is None) == (t is None):
            raise ValueError("seek: give exactly one of frame= or t=")
        if t is not None:
            frame = int(np.searchsorted(self.times, t - 1e-9, side="left"))
        if not 0 <= frame < self.frame_count:
            raise SourceError(f"{self.describe()}: cannot seek to frame {frame}; it has frames 0..{self.frame_count - 1}")
        self._next = int(frame)
        self._pace_origin = None
        return self._next

    def _read(self, i: int) -> np.ndarray | None:
        """Frame i of the video (sequential reads; seeks by position, checked, else by decoding forward)."""
        if i == 0 and self._first_img is not None and self._pos == 1:
            img, self._first_img = self._first_img, None
            return img
        self._first_img = None
        if i != self._pos:
            self._cap, ok = _seek_capture(self._cap, self.video_path, i)
            if not ok:
                return None
            self._pos = i
        ok, img = self._cap.read()
        if not ok or img is None:
            return None
        self._pos = i + 1
        return _as_bgr(img)

    def _frames(self) -> Iterator[Frame]:
        self._pace_origin = None
        while not self.closed:
            if self._next >= self.frame_count:
                if not self.loop:
                    if self.notice and self.error is None:
                        self.error = self.notice  # replay reports it with the other early ends
                    return
                self._next = 0
                self.loops += 1
                self._pace_origin = None
            i = self._next
            img = self._read(i)
            if img is None:
                self._fail(f"{self.video_path}: decoding stopped at frame {i} of {self.frame_count} "
                           f"(truncated or corrupt video); frames before it were replayed")
                return
            depth = None
            if self.depth is not None:
                try:
                    depth = self.depth.read(i)
                except SourceError as e:
                    self._fail(f"{e}; frames before {i} were replayed")
                    return
            t = float(self.times[i])
            if self.realtime:
                now = time.monotonic()
                if self._pace_origin is None:
                    self._pace_origin = now - t / self.speed
                wait = self._pace_origin + t / self.speed - now
                if wait > 0:
                    time.sleep(wait)
            self._next = i + 1
            yield Frame(i, t, img, depth)

    def _release(self) -> None:
        self._cap.release()

