"""Sources: replay of recordings (timestamps, seek, loop, pacing), video files, and every failure message."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError, SourceError
from tracking.recording.writer import RecordingWriter
from tracking.sources import (Frame, RecordingSource, SourceWarning, V4L2Source, VideoFileSource, open_source,
                              read_frames_csv)

W, H = 160, 120
CAM = Camera([[150.0, 0, 79.5], [0, 150.0, 59.5], [0, 0, 1]], [0.01, 0, 0, 0, 0], W, H)
# Irregular capture times (a real camera's), so replay must use frames.csv and not frame / fps.
TIMES = np.cumsum([0.0] + [0.031, 0.035, 0.029, 0.040, 0.033, 0.034, 0.030, 0.036, 0.032, 0.033] * 2)


def frame_image(i: int) -> np.ndarray:
    """A frame that encodes its index in flat blocks (survives lossy codecs) plus some structure."""
    img = np.zeros((H, W, 3), np.uint8)
    img[:, :] = (8 * i + 20, 200 - 6 * i, 128)
    cv2.putText(img, str(i), (20, 80), cv2.FONT_HERSHEY_SIMPLEX, 2.0, (255, 255, 255), 3)
    return img


def index_of(img: np.ndarray) -> int:
    return int(round((float(np.median(img[5:30, 5:30, 0])) - 20) / 8))


def make_recording(folder: Path, fourcc: str = "FFV1", n: int = len(TIMES)) -> Path:
    with RecordingWriter(folder, CAM, 30.0, None, {"kind": "synthetic"}, fourcc=fourcc) as w:
        for i in range(n):
            w.write(frame_image(i), 100.0 + TIMES[i])  # absolute capture clock: stored relative to frame 0
    return folder


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    return make_recording(tmp_path_factory.mktemp("rec") / "r")


@pytest.fixture(scope="module")
def rec_mjpg(tmp_path_factory) -> Path:
    return make_recording(tmp_path_factory.mktemp("recm") / "r", "MJPG")


def test_replay_yields_every_frame_once_with_recorded_timestamps(rec):
    with RecordingSource(rec) as src:
        assert src.frame_count == len(TIMES) and src.camera.to_dict() == CAM.to_dict()
        frames = list(src)
    assert all(isinstance(f, Frame) for f in frames)
    assert [f.index for f in frames] == list(range(len(TIMES)))
    np.testing.assert_allclose([f.t for f in frames], TIMES - TIMES[0], atol=1e-6)
    for f in frames:
        assert f.image.shape == (H, W, 3) and f.image.dtype == np.uint8
        np.testing.assert_array_equal(f.image, frame_image(f.index))  # FFV1 is lossless
    assert src.error is None


def test_seek_by_frame_and_time(rec):
    with RecordingSource(rec) as src:
        assert src.seek(frame=7) == 7
        f = next(iter(src))
        assert f.index == 7 and index_of(f.image) == 7
        # t between frames 11 and 12: the first frame at or after t
        t = (TIMES[11] + TIMES[12]) / 2 - TIMES[0]
        assert src.seek(t=t) == 12
        got = [(f.index, index_of(f.image)) for f in src]
        assert got == [(i, i) for i in range(12, len(TIMES))]
        src.seek(t=TIMES[3] - TIMES[0])  # exact time hits that frame
        assert next(iter(src)).index == 3
        with pytest.raises(SourceError, match="cannot seek to frame 99"):
            src.seek(frame=99)


def test_loop_restarts_and_counts(rec):
    n = len(TIMES)
    with RecordingSource(rec, loop=True) as src:
        it = iter(src)
        frames = [next(it) for _ in range(2 * n + 3)]
    assert [f.index for f in frames] == list(range(n)) * 2 + [0, 1, 2]
    assert [index_of(f.image) for f in frames] == [f.index for f in frames]
    assert src.loops == 2


def test_realtime_pacing_follows_recorded_times(rec):
    with RecordingSource(rec, realtime=True) as src:
        start, late = None, []
        for f in src:
            now = time.monotonic()
            if start is None:
                start = now
            late.append((now - start) - f.t)
    late = np.array(late)
    assert late.min() > -0.001  # never early
    # within a few ms typically; the max allows for a loaded 2-core CI machine, and lateness must not
    # accumulate (each frame is paced against the first one's clock, not the previous frame's)
    assert np.median(late) < 0.004 and late.max() < 0.05, late


def test_plain_video_needs_calibration_for_a_camera(rec_mjpg, tmp_path):
    video = rec_mjpg / "video.avi"
    with open_source(str(video)) as src:
        assert isinstance(src, VideoFileSource) and not src.has_camera
        with pytest.raises(SourceError, match="no calibration; pass --calibration"):
            src.camera  # noqa: B018
        frames = list(src)
    assert [index_of(f.image) for f in frames] == list(range(len(TIMES)))
    np.testing.assert_allclose([f.t for f in frames], np.arange(len(TIMES)) / 30.0)
    CAM.scaled(320, 240).save_yaml(tmp_path / "cam.yaml")  # same lens, calibrated at twice the size
    with open_source(f"file:{video}", calibration=tmp_path / "cam.yaml") as src:
        np.testing.assert_allclose(src.camera.K, CAM.K, atol=1e-9)
    Camera(CAM.K, CAM.dist, 160, 160).save_yaml(tmp_path / "square.yaml")
    with pytest.raises(CalibrationError, match="another aspect ratio"):
        VideoFileSource(video, tmp_path / "square.yaml")


def test_truncated_video_replays_up_to_the_damage_and_reports_it(rec_mjpg, tmp_path):
    bad = tmp_path / "trunc"
    shutil.copytree(rec_mjpg, bad)
    data = (bad / "video.avi").read_bytes()
    (bad / "video.avi").write_bytes(data[: int(len(data) * 0.55)])
    with RecordingSource(bad) as src:
        with pytest.warns(SourceWarning, match="truncated or corrupt"):
            frames = list(src)
    assert 3 <= len(frames) < len(TIMES)
    assert [index_of(f.image) for f in frames] == list(range(len(frames)))
    assert "video.avi" in src.error and f"frame {len(frames)} of {len(TIMES)}" in src.error


def test_corrupt_and_missing_video_name_the_file(rec_mjpg, tmp_path):
    bad = tmp_path / "garbage"
    shutil.copytree(rec_mjpg, bad)
    (bad / "video.avi").write_bytes(np.random.default_rng(0).integers(0, 256, 20000, dtype=np.uint8).tobytes())
    with pytest.raises(SourceError, match=r"garbage/video.avi: (OpenCV cannot open|the video opens but no frame)"):
        RecordingSource(bad)
    (bad / "video.avi").write_bytes(b"")
    with pytest.raises(SourceError, match="video.avi: video file is empty"):
        RecordingSource(bad)
    (bad / "video.avi").unlink()
    with pytest.raises(SourceError, match="video.avi: missing; .*session.json names video 'video.avi'"):
        RecordingSource(bad)


def test_invalid_session_and_frames_csv_messages(rec, tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(rec, bad)
    good = json.loads((bad / "session.json").read_text())
    (bad / "session.json").write_text('{"format": "arapp-recording/1",\n "fps": }')
    with pytest.raises(SessionError, match="invalid JSON at line 2"):
        open_source(str(bad))
    for patch, msg in (({"fps": -1}, "fps: must be a positive number"),
                       ({"camera": {**good["camera"], "K": [[1, 0], [0, 1]]}}, r"camera.K: must be 3x3"),
                       ({"anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0}]},
                        r"anchors\[0\].length: missing"),
                       ({"camera": {**good["camera"], "width": 320, "height": 240}}, "camera is 320x240 but video.mkv has 160x120")):
        (bad / "session.json").write_text(json.dumps({**good, **patch}))
        with pytest.raises(SessionError, match=msg):
            RecordingSource(bad)
    (bad / "session.json").write_text(json.dumps(good))
    (bad / "frames.csv").write_text("frame,t\n0,0.0\n1,0.03\n3,0.06\n")
    with pytest.raises(SessionError, match=r"frames.csv:4: frame 3 out of order; expected 2"):
        RecordingSource(bad)
    (bad / "frames.csv").write_text("index,time\n0,0\n")
    with pytest.raises(SessionError, match="header 'frame,t'"):
        read_frames_csv(bad / "frames.csv")
    with pytest.raises(SessionError, match="no session.json"):
        open_source(str(tmp_path))


def test_source_specs_and_missing_devices(tmp_path):
    with pytest.raises(SourceError, match=r"no camera at /dev/video99 .*arapp sources"):
        open_source("v4l2:/dev/video99")
    with pytest.raises(SourceError, match="no camera at /dev/video99"):
        open_source("v4l2:99")
    with pytest.raises(SourceError, match="v4l2 needs a device"):
        open_source("v4l2:")
    with pytest.raises(SourceError, match="no camera at /dev/video98"):
        V4L2Source(98)
    with pytest.raises(SourceError, match=r"unknown source kind 'rtsp'"):
        open_source("rtsp://camera.local/stream")
    with pytest.raises(SourceError, match="nothing_here: no such recording folder, video or image file"):
        open_source(str(tmp_path / "nothing_here"))
    with pytest.raises(SourceError, match="empty source"):
        open_source("  ")
    not_video = tmp_path / "notes.txt"
    not_video.write_text("hello")
    # issue 25: a text file is named as one (was "OpenCV cannot open" or "no frame")
    with pytest.raises(SourceError, match="notes.txt: a text file, not a video"):
        open_source(f"file:{not_video}")


def test_depthai_without_a_device_says_so():
    from tracking.sources import list_depthai

    if list_depthai():
        pytest.skip("a DepthAI device is attached")
    with pytest.raises(SourceError, match="no DepthAI \\(OAK\\) device found"):
        open_source("depthai")
    with pytest.raises(SourceError, match="no DepthAI \\(OAK\\) device found"):
        open_source("depthai:1844301011B546F500")


def test_arapp_sources_lists_devices_or_says_none(monkeypatch, capsys):
    import tracking.sources as sources
    from arapp.cli import main

    monkeypatch.setattr(sources, "list_v4l2", lambda: [])
    monkeypatch.setattr(sources, "list_depthai", lambda: [])
    assert main(["sources"]) == 0
    out = capsys.readouterr().out
    assert "V4L2 cameras:\n  none found" in out and "No camera is attached" in out
    monkeypatch.setattr(sources, "list_v4l2",
                        lambda: [{"spec": "v4l2:/dev/video0", "device": "/dev/video0", "name": "HD Webcam"}])
    monkeypatch.setattr(sources, "list_depthai",
                        lambda: [{"spec": "depthai:14442C10", "id": "14442C10", "name": "1.1", "state": "UNBOOTED"}])
    assert main(["sources"]) == 0
    out = capsys.readouterr().out
    assert "v4l2:/dev/video0" in out and "HD Webcam" in out and "depthai:14442C10" in out
    assert "No camera is attached" not in out


class FakeCapture:
    """Stands in for cv2.VideoCapture on a V4L2 device: grants 320x240 MJPG, then 'unplugs' after 4 reads."""

    def __init__(self, path, api=None):
        self.path, self.props, self.reads = path, {}, 0

    def isOpened(self):
        return True

    def set(self, prop, value):
        self.props[prop] = value
        return True

    def get(self, prop):
        if prop == cv2.CAP_PROP_FOURCC:
            return float(cv2.VideoWriter_fourcc(*"MJPG"))
        if prop == cv2.CAP_PROP_FPS:
            return 25.0
        if prop == cv2.CAP_PROP_POS_MSEC:
            return 1000.0 + 40.0 * self.reads  # driver timestamps, ms
        return 0.0

    def read(self):
        self.reads += 1
        if self.reads > 4:
            return False, None
        return True, np.full((240, 320, 3), self.reads, np.uint8)

    def release(self):
        pass


def test_v4l2_reports_granted_mode_and_a_vanishing_camera(monkeypatch, tmp_path):
    import tracking.sources as sources

    real_exists = sources.v4l2.os.path.exists
    monkeypatch.setattr(sources.v4l2.os.path, "exists", lambda p: p == "/dev/video7" or real_exists(p))
    monkeypatch.setattr(sources.v4l2.os, "access", lambda p, mode: True)
    monkeypatch.setattr(sources.v4l2.cv2, "VideoCapture", FakeCapture)
    CAM.save_yaml(tmp_path / "cam.yaml")  # 160x120 calibration, scaled to the granted 320x240
    with open_source("v4l2:7", width=1920, height=1080, fps=60, calibration=tmp_path / "cam.yaml") as src:
        assert src.granted == {"width": 320, "height": 240, "fps": 25.0, "fourcc": "MJPG"}
        assert src.requested == {"width": 1920, "height": 1080, "fps": 60, "fourcc": "MJPG"}
        assert src.info["device"] == "/dev/video7" and src.camera.width == 320
        assert src._cap.props[cv2.CAP_PROP_FOURCC] == cv2.VideoWriter_fourcc(*"MJPG")
        with pytest.warns(SourceWarning, match="stopped delivering frames after 4 frames"):
            frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3]
    np.testing.assert_allclose([f.t for f in frames], [0.0, 0.04, 0.08, 0.12])
    assert "/dev/video7" in src.error and "unplugged" in src.error


def test_depthai_source_reads_the_device_calibration(monkeypatch):
    """The depthai v3 call sequence, against a stand-in module (no OAK device in CI)."""
    import sys
    import types
    from datetime import timedelta

    calls = []

    class Info:
        name, state = "1.2.3", "X_LINK_UNBOOTED"

        def __init__(self, ident):
            self.ident = ident

        def getDeviceId(self):
            return self.ident

    class Calib:
        def getCameraIntrinsics(self, socket, w, h):
            calls.append(("intrinsics", socket, w, h))
            return [[800.0, 0, 639.5], [0, 800.0, 359.5], [0, 0, 1]]

        def getDistortionCoefficients(self, socket):
            return [0.1, -0.05, 0, 0] + [0.0] * 10

    class Msg:
        def __init__(self, seq):
            self.seq = seq

        def getCvFrame(self):
            return np.zeros((720, 1280, 3), np.uint8)

        def getTimestamp(self):
            return timedelta(seconds=50 + self.seq / 30)

        def getSequenceNum(self):
            return self.seq

        def getTransformation(self):
            raise AttributeError("older depthai: no transformation")

    class Queue:
        def __init__(self):
            self.seqs = [10, 11, 13]  # frame 12 dropped on the device

        def get(self, timeout):
            return Msg(self.seqs.pop(0)) if self.seqs else None

    class Output:
        def createOutputQueue(self, maxSize, blocking):
            return Queue()

    class CameraNode:
        def build(self, socket):
            calls.append(("build", socket))
            return self

        def requestOutput(self, size, type, fps):
            calls.append(("output", size, type, fps))
            return Output()

    class Pipeline:
        def __init__(self, device):
            self.device = device

        def create(self, node):
            return CameraNode()

        def start(self):
            calls.append("start")

        def stop(self):
            calls.append("stop")

    class Device:
        @staticmethod
        def getAllAvailableDevices():
            return [Info("AAA"), Info("BBB")]

        def __init__(self, info):
            calls.append(("open", info.getDeviceId()))

        def readCalibration(self):
            return Calib()

        def getConnectedCameras(self):
            return ["CAM_A"]  # an OAK-1: no stereo pair, so colour only

        def close(self):
            calls.append("close")

    dai = types.SimpleNamespace(Device=Device, Pipeline=Pipeline, node=types.SimpleNamespace(Camera=CameraNode),
                                CameraBoardSocket=types.SimpleNamespace(CAM_A="CAM_A", CAM_B="CAM_B", CAM_C="CAM_C"),
                                ImgFrame=types.SimpleNamespace(Type=types.SimpleNamespace(BGR888i="BGR888i")))
    monkeypatch.setitem(sys.modules, "depthai", dai)
    with pytest.raises(SourceError, match="no DepthAI device 'CCC'; attached: AAA, BBB"):
        open_source("depthai:CCC")
    with open_source("depthai:BBB") as src:
        assert src.camera.fx == 800.0 and src.camera.dist.size == 14 and src.camera.size == (1280, 720)
        with pytest.warns(SourceWarning, match="no frame for 5 s after 3 frames"):
            frames = list(src)
    assert ("open", "BBB") in calls and ("output", (1280, 720), "BGR888i", 30.0) in calls
    assert ("intrinsics", "CAM_A", 1280, 720) in calls and calls[-2:] == ["stop", "close"]
    assert [f.index for f in frames] == [0, 1, 3]  # the gap shows the dropped frame
    np.testing.assert_allclose([f.t for f in frames], [0, 1 / 30, 3 / 30], atol=2e-6)  # timedelta: 1 us


# -- the spec registry ------------------------------------------------------------------------------------

def test_parse_spec_table(tmp_path):
    from tracking.sources import SourceSpec, parse_spec

    folder = make_recording(tmp_path / "my rec", n=3)
    video = tmp_path / "clip.mp4"
    video.write_bytes(b"x")
    # spec -> (scheme, target, calibration, live, display name); written out here, not derived from the parser
    table = {
        "v4l2:0": ("v4l2", "0", None, True, "v4l2:0"),
        "v4l2:/dev/video2": ("v4l2", "/dev/video2", None, True, "v4l2:/dev/video2"),
        "depthai": ("depthai", "", None, True, "depthai"),
        "depthai:14442C10": ("depthai", "14442C10", None, True, "depthai:14442C10"),
        str(folder): ("file", str(folder), None, False, "my rec"),
        f"file:{folder}": ("file", str(folder), None, False, "my rec"),
        f"file:{folder}/session.json": ("file", f"{folder}/session.json", None, False, "my rec"),
        f"file:{video}?calibration=cam.yaml": ("file", str(video), "cam.yaml", False, "clip.mp4"),
        f"v4l2:1?calibration={tmp_path}/c.yaml": ("v4l2", "1", f"{tmp_path}/c.yaml", True, "v4l2:1"),
    }
    for text, (scheme, target, calib, live, name) in table.items():
        spec = parse_spec(text)
        assert (spec.scheme, spec.target, spec.calibration, spec.live, spec.display_name) == \
            (scheme, target, calib, live, name), text
        assert parse_spec(spec.text) == spec  # written back, read again: the same spec
    assert parse_spec(str(folder)).recording_folder == folder
    assert parse_spec(f"file:{video}").recording_folder is None
    assert parse_spec("v4l2:0").recording_folder is None
    assert isinstance(parse_spec(parse_spec("v4l2:0")), SourceSpec)
    for bad, message in [("rtsp://cam/stream", "unknown source kind 'rtsp'"), ("v4l2:", "v4l2 needs a device"),
                         ("file:x.mp4?fps=3", "unknown option 'fps'"), ("file:x.mp4?calibration=", "is empty"),
                         ("", "empty source")]:
        with pytest.raises(SourceError, match=message):
            parse_spec(bad)


def test_live_and_seekable_are_attributes_of_the_source(rec, tmp_path):
    from tracking.sources import DepthAISource

    assert (RecordingSource.live, RecordingSource.seekable) == (False, True)
    assert (VideoFileSource.live, V4L2Source.live, DepthAISource.live) == (False, True, True)
    with open_source(str(rec)) as src:
        assert not src.live and src.seekable


def test_a_new_scheme_is_one_registry_row(monkeypatch, rec):
    """A camera source added the documented way: a Source subclass and one Scheme row; the parser,
    open_source, `live` and the device list then know it, with no other change."""
    import tracking.sources.registry as registry
    from tracking.sources import Source, list_devices, parse_spec

    class PatternSource(Source):
        kind = "pattern"
        live = True

        def __init__(self, target):
            super().__init__()
            self.target = target
            self._camera = CAM

        def _frames(self):
            for i in range(3):
                yield Frame(i, i / 30, frame_image(i))

    row = registry.Scheme("pattern", lambda target, options: PatternSource(target), PatternSource.live,
                          "'pattern:NAME'", devices=lambda: [("pattern:bars", "test bars")])
    monkeypatch.setitem(registry.SCHEMES, "pattern", row)
    assert parse_spec("pattern:bars").live and parse_spec("pattern:bars").target == "bars"
    with open_source("pattern:bars") as src:
        assert isinstance(src, PatternSource) and src.target == "bars" and len(list(src)) == 3
    assert ("pattern:bars", "test bars") in list_devices()
    assert "'pattern:NAME'" in registry.spec_help()


# -- frames.csv against the video -------------------------------------------------------------------------

def _cut_frames_csv(src_folder: Path, dst: Path, keep: int) -> Path:
    shutil.copytree(src_folder, dst)
    lines = (dst / "frames.csv").read_text().splitlines()
    (dst / "frames.csv").write_text("\n".join(lines[:1 + keep]) + "\n")
    return dst


def test_frames_csv_shorter_than_the_video_is_warned_with_the_file_named(rec_mjpg, tmp_path):
    """Policy (tracking.sources.recording.check_frames_csv): warn and replay the frames frames.csv lists;
    the warning names frames.csv, both counts and the frames left out; the source's `error` says it at the end."""
    n = len(TIMES)
    short = _cut_frames_csv(rec_mjpg, tmp_path / "short", 12)
    with pytest.warns(SourceWarning) as record:
        src = RecordingSource(short)
    message = str(record[0].message)
    assert str(short / "frames.csv") in message and f"lists 12 frames but video.avi has {n}" in message
    assert f"frames 12..{n - 1}" in message
    with src:
        frames = list(src)
    assert [f.index for f in frames] == list(range(12)) and src.error == message
    # One row per video frame: nothing to say.
    with RecordingSource(rec_mjpg) as full:
        assert full.notice is None and len(list(full)) == n and full.error is None


