"""Recorder: round trip from a file-backed source, overwrite protection, limits, Ctrl-C, CLI errors."""

from __future__ import annotations

import json
import os
import signal

import cv2
import numpy as np
import pytest

from arapp.cli import main
from tracking.errors import SessionError, SourceError
from tracking.recording.writer import RecordingWriter, record
from tracking.recording.schema import load_session
from tracking.sources import RecordingSource, open_source

from test_sources import (CAM, NO_DEPTH_FRAME, TIMES, depth_of, depth_rule, frame_image,  # noqa: E402 - shared
                          make_depth_recording, make_recording)

ANCHORS = [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
            "marker_length": 0.04, "separation": 0.01, "first_id": 0},
           {"kind": "qr", "text": "arapp anchor 1", "length": 0.06,
            "world_from_anchor": [[1, 0, 0, 0], [0, 1, 0, 0.3], [0, 0, 1, 0], [0, 0, 0, 1]]}]


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    return make_recording(tmp_path_factory.mktemp("rec") / "r")


def test_round_trip_from_a_file_backed_source_is_frame_for_frame(rec, tmp_path):
    out = tmp_path / "copy"
    with open_source(str(rec)) as src:
        session = record(src, out, anchors=ANCHORS, fourcc="FFV1", progress=lambda s: None)
    assert session.folder == out and session.video == "video.mkv"
    again = load_session(out)  # session.json validates
    assert again.camera.to_dict() == CAM.to_dict() and again.fps == 30.0
    assert [a.to_dict() for a in again.anchors] == [a.to_dict() for a in session.anchors]
    assert again.anchors[1].world_from_anchor[1, 3] == 0.3
    data = json.loads((out / "session.json").read_text())
    assert data["format"] == "arapp-recording/1" and data["source"]["recording"] == str(rec)
    with RecordingSource(rec) as a, RecordingSource(out) as b:
        fa, fb = list(a), list(b)
    assert len(fa) == len(fb) == len(TIMES)
    for x, y in zip(fa, fb):
        assert x.index == y.index and x.t == pytest.approx(y.t, abs=1e-6)
        np.testing.assert_array_equal(x.image, y.image)
    assert (out / "frames.csv").read_text().splitlines()[0] == "frame,t"
    # re-recording a recording keeps its anchors when none are given
    with open_source(str(out)) as src:
        third = record(src, tmp_path / "third", max_frames=2, progress=lambda s: None)
    assert [a.to_dict() for a in load_session(third.folder).anchors] == [a.to_dict() for a in again.anchors]


def test_mjpg_recording_is_close_to_the_source(rec, tmp_path):
    with open_source(str(rec)) as src:
        record(src, tmp_path / "m", progress=lambda s: None)  # default MJPG, the source's anchors
    with RecordingSource(tmp_path / "m") as b:
        frames = list(b)
    assert len(frames) == len(TIMES) and b.session.video == "video.avi"
    for f in frames:
        err = np.abs(f.image.astype(float) - frame_image(f.index)).mean()
        assert err < 4.0
    assert [a.to_dict() for a in b.session.anchors] == [a.to_dict() for a in RecordingSource(rec).session.anchors]


def test_existing_recording_is_not_overwritten_without_force(rec, tmp_path):
    out = tmp_path / "x"
    with open_source(str(rec)) as src:
        record(src, out, max_frames=3, progress=lambda s: None)
    before = (out / "frames.csv").read_text()
    with open_source(str(rec)) as src:
        with pytest.raises(FileExistsError, match="use --force to overwrite"):
            record(src, out, progress=lambda s: None)
    assert (out / "frames.csv").read_text() == before
    with open_source(str(rec)) as src:
        record(src, out, max_frames=5, force=True, progress=lambda s: None)
    assert len(RecordingSource(out).times) == 5


def test_seconds_limit_and_progress_line(rec, tmp_path):
    lines = []
    with open_source(str(rec)) as src:
        s = record(src, tmp_path / "s", seconds=0.3, progress=lines.append)
    times = RecordingSource(s.folder).times
    assert times[-1] >= 0.3 and times[-2] < 0.3
    assert "frames" in lines[-1] and "dropped" in lines[-1]


def test_ctrl_c_finishes_the_file_cleanly(rec, tmp_path):
    # Ctrl-C at Python's default, as in a terminal (a suite started in the background inherits SIGINT ignored)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _ctrl_c_during_recording(rec, tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


def _ctrl_c_during_recording(rec, tmp_path):
    class Interrupting:
        """Wraps a source and sends SIGINT to this process at frame 5, like Ctrl-C."""

        def __init__(self, src):
            self.src, self.camera, self.fps, self.info = src, src.camera, src.fps, src.info

        def __iter__(self):
            for f in self.src:
                if f.index == 5:  # Ctrl-C while frame 5 is being captured: it is the last one written
                    os.kill(os.getpid(), signal.SIGINT)
                yield f

    with open_source(str(rec)) as src:
        lines = []
        s = record(Interrupting(src), tmp_path / "c", progress=lines.append)
    assert "stopped by Ctrl-C" in lines[-1]
    with RecordingSource(s.folder) as r:
        assert [f.index for f in r] == list(range(6))
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # handler restored


