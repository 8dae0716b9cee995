"""The live view's threads without a window: latest-frame-wins hand-over, pacing, replay controls,
and a slow stage dropping frames instead of adding latency."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
import pytest

from arapp.engine.slots import LatestSlot


@dataclass
class Frame:
    index: int
    t: float
    image: np.ndarray


class ListSource:
    """An in-memory seekable source: n frames at `fps`, image value = frame index."""

    def __init__(self, n: int = 30, fps: float = 30.0):
        self.frame_count, self.fps, self.pos = n, fps, 0
        self.closed = False
        self.camera = object()
        self.session = None
        self.live, self.seekable = False, True  # as tracking.sources.Source says it

    def __iter__(self):
        return self

    def __next__(self):
        if self.pos >= self.frame_count:
            raise StopIteration
        i = self.pos
        self.pos += 1
        return Frame(i, i / self.fps, np.full((4, 4, 3), i, np.uint8))

    def seek(self, frame: int) -> None:
        self.pos = frame

    def close(self) -> None:
        self.closed = True


def drain(slot: LatestSlot, until, timeout: float = 5.0) -> list:
    got = []
    deadline = time.perf_counter() + timeout
    while time.perf_counter() < deadline and not until(got):
        item = slot.take(timeout=0.05)
        if item is not None:
            got.append(item)
    return got


def test_latest_slot_keeps_only_the_newest():
    s = LatestSlot()
    assert s.take() is None
    assert s.put(1) is False
    assert s.put(2) is True and s.put(3) is True
    assert s.dropped == 2
    assert s.take() == 3 and s.take() is None


def test_latest_slot_wakes_a_waiting_consumer():
    s = LatestSlot()
    out = []
    t = threading.Thread(target=lambda: out.append(s.take(timeout=5.0)))
    t.start()
    time.sleep(0.05)
    s.wake()
    t.join(1.0)
    assert not t.is_alive() and out == [None]


def test_player_paces_at_the_recorded_times_and_speed():
    from arapp.engine.player import Player

    slot = LatestSlot()
    src = ListSource(12, fps=30.0)
    ended = threading.Event()
    p = Player(lambda: src, slot, speed=2.0, on_end=ended.set)
    p.start()
    got = drain(slot, lambda g: ended.is_set() and slot.peek() is None)
    p.stop()
    p.join(2.0)
    assert [c.index for c in got] == list(range(12))  # a fast consumer sees every frame
    # 11 frame intervals of 1/30 s at 2x speed: 0.183 s
    span = got[-1].captured_at - got[0].captured_at
    assert span == pytest.approx(11 / 30 / 2, abs=0.04)
    assert src.closed


def test_player_seek_step_and_loop():
    from arapp.engine.player import Player

    slot = LatestSlot()
    src = ListSource(20)
    p = Player(lambda: src, slot, playing=False)
    p.start()
    p.seek(7)
    assert drain(slot, lambda g: len(g) >= 1)[0].index == 7  # a seek while paused shows that frame
    p.step()
    assert drain(slot, lambda g: len(g) >= 1)[0].index == 8
    p.step()
    assert drain(slot, lambda g: len(g) >= 1)[0].index == 9
    assert slot.take(timeout=0.2) is None  # paused
    p.set_loop(True)
    p.set_speed(2.0)
    p.seek(17)
    p.play()
    idx = [c.index for c in drain(slot, lambda g: any(c.index == 3 for c in g))]
    assert idx[0] == 17
    # on to the end, then round to the start (a frame may be skipped if this thread is slow to take it)
    wraps = [k for k in range(1, len(idx)) if idx[k] < idx[k - 1]]
    assert len(wraps) == 1 and idx[wraps[0]] <= 1
    assert idx[: wraps[0]] == sorted(idx[: wraps[0]]) and idx[wraps[0]:] == sorted(idx[wraps[0]:])
    p.stop()
    p.join(2.0)


@dataclass
class Result:
    index: int
    t: float
    image: np.ndarray


class SlowPipeline:
    """Takes 40 ms a frame."""

    def process(self, image, t, index):
        time.sleep(0.04)
        return Result(index, t, image)

    def close(self):
        pass


class CountingSource(ListSource):
    """Counts frames actually decoded (yielded)."""

    def __init__(self, *a, live: bool = False, period: float = 0.0, **k):
        super().__init__(*a, **k)
        self.decoded = 0
        self.period = period
        if live:
            self.live, self.seekable = True, False  # a camera: read continuously, never seeks

    def __next__(self):
        if self.period:
            time.sleep(self.period)  # a camera delivering at its own rate
        f = super().__next__()
        self.decoded += 1
        return f


def run_slow_stage(src, on_demand: bool = False) -> tuple[list, LatestSlot, object]:
    from arapp.engine.player import Player
    from arapp.engine.processor import Processor

    captured, shown = LatestSlot(), LatestSlot()
    ended = threading.Event()
    player = Player(lambda: src, captured, on_end=ended.set, on_demand=on_demand)
    proc = Processor(SlowPipeline, captured, shown, skipped=lambda: player.skipped)
    proc.start()
    player.start()
    got = drain(shown, lambda g: bool(g) and g[-1].result.index == src.frame_count - 1, timeout=10.0)
    player.stop()
    proc.stop()
    player.join(2.0)
    return got, captured, player


def test_a_slow_stage_skips_recording_frames_instead_of_adding_latency():
    """A 100 fps recording into a 40 ms/frame pipeline: the reader jumps to the frame due whenever the
    pipeline is free, so skipped frames are never decoded and latency stays one frame's processing."""
    src = CountingSource(100, fps=100.0)
    got, captured, player = run_slow_stage(src, on_demand=True)
    assert got[-1].result.index == 99  # the newest frame always gets through
    assert player.skipped > 40  # ~1 s of frames, ~25 processed
    assert src.decoded == len(got) + captured.dropped
    assert src.decoded < 50
    latency = np.array([g.processed_at - g.captured_at for g in got])
    assert np.median(latency) < 0.1  # one processing time (40 ms) plus scheduling, never a queue
    idx = [g.result.index for g in got]
    assert idx == sorted(idx)
    # the frames shown keep to the clock: frame k is shown about k/100 s after frame 0
    lag = np.array([(g.captured_at - got[0].captured_at) - (g.result.t - got[0].result.t) for g in got])
    assert np.abs(lag).max() < 0.1