def test_arapp_replay_reports_a_short_frames_csv(rec_mjpg, tmp_path, capsys):
    from arapp.cli import main

    short = _cut_frames_csv(rec_mjpg, tmp_path / "short", 12)
    rc = main(["replay", str(short), "--out", str(tmp_path / "out"), "--no-video", "--no-slam"])
    captured = capsys.readouterr()
    said = [line for line in (captured.out + captured.err).splitlines() if "frames.csv: lists 12 frames" in line]
    assert rc == 0 and len(said) == 1 and said[0].startswith("replay: warning: ")  # once, however often opened


# -- depth: the recording's depth stream and the OAK-D's stereo depth (issue 17 item 2) -------------------

def depth_of(i: int) -> np.ndarray:
    """Frame i's depth (float64 metres): continuous values (not whole millimetres, so rounding is tested),
    holes, and values the 16-bit millimetre files cannot hold (NaN, negative, beyond 65.535 m)."""
    d = 0.25 + 1.5 * np.random.default_rng(100 + i).random((H, W))
    d[::7, ::5] = 0.0
    d[0, 0], d[0, 1], d[0, 2], d[0, 3] = np.nan, -0.5, 70.0, np.inf
    return d


def depth_rule(d: np.ndarray) -> np.ndarray:
    """What a depth file must hold (docs/recording-format.md): whole millimetres, rounded; 0 = no depth."""
    with np.errstate(invalid="ignore"):
        mm = np.rint(d * 1000.0)
        ok = np.isfinite(mm) & (mm > 0) & (mm <= 65535)
    return np.where(ok, mm, 0).astype(np.uint16)


