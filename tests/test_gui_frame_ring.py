"""The shared-memory hand-over of display frames from the pipeline child process to the UI
(arapp.gui.hosts.frame_ring, arapp.gui.hosts.remote): frames arrive intact, a frame nobody took is dropped and its
slot freed, and no /dev/shm segment outlives a stop or a killed child."""

from __future__ import annotations

import hashlib
import multiprocessing as mp
import os
from pathlib import Path

import numpy as np
import pytest

from arapp.gui.hosts.frame_ring import FrameRing, RingReader

SHAPE = (90, 160, 4)


def pattern(i: int) -> np.ndarray:
    """Frame i of the test stream: seeded noise, so the parent can rebuild what the child wrote."""
    return np.random.default_rng(1000 + i).integers(0, 256, SHAPE, dtype=np.uint8)


def segment_exists(name: str) -> bool:
    return Path("/dev/shm", name.lstrip("/")).exists()


def _writer(conn, frames: int) -> None:
    """Child: write `frames` frames into a ring, each announced with its slot and the SHA-256 of its bytes."""
    ring = FrameRing(int(np.prod(SHAPE)), count=3)
    conn.send(("ring", ring.name, ring.slot_bytes, ring.count))
    for i in range(frames):
        img = pattern(i)
        slot = ring.write(img)
        while slot is None:  # every slot held: wait for the parent to give one back
            conn.recv()
            slot = ring.write(img)
        conn.send(("frame", i, slot, hashlib.sha256(img.tobytes()).hexdigest()))
    conn.send(("done", ring.dropped))
    while conn.recv() != "bye":  # the parent has checked everything
        pass
    ring.close()
    conn.close()


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="POSIX shared memory in /dev/shm")
def test_frames_cross_the_process_boundary_intact_and_the_segment_is_unlinked():
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_writer, args=(child, 8))
    proc.start()
    child.close()
    kind, name, slot_bytes, count = parent.recv()
    assert kind == "ring"
    reader = RingReader(name, slot_bytes, count)
    assert not segment_exists(name)  # unlinked as soon as the UI side has mapped it
    seen = []
    while True:
        msg = parent.recv()
        if msg[0] == "done":
            break
        _, i, slot, digest = msg
        got = reader.view(slot, SHAPE)
        assert hashlib.sha256(got.tobytes()).hexdigest() == digest  # the child's own bytes
        assert np.array_equal(got, pattern(i))                       # and the stream's rule
        seen.append(i)
        reader.release(slot)
        parent.send("released")
    assert seen == list(range(8))
    parent.send("bye")
    proc.join(20)
    assert proc.exitcode == 0
    assert not segment_exists(name)


def test_a_full_ring_drops_the_frame_until_a_slot_is_released():
    ring = FrameRing(int(np.prod(SHAPE)), count=3)
    try:
        reader = RingReader(ring.name, ring.slot_bytes, ring.count)
        slots = [ring.write(pattern(i)) for i in range(3)]
        assert sorted(slots) == [0, 1, 2]
        assert ring.write(pattern(3)) is None and ring.dropped == 1  # the UI holds all three
        reader.release(slots[1])
        assert ring.write(pattern(4)) == slots[1]
        assert np.array_equal(reader.view(slots[1], SHAPE), pattern(4))
        assert np.array_equal(reader.view(slots[0], SHAPE), pattern(0))  # a held slot is never written
    finally:
        ring.close()
    assert not segment_exists(ring.name)


def test_a_claimed_slot_is_written_in_place_and_never_handed_out_twice():
    """The child's processing thread writes the display picture into a claimed slot itself (no copy):
    what it writes there is what the UI reads; a claimed slot is not claimed again until published and
    released, or abandoned; an abandoned one is free again."""
    ring = FrameRing(int(np.prod(SHAPE)), count=2)
    try:
        reader = RingReader(ring.name, ring.slot_bytes, ring.count)
        a, view_a = ring.claim(SHAPE)
        b, _ = ring.claim(SHAPE)
        assert a != b and ring.claim(SHAPE) is None and ring.dropped == 1  # both being written
        view_a[...] = pattern(7)
        ring.publish(a)
        assert reader.flags[a] == 1 and np.array_equal(reader.view(a, SHAPE), pattern(7))
        ring.abandon(b)
        assert ring.claim(SHAPE)[0] == b  # free again; a stays held by the UI
        with pytest.raises(ValueError, match="does not fit"):
            ring.claim((SHAPE[0] + 1,) + SHAPE[1:])
    finally:
        del view_a
        ring.close()
    assert not segment_exists(ring.name)