def test_a_slow_stage_drops_recording_frames_read_at_their_pace():
    """The default for recordings: read every frame at its time, the slot drops those the pipeline misses."""
    src = CountingSource(100, fps=100.0)
    got, captured, player = run_slow_stage(src)
    assert got[-1].result.index == 99
    assert src.decoded == 100 and captured.dropped > 40 and player.skipped == 0
    latency = np.array([g.processed_at - g.captured_at for g in got])
    assert np.median(latency) < 0.1
    lag = np.array([(g.captured_at - got[0].captured_at) - (g.result.t - got[0].result.t) for g in got])
    assert np.abs(lag).max() < 0.1  # still on the recording's clock


def test_a_slow_stage_drops_live_frames_instead_of_adding_latency():
    """A camera at ~100 fps into a 40 ms/frame pipeline: every frame is read, stale ones are dropped."""
    src = CountingSource(100, fps=100.0, live=True, period=0.01)
    got, captured, player = run_slow_stage(src)
    assert got[-1].result.index == 99
    assert src.decoded == 100 and captured.dropped > 40
    latency = np.array([g.processed_at - g.captured_at for g in got])
    assert np.median(latency) < 0.1


def test_processor_applies_commands_between_frames_and_redraws_when_paused():
    from arapp.engine.player import Captured
    from arapp.engine.processor import Processor

    class Pipeline:
        def __init__(self):
            self.mode = "shaded"
            self.calls = []
            self.draw = False  # redraw() then returns the frame as captured

        def process(self, image, t, index):
            self.calls.append(index)

            @dataclass
            class R:
                index: int
                t: float
                image: np.ndarray
                world_from_camera: object = None

            return R(index, t, image)

        def set_mode(self, m):
            self.mode = m

        def close(self):
            pass

    pipe = Pipeline()
    inbox, out = LatestSlot(), LatestSlot()
    proc = Processor(lambda: pipe, inbox, out)
    proc.start()
    inbox.put(Captured(5, 0.1, np.zeros((2, 2, 3), np.uint8), time.perf_counter()))
    assert out.take(timeout=2.0).result.index == 5
    proc.submit(lambda p: p.set_mode("wireframe"))
    again = out.take(timeout=2.0)  # the paused frame is drawn again with the new setting...
    assert again is not None and again.result.index == 5 and pipe.mode == "wireframe"
    assert pipe.calls == [5]  # ...without tracking it twice
    proc.stop()
    proc.join(2.0)
    assert not proc.is_alive()