NO_DEPTH_FRAME = 3  # a frame the camera gave no depth for


def make_depth_recording(folder: Path, n: int = 8) -> Path:
    with RecordingWriter(folder, CAM, 30.0, None, {"kind": "synthetic"}, fourcc="FFV1") as w:
        for i in range(n):
            w.write(frame_image(i), TIMES[i], depth=None if i == NO_DEPTH_FRAME else depth_of(i))
    return folder


@pytest.fixture(scope="module")
def depth_rec(tmp_path_factory) -> Path:
    return make_depth_recording(tmp_path_factory.mktemp("depth") / "r")


def _png16(path: Path, shape=(H, W), channels: int = 1, dtype=np.uint16) -> None:
    img = np.full(shape + ((channels,) if channels > 1 else ()), 200, dtype)
    assert cv2.imwrite(str(path), img)


def _edit_block(folder: Path, **changes) -> None:
    data = json.loads((folder / "session.json").read_text())
    data["depth"].update(changes)
    (folder / "session.json").write_text(json.dumps(data))


BAD_DEPTH = {
    "folder gone": (lambda f: shutil.rmtree(f / "depth"), r"depth: missing; .*session.json declares a depth stream"),
    "not a png": (lambda f: (f / "depth" / "000002.png").write_text("not an image"),
                  r"000002.png: not a PNG file; depth frames are 16-bit greyscale PNGs"),
    "8-bit": (lambda f: _png16(f / "depth" / "000002.png", dtype=np.uint8), r"000002.png: a 8-bit PNG"),
    "colour": (lambda f: _png16(f / "depth" / "000002.png", channels=3), r"000002.png: .*colour type 2"),
    "size": (lambda f: _png16(f / "depth" / "000002.png", shape=(60, 80)),
             r"000002.png: depth of 80x60 but the camera is 160x120"),
    "frame beyond the end": (lambda f: shutil.copy(f / "depth" / "000002.png", f / "depth" / "000099.png"),
                             r"000099.png: depth for frame 99, but the recording has frames 0..7"),
    "stray file": (lambda f: (f / "depth" / "notes.txt").write_text("x"),
                   r"notes.txt: unexpected file in the depth folder"),
    "scale": (lambda f: _edit_block(f, scale=-1), r"session.json: depth.scale: must be the metres of one count"),
    "units": (lambda f: _edit_block(f, scale=0.01), r"depth.units says 'mm' but depth.scale is 0.01"),
    "alignment": (lambda f: _edit_block(f, aligned_to="left"), r"depth.aligned_to: must be 'camera'"),
    "encoding": (lambda f: _edit_block(f, encoding="exr"), r"depth.encoding: only 'png16'"),
    "unknown key": (lambda f: _edit_block(f, fps=30), r"depth.fps: unknown key"),
}