def test_writer_checks_frames_and_anchors(tmp_path):
    with pytest.raises(SessionError, match=r"anchors\[0\].length: missing"):
        RecordingWriter(tmp_path / "a", CAM, 30, [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 1}])
    with pytest.raises(SourceError, match="codec 'H264' not supported"):
        RecordingWriter(tmp_path / "b", CAM, 30, fourcc="H264")
    w = RecordingWriter(tmp_path / "c", CAM, 30)
    with pytest.raises(SourceError, match="frame of 320x240 does not match the camera size 160x120"):
        w.write(np.zeros((240, 320, 3), np.uint8), 0.0)
    w.write(frame_image(0), 5.0)
    w.close()
    assert load_session(tmp_path / "c").video == "video.avi"


def test_cli_record_messages(rec, tmp_path, capsys, config_dir):
    video = str(rec / "video.mkv")
    # issue 25: a video without a calibration file records with the estimated camera, said in one line
    # (was refused: "no calibration; pass --calibration"), and the default anchor it wrote is named
    assert main(["record", "--source", video, "--out", str(tmp_path / "v"), "--seconds", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "the estimated camera" in out and "arapp calibrate --source" in out
    assert "wrote the default anchor" in out and "id 0" in out
    assert load_session(tmp_path / "v").source["calibration"].startswith("estimated")
    assert main(["record", "--source", "v4l2:/dev/video99", "--out", str(tmp_path / "w")]) == 2
    assert "no camera at /dev/video99" in capsys.readouterr().err
    bad = tmp_path / "anchors.json"
    bad.write_text("[{]")
    CAM.save_yaml(tmp_path / "cam.yaml")
    assert main(["record", "--source", video, "--calibration", str(tmp_path / "cam.yaml"), "--anchors", str(bad),
                 "--out", str(tmp_path / "z")]) == 2
    assert "anchors.json: invalid JSON at line 1" in capsys.readouterr().err
    bad.write_text(json.dumps({"anchors": ANCHORS}))
    assert main(["record", "--source", video, "--calibration", str(tmp_path / "cam.yaml"), "--anchors", str(bad),
                 "--out", str(tmp_path / "z"), "--seconds", "0.2"]) == 0
    assert len(load_session(tmp_path / "z").anchors) == 2
    assert main(["record", "--source", video, "--calibration", str(tmp_path / "cam.yaml"),
                 "--out", str(tmp_path / "z")]) == 2
    assert "use --force" in capsys.readouterr().err


# -- the depth stream (issue 17 item 2) --------------------------------------------------------------------

def _check_depth_frames(folder, n):
    """Replayed depth within 1 mm of what was given (0.5 mm: rounded to whole millimetres), 0 where the
    files cannot hold a depth, None for the frame that had none; the files themselves by the written rule."""
    with RecordingSource(folder) as src:
        assert src.has_depth
        frames = list(src)
    assert [f.index for f in frames] == list(range(n))
    for f in frames:
        png = folder / "depth" / f"{f.index:06d}.png"
        if f.index == NO_DEPTH_FRAME:
            assert f.depth is None and not png.exists()
            continue
        raw = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)   # OpenCV's reader, not the code under test
        np.testing.assert_array_equal(raw, depth_rule(depth_of(f.index)))
        given = depth_of(f.index)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(given) & (given > 0.0005) & (given < 65.535)
        assert f.depth.dtype == np.float32 and f.depth.shape == given.shape
        assert np.max(np.abs(f.depth[valid] - given[valid])) <= 0.0005 + 1e-6
        assert np.all(f.depth[~valid] == 0)


def test_depth_stream_round_trip_is_exact_to_a_millimetre(tmp_path):
    n = 8
    rec = make_depth_recording(tmp_path / "d", n)
    data = json.loads((rec / "session.json").read_text())
    assert data["depth"] == {"path": "depth", "encoding": "png16", "units": "mm", "scale": 0.001,
                             "aligned_to": "camera"}
    _check_depth_frames(rec, n)
    # arapp record from a source that gives depth records it; --no-depth leaves it out
    lines = []
    with open_source(str(rec)) as src:
        record(src, tmp_path / "copy", fourcc="FFV1", progress=lines.append)
    assert f"{n} frames, {n - 1} with depth" in lines[-1]
    _check_depth_frames(tmp_path / "copy", n)
    with open_source(str(rec)) as src:
        record(src, tmp_path / "plain", fourcc="FFV1", progress=lambda s: None, depth=False)
    assert not (tmp_path / "plain" / "depth").exists()
    assert "depth" not in json.loads((tmp_path / "plain" / "session.json").read_text())
    with RecordingSource(tmp_path / "plain") as src:
        assert not src.has_depth and all(f.depth is None for f in src)


def test_cli_record_keeps_or_drops_depth(tmp_path, capsys):
    rec = make_depth_recording(tmp_path / "d", 6)
    assert main(["record", "--source", str(rec), "--out", str(tmp_path / "a"), "--codec", "FFV1"]) == 0
    assert "depth for 5 frames (depth/, 16-bit PNG, mm)" in capsys.readouterr().out
    _check_depth_frames(tmp_path / "a", 6)
    assert main(["record", "--source", str(rec), "--out", str(tmp_path / "b"), "--no-depth"]) == 0
    assert "depth" not in capsys.readouterr().out and not (tmp_path / "b" / "depth").exists()


def test_writer_refuses_depth_not_aligned_to_the_frame(tmp_path):
    w = RecordingWriter(tmp_path / "c", CAM, 30)
    with pytest.raises(SourceError, match=r"depth of shape \(60, 80\) does not match the frame's 120x160"):
        w.write(frame_image(0), 0.0, depth=np.ones((60, 80)))
    with pytest.raises(SourceError, match="depth must be a float array in metres, got dtype uint16"):
        w.write(frame_image(0), 0.0, depth=np.ones((120, 160), np.uint16))
    w.close()