@pytest.mark.skipif(not hasattr(os, "setpriority") or not Path("/proc/self/task").is_dir(),
                    reason="per-thread niceness (Linux)")
def test_background_threads_of_the_pipeline_process_are_niced_and_the_rest_not():
    """The child renices work no frame waits for (SLAM mapping, discovery, ...) once, the capture and
    processing threads keep the process's priority; read back from /proc, not from the code under test."""
    import threading

    from arapp.gui.hosts.remote import BACKGROUND_NICE, renice_background

    def nice_of(tid: int) -> int:
        return int(Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()[16])

    stop = threading.Event()
    mapping = threading.Thread(target=stop.wait, name="slam-mapping", daemon=True)
    processing = threading.Thread(target=stop.wait, name="arapp-process", daemon=True)
    mapping.start()
    processing.start()
    try:
        base = nice_of(threading.get_native_id())
        done: set[int] = set()
        renice_background(done)
        assert nice_of(mapping.native_id) == min(19, base + BACKGROUND_NICE)
        assert nice_of(processing.native_id) == base
        assert mapping.native_id in done and processing.native_id not in done
    finally:
        stop.set()


def _meta(i: int, slot: int) -> dict:
    from arapp.gui.hosts.remote import STATE_KEYS

    return {"index": i, "t": i / 30.0, "state": "lost", "markers": 0, "inliers": 0, "ms_track": 1.0,
            "ms_render": 1.0, "pose": None, "captured_at": 0.0, "processed_at": 0.0, "marks": False, "dropped": 0,
            "w": SHAPE[1], "h": SHAPE[0], "full": False, "slot": slot, **{k: None for k in STATE_KEYS}}


def test_remote_engine_drops_stale_frames_and_frees_their_slots(qtbot):
    from arapp.gui.hosts.remote import RemoteEngine

    ring = FrameRing(int(np.prod(SHAPE)), count=4)
    try:
        eng = RemoteEngine("unused")
        eng._attach_ring(ring.name, ring.slot_bytes, ring.count)
        flags = eng._ring.flags
        a = ring.write(pattern(0))
        eng._frame(None, _meta(0, a))
        b = ring.write(pattern(1))
        eng._frame(None, _meta(1, b))
        # frame 0 was never taken: dropped (latest wins), its slot free for the child again
        assert eng.shown.dropped == 1 and flags[a] == 0 and flags[b] == 1
        shown = eng.take()
        assert shown.result.index == 1
        assert np.array_equal(shown.display, pattern(1))
        q = shown.qimage  # the QImage is over the shared slot itself (no copy)
        assert bytes(q.constBits())[: 4 * SHAPE[1]] == pattern(1)[0].tobytes()
        c = ring.write(pattern(2))
        eng._frame(None, _meta(2, c))
        assert flags[b] == 1  # still shown until the UI takes the next one
        assert eng.take().result.index == 2
        assert flags[b] == 0 and flags[c] == 1
    finally:
        ring.close()


@pytest.mark.skipif(not Path("/dev/shm").is_dir(), reason="POSIX shared memory in /dev/shm")
@pytest.mark.parametrize("ending", ["stop", "killed"])
def test_a_real_child_leaves_no_segment_behind(qtbot, tmp_path, ending):
    from gui_helpers import ANCHORS, TIMEOUT_MS, write_arc_recording

    from arapp.gui.hosts.remote import RemoteEngine

    before = set(os.listdir("/dev/shm"))
    rec = write_arc_recording(tmp_path / "arc", n=6)
    eng = RemoteEngine(str(rec), anchors_json=ANCHORS, loop=True)
    errors = []
    eng.error.connect(lambda *a: errors.append(a))
    eng.start()
    got = []
    eng.frame_ready.connect(lambda: got.append(eng.take()))
    qtbot.waitUntil(lambda: errors or len([s for s in got if s is not None]) >= 3, timeout=TIMEOUT_MS)
    assert not errors
    shown = [s for s in got if s is not None][-1]
    assert shown.ring_slot is not None  # it came through shared memory
    assert shown.display.shape == (480, 640, 4)  # the recording's size: no display size was set
    # the picture is the recording's frame (BGRA, no model loaded): its grey marker image
    assert shown.display[..., :3].std() > 10
    if ending == "killed":
        eng.process.kill()
        eng.process.join(10)
    eng.stop(wait=10.0)
    qtbot.waitUntil(lambda: not eng.running, timeout=TIMEOUT_MS)
    assert errors == [] or ending == "killed"
    assert set(os.listdir("/dev/shm")) - before == set()