@pytest.mark.parametrize("case", list(BAD_DEPTH))
def test_bad_depth_files_are_one_line_errors_naming_the_file(depth_rec, tmp_path, case):
    damage, message = BAD_DEPTH[case]
    folder = tmp_path / "r"
    shutil.copytree(depth_rec, folder)
    damage(folder)
    with pytest.raises(SessionError, match=message) as e:
        RecordingSource(folder)
    assert "\n" not in str(e.value) and str(folder) in str(e.value)
    RecordingSource(folder, depth=False).close()  # the colour frames stay usable without the depth stream


def test_a_truncated_depth_file_ends_the_replay_naming_it(depth_rec, tmp_path):
    folder = tmp_path / "r"
    shutil.copytree(depth_rec, folder)
    png = folder / "depth" / "000005.png"
    png.write_bytes(png.read_bytes()[:200])  # the header survives; the data does not
    with RecordingSource(folder) as src:
        with pytest.warns(SourceWarning, match="000005.png: the depth PNG cannot be decoded"):
            frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3, 4]
    assert "000005.png" in src.error and "\n" not in src.error


def test_recording_without_depth_has_none(rec):
    assert not (rec / "depth").exists() and "depth" not in json.loads((rec / "session.json").read_text())
    with RecordingSource(rec) as src:
        assert not src.has_depth
        assert all(f.depth is None for f in src)