def test_gui_recorder_writes_a_recording_that_replays(tmp_path):
    """The record button's writer: frames handed over from the capture thread come back from the recording."""
    from arapp.engine.recording import GuiRecorder, new_recording_folder
    from arapp.engine.player import Captured
    from tracking.camera import Camera
    from tracking.recording.schema import parse_anchors
    from tracking.sources import RecordingSource

    cam = Camera(np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]]), np.zeros(5), 160, 120)
    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05}])
    folder = new_recording_folder(tmp_path)
    rec = GuiRecorder(folder, cam, 25.0, anchors)
    import cv2

    images = []
    for i in range(10):  # smooth pictures (JPEG-friendly) that differ from frame to frame
        img = np.zeros((120, 160, 3), np.uint8)
        img[:, :, 1] = np.linspace(0, 200, 160)[None, :].astype(np.uint8)
        cv2.rectangle(img, (10 + 12 * i, 30), (40 + 12 * i, 80), (255, 255, 255), -1)
        images.append(img)
    t0 = 100.0
    for i, img in enumerate(images):
        rec.write(Captured(i, t0 + i * 0.04, img, time.perf_counter()))
    session = rec.close()
    assert session.anchors[0].id == 3 and session.camera.width == 160
    with RecordingSource(folder) as src:
        frames = list(src)
    assert len(frames) == 10 and rec.dropped == 0
    assert np.allclose([f.t for f in frames], np.arange(10) * 0.04, atol=1e-6)
    # each frame comes back as itself, in order (MJPG is lossy, but far closer to itself than to a neighbour)
    for k in (0, 5, 9):
        err = [np.abs(frames[k].image.astype(int) - im.astype(int)).mean() for im in images]
        assert int(np.argmin(err)) == k and err[k] < 4
    assert new_recording_folder(tmp_path) != folder  # never reuses an existing folder


def test_a_camera_lost_mid_stream_is_reported_not_raised():
    """tracking.sources ends a vanished camera's stream with `.error` set; the player turns it into a
    'Camera lost' report with that message and ends cleanly."""
    from arapp.engine.player import Player

    class DyingCamera(ListSource):
        kind = "v4l2"

        def __init__(self):
            super().__init__(5)
            self.live, self.seekable = True, False
            self.error = None

        def __next__(self):
            if self.pos == 3:
                self.error = "V4L2 /dev/video0 stopped delivering frames after 3 frames (unplugged?)"
                raise StopIteration
            return super().__next__()

    src = DyingCamera()
    errors = []
    slot = LatestSlot()
    p = Player(lambda: src, slot, on_error=lambda title, msg: errors.append((title, msg)))
    p.start()
    p.join(5.0)
    assert not p.is_alive()
    assert errors == [("Camera lost", src.error)]
    assert src.closed


def test_marker_sheets_print_the_anchors_in_use(tmp_path):
    """The tracking panel's 'Marker sheets' button: the sheet of each anchor is detected as that anchor."""
    import cv2

    from arapp.app.sheets import save_sheets

    blocks = [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
               "marker_length": 0.04, "separation": 0.01, "first_id": 0},
              {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 20, "length": 0.05,
               "world_from_anchor": [[1, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]
    paths = save_sheets(blocks, tmp_path, dpi=100)
    pngs = sorted(p for p in paths if p.suffix == ".png")
    assert [p.name.split("_")[0] for p in pngs] == ["anchor0", "anchor1"]
    assert all(p.with_suffix(".pdf").is_file() for p in pngs)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    found = []
    for p in pngs:
        ids = detector.detectMarkers(cv2.imread(str(p)))[1]
        found.append(sorted(int(i) for i in (np.zeros(0) if ids is None else ids).ravel()))
    assert found == [list(range(12)), [20]]


class SlowReadSource(ListSource):
    """Each frame takes `read_s` to read (a decoder), its start time noted."""

    def __init__(self, *a, read_s: float = 0.0, **k):
        super().__init__(*a, **k)
        self.read_s, self.read_at = read_s, []

    def __next__(self):
        self.read_at.append(time.perf_counter())
        time.sleep(self.read_s)
        return super().__next__()


def test_a_recording_reads_its_next_frame_once_the_consumer_is_done_and_still_in_time():
    """A 20 fps recording whose frames take 15 ms to read, a consumer busy 20 ms with each: the next frame is
    read once the consumer waits for it (not beside its work, where the decoding shared the cores with the
    tracking), and it is still handed over when due."""
    from arapp.engine.player import Player

    src = SlowReadSource(24, fps=20.0, read_s=0.015)
    inbox = LatestSlot()
    busy = []   # (took, done) of each frame the consumer worked on
    player = Player(lambda: src, inbox)
    player.start()
    while len(busy) < 20:
        item = inbox.take(timeout=2.0)
        assert item is not None, "no frame within 2 s"
        took = time.perf_counter()
        time.sleep(0.020)
        busy.append((took, time.perf_counter(), item))
    player.stop()
    player.join(2.0)
    # the read of each next frame began after the consumer was done with the frame before it
    after = [src.read_at[item.index + 1] >= done - 0.001 for _, done, item in busy[2:-1]]
    assert np.mean(after) >= 0.7, after
    # and the frames were handed over when due on the replay clock (read by then: waiting for the time itself
    # would make them 15 ms late)
    t0 = busy[0][2].captured_at - busy[0][2].t
    late = [item.captured_at - (t0 + item.t) for _, _, item in busy]
    assert np.median(late) < 0.005, late
    assert [item.index for _, _, item in busy] == list(range(20))