class _FakeDepthAI:
    """A stand-in depthai v3 module for an OAK device with stereo depth (no device in CI). It records the
    calls the source makes and delivers colour frames, or Sync message groups {rgb, depth}."""

    def __init__(self, sockets=("CAM_A", "CAM_B", "CAM_C"), platform="RVC2", n=3, depth_shape=None):
        self.calls = []
        calls = self.calls
        size = {"w": 0, "h": 0}
        mm = lambda seq, shape: (np.arange(shape[0] * shape[1]).reshape(shape) % 4000 + 200 + seq).astype(np.uint16)
        self.mm = mm

        class Img:
            def __init__(self, seq, arr):
                self.seq, self.arr = seq, arr

            def getCvFrame(self):
                return self.arr

            getFrame = getCvFrame

            def getTimestamp(self):
                return timedelta(seconds=10 + self.seq / 30)

            def getSequenceNum(self):
                return self.seq

            def getTransformation(self):
                raise AttributeError("no transformation in this stand-in")

        class Group(dict):
            pass

        class Queue:
            def __init__(self, name):
                self.name, self.seqs = name, list(range(n))

            def get(self, timeout):
                if not self.seqs:
                    return None
                seq = self.seqs.pop(0)
                rgb = Img(seq, np.full((size["h"], size["w"], 3), seq, np.uint8))
                if self.name != "sync.out":
                    return rgb
                shape = depth_shape or (size["h"], size["w"])
                return Group(rgb=rgb, depth=Img(seq, mm(seq, shape)))

        class Output:
            def __init__(self, name):
                self.name = name

            def link(self, target):
                calls.append(("link", self.name, target))

            def createOutputQueue(self, maxSize, blocking):
                calls.append(("queue", self.name))
                return Queue(self.name)

        class CameraNode:
            def build(self, socket):
                self.socket = socket
                return self

            def requestOutput(self, size_, type=None, fps=None, enableUndistortion=None):
                calls.append(("output", self.socket, tuple(size_), type, fps, enableUndistortion))
                if self.socket == "CAM_A":
                    size["w"], size["h"] = size_
                return Output(f"{self.socket}.out")

        class StereoDepth:
            PresetMode = types.SimpleNamespace(DEFAULT="DEFAULT")

            def __init__(self):
                self.depth, self.inputAlignTo = Output("stereo.depth"), "stereo.inputAlignTo"

            def build(self, left, right, presetMode):
                calls.append(("stereo", left.name, right.name, presetMode))
                return self

            def __getattr__(self, name):  # setLeftRightCheck, setSubpixel, setExtendedDisparity
                return lambda *a: calls.append((name, *a))

        class Sync:
            def __init__(self):
                self.inputs = {"rgb": "sync.rgb", "depth": "sync.depth"}
                self.out = Output("sync.out")

            def setSyncThreshold(self, dt):
                calls.append(("sync threshold", dt))

        class ImageAlign:
            def __init__(self):
                self.input, self.inputAlignTo = "align.input", "align.inputAlignTo"
                self.outputAligned = Output("align.outputAligned")

        class Pipeline:
            def __init__(self, device):
                pass

            def create(self, node):
                calls.append(("create", node.__name__))
                return node()

            def start(self):
                calls.append("start")

            def stop(self):
                calls.append("stop")

        class Info:
            name, state = "1.2", "X_LINK_UNBOOTED"

            def getDeviceId(self):
                return "OAKD"

        class Calib:
            def getCameraIntrinsics(self, socket, w, h):
                return [[0.8 * w, 0, (w - 1) / 2], [0, 0.8 * w, (h - 1) / 2], [0, 0, 1]]

            def getDistortionCoefficients(self, socket):
                return [0.1, -0.05, 0, 0] + [0.0] * 10

        class Device:
            @staticmethod
            def getAllAvailableDevices():
                return [Info()]

            def __init__(self, info):
                pass

            def readCalibration(self):
                return Calib()

            def getConnectedCameras(self):
                return list(sockets)

            def getPlatform(self):
                return platform

            def close(self):
                calls.append("close")

        self.module = types.SimpleNamespace(
            Device=Device, Pipeline=Pipeline, Platform=types.SimpleNamespace(RVC2="RVC2", RVC4="RVC4"),
            node=types.SimpleNamespace(Camera=CameraNode, StereoDepth=StereoDepth, Sync=Sync, ImageAlign=ImageAlign),
            CameraBoardSocket=types.SimpleNamespace(CAM_A="CAM_A", CAM_B="CAM_B", CAM_C="CAM_C"),
            ImgFrame=types.SimpleNamespace(Type=types.SimpleNamespace(BGR888i="BGR888i")))


import types  # noqa: E402 - used by the stand-in above
from datetime import timedelta  # noqa: E402


def _open_fake(monkeypatch, fake, **kw):
    import sys

    from tracking.sources import DepthAISource

    monkeypatch.setitem(sys.modules, "depthai", fake.module)
    return DepthAISource(width=W, height=H, fps=30.0, **kw)


@pytest.mark.parametrize("platform", ["RVC2", "RVC4"])
def test_depthai_gives_stereo_depth_aligned_to_the_colour_camera(monkeypatch, platform):
    """The depthai v3 calls for depth aligned to CAM_A, against a stand-in module (not a real OAK-D)."""
    fake = _FakeDepthAI(platform=platform)
    with _open_fake(monkeypatch, fake) as src:
        assert src.has_depth and src.info["depth"]["aligned_to"] == "CAM_A"
        assert np.all(src.camera.dist == 0)  # colour undistorted on the device, like the depth aligned to it
        with pytest.warns(SourceWarning):
            frames = list(src)
    calls = fake.calls
    assert ("output", "CAM_A", (W, H), "BGR888i", 30.0, True) in calls  # undistorted colour
    assert ("output", "CAM_B", (640, 400), None, 30.0, None) in calls
    assert ("stereo", "CAM_B.out", "CAM_C.out", "DEFAULT") in calls
    assert ("setLeftRightCheck", True) in calls and ("setSubpixel", True) in calls
    assert ("link", "CAM_A.out", "sync.rgb") in calls and ("queue", "sync.out") in calls
    if platform == "RVC2":
        assert ("link", "CAM_A.out", "stereo.inputAlignTo") in calls
        assert ("link", "stereo.depth", "sync.depth") in calls
    else:
        assert ("link", "stereo.depth", "align.input") in calls and ("link", "CAM_A.out", "align.inputAlignTo") in calls
        assert ("link", "align.outputAligned", "sync.depth") in calls
    assert [f.index for f in frames] == [0, 1, 2]
    for f in frames:
        assert f.depth.dtype == np.float32 and f.depth.shape == (H, W)
        np.testing.assert_allclose(f.depth, fake.mm(f.index, (H, W)) / 1000.0, atol=1e-6)  # mm -> m


def test_depthai_depth_off_missing_or_at_another_size(monkeypatch):
    fake = _FakeDepthAI()
    with _open_fake(monkeypatch, fake, depth=False) as src:
        with pytest.warns(SourceWarning):
            assert all(f.depth is None for f in src)
    assert not src.has_depth and ("create", "StereoDepth") not in fake.calls
    assert src.camera.dist[0] == 0.1  # colour-only keeps the device's distortion
    oak1 = _FakeDepthAI(sockets=("CAM_A",))
    with _open_fake(monkeypatch, oak1) as src:
        assert not src.has_depth
    with pytest.raises(SourceError, match="has no stereo pair \\(CAM_B and CAM_C\\), so no depth"):
        _open_fake(monkeypatch, _FakeDepthAI(sockets=("CAM_A",)), depth=True)
    half = _FakeDepthAI(depth_shape=(H // 2, W // 2))
    with _open_fake(monkeypatch, half) as src:
        f = next(iter(src))
    assert f.depth.shape == (H, W)
    np.testing.assert_allclose(f.depth[::2, ::2], half.mm(0, (H // 2, W // 2)) / 1000.0, atol=1e-6)
