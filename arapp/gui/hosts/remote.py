"""The live view's pipeline in a child process: capture, tracking and rendering never share the UI's GIL.

Why: the tracker and renderer are Python code running on several threads;
in the GUI's own process they hold the interpreter lock often enough that
the UI thread stalls for hundreds of milliseconds on a loaded 2-core machine
(benchmarks/bench_gui.py measures it). In a child process they cannot.

The child (started from a fork server that has the heavy modules imported
already, so it starts in a fraction of a second) runs the same `Player` and
`Processor` threads as `workers.Engine` (an `arapp.engine.live.LiveEngine`). The processing thread writes
each finished picture, scaled to the view and in the screen's 32-bit format, straight into a slot of
shared memory (`arapp.gui.hosts.frame_ring`) and sends the slot's number with the frame's metadata on a
pipe of its own; that pipe wakes the UI thread's event loop (a QSocketNotifier), which wraps the
newest slot in place as a QImage and paints it: no copy of the picture and no thread in between.
Frames that came meanwhile are dropped and free their slots at once; the frame shown frees its slot
when the next one is taken. Everything else (events, and whole frames when `full_frames` asks for
them) comes on the command pipe, read by a receiver thread.
Commands go the other way as the `arapp.engine.commands` dataclasses themselves
(a model travels as its path plus control-point edits; the child loads and
tessellates it itself).

`RemoteEngine` has the interface of `workers.Engine`.
"""

from __future__ import annotations

import gc
import multiprocessing as mp
import os
from multiprocessing import forkserver
import threading
import time
import traceback

import numpy as np
from PySide6.QtCore import QObject, QSocketNotifier, Signal
from PySide6.QtGui import QImage

from arapp.engine.commands import Pause, Play, SetDisplaySize, SetModel, Step, Stop
from arapp.engine.live import LiveEngine, SourceInfo
from arapp.engine.processor import Shown
from arapp.engine.slots import LatestSlot
from arapp.gui.hosts.frame_ring import FrameRing, RingReader
from arapp.engine.pipeline import FrameResult
from tracking.camera import Camera
from tracking.recording.schema import parse_anchors

PRELOAD = ["numpy", "cv2", "arapp.engine.pipeline", "arapp.engine.live", "tracking.sources", "tracking.fusion",
           "arapp.geometry.model", "trimesh"]
# the model state each frame carries back (LiveEngine.state)
STATE_KEYS = ("mesh_faces", "model_gen", "mode", "resets", "toolpaths", "discovery")
# The capture, processing and anchor-detection threads run at the UI's own priority: the UI thread only
# takes and paints (about a millisecond a frame) and, asleep between frames, is let on a core first when
# it wakes, while a niced pipeline fell far behind the machine's other work (+5 gave it a third of a
# normal process's share of the CPU). Work that no frame waits for runs niced, each thread once it exists.
BACKGROUND_NICE = 5
BACKGROUND_THREADS = ("slam-mapping", "arapp-discovery", "arapp-toolpaths", "arapp-record", "arapp-ar-video")
_context = None
_context_lock = threading.Lock()


def context():
    """The fork-server context, created once per process with the heavy modules preloaded."""
    global _context
    with _context_lock:
        if _context is None:
            ctx = mp.get_context("forkserver")
            ctx.set_forkserver_preload(PRELOAD)
            _context = ctx
        return _context


def warm_up() -> None:
    """Start the fork server in the background now, so the first source opens quickly."""

    def start():
        context()
        forkserver.ensure_running()

    threading.Thread(target=start, name="arapp-forkserver", daemon=True).start()


# Results cross the process boundary as the pipeline's own FrameResult (`image`: the full-size composite,
# only with full_frames, else None). `extra` holds the child's view of the model: mesh_faces, model_gen,
# mode, resets, and `toolpaths`: the print preview drawn (arapp.engine.toolpaths info dict, None before any).
# Commands travel as the arapp.engine.commands dataclasses themselves; events come back as (event name, *args).


# ---------------------------------------------------------------------------------------------- child


def info_dict(info: SourceInfo) -> dict:
    """A SourceInfo as plain data for the pipe (camera and anchors as their JSON dicts)."""
    return {"name": info.name, "seekable": info.seekable, "frame_count": info.frame_count, "fps": info.fps,
            "camera": info.camera.to_dict(), "live": info.live, "anchors": [a.to_dict() for a in info.anchors]}


def info_from_dict(d: dict) -> SourceInfo:
    return SourceInfo(name=d["name"], seekable=d["seekable"], frame_count=d["frame_count"], fps=d["fps"],
                      camera=Camera.from_dict(d["camera"]), anchors=parse_anchors(d["anchors"]), live=d["live"])


class _Child:
    """Everything that runs in the child process: a LiveEngine, its events sent up the pipe."""

    def __init__(self, conn, frames, spec: str, anchors_json: list, speed: float, loop: bool, playing: bool,
                 full_frames: bool, display_size):
        self.conn = conn
        self.frames = frames  # the pipe of shared-memory frames (and their rings), read by the UI thread
        self.frames_lock = threading.Lock()
        self.full_frames = full_frames
        self.ring: FrameRing | None = None
        self.rings: list[FrameRing] = []  # every ring made, unlinked when the child ends
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self._claim: tuple[int, np.ndarray] | None = None  # the ring slot the next display picture is written to
        self._frozen = False  # gc.freeze() done after the first frame
        self.engine = LiveEngine(spec, anchors=parse_anchors(anchors_json), speed=speed, loop=loop,
                                 playing=playing, display_size=display_size,
                                 display_buffer=None if full_frames else self.claim_slot)
        ev = self.engine.events
        # each frame goes up from the processing thread as soon as it is made (no hop through another thread)
        ev.ready.connect(self.send_ready)
        ev.opened.connect(lambda info: self.send(("opened", info_dict(info))))
        ev.error.connect(lambda title, message: self.send(("error", title, message)))
        ev.ended.connect(lambda: self.send(("ended",)))
        ev.recorded.connect(lambda folder: self.send(("recorded", folder)))
        ev.toolpaths.connect(lambda info: self.send(("toolpaths", info)))

    def send(self, msg, *blobs) -> None:
        with self.lock:
            try:
                self.conn.send(msg)
                for b in blobs:
                    self.conn.send_bytes(b)
            except (OSError, EOFError, BrokenPipeError):
                self.stop.set()  # the UI is gone

    def post(self, msg) -> None:
        """Send a message of the frames pipe (a ring, or a frame in one)."""
        with self.frames_lock:
            try:
                self.frames.send(msg)
            except (OSError, EOFError, BrokenPipeError):
                self.stop.set()

    def command_loop(self) -> None:
        while not self.stop.is_set():
            try:
                command = self.conn.recv()
            except (EOFError, OSError):
                break
            if isinstance(command, Stop):
                break
            try:
                self.engine.apply(command)
            except Exception as exc:  # noqa: BLE001 - a bad setting is told to the user
                self.send(("error", "Cannot apply the change", str(exc) or type(exc).__name__))
        self.stop.set()

    def claim_slot(self, shape: tuple) -> np.ndarray | None:
        """Processing thread: the shared-memory slot to write the next display picture into (in place: the
        picture crosses to the UI without a copy), or None when the UI holds every slot (the frame is then
        dropped in send_frame)."""
        nbytes = int(np.prod(shape))
        if self.ring is None or self.ring.slot_bytes < nbytes:
            if self.ring is not None:
                self._abandon()
                try:
                    self.ring.shm.close()  # the UI has its own mapping; the name is unlinked at the end
                except BufferError:
                    pass  # a picture made here still points into it; the mapping goes with the process
            self.ring = FrameRing(nbytes)
            self.rings.append(self.ring)
            self.post(("ring", self.ring.name, self.ring.slot_bytes, self.ring.count))
        self._abandon()
        self._claim = self.ring.claim(shape)
        return None if self._claim is None else self._claim[1]

    def _abandon(self) -> None:
        """A claimed slot whose picture was not sent (an error between): free again."""
        if self._claim is not None:
            self.ring.abandon(self._claim[0])
            self._claim = None

    def send_ready(self) -> None:
        """Processing thread, after each frame: send the newest one up."""
        shown = self.engine.take(timeout=0.0)
        if shown is not None:
            self.send_frame(shown)
            if not self._frozen:
                # the modules, model, tracker and GL objects alive after the first frame stay for good: out of
                # the collector's reach, a full collection is a young-objects one (~50 ms less, now and then,
                # in whichever frame it falls)
                gc.freeze()
                self._frozen = True

    def send_frame(self, shown) -> None:
        r = shown.result
        bgra = shown.display
        meta = {"index": int(r.index), "t": float(r.t), "state": r.state, "markers": int(r.markers),
                "inliers": int(r.inliers), "ms_track": float(r.ms_track), "ms_render": float(r.ms_render),
                "pose": None if r.world_from_camera is None else np.asarray(r.world_from_camera).tolist(),
                "captured_at": shown.captured_at, "processed_at": shown.processed_at, "marks": shown.marks,
                "dropped": shown.dropped_capture, "w": bgra.shape[1], "h": bgra.shape[0],
                "full": self.full_frames, **{k: r.extra[k] for k in STATE_KEYS},
                "ambiguous": bool(r.extra.get("ambiguous", False))}   # a head-on marker's tilt undecided
        if not self.full_frames:
            # the picture goes through shared memory; the pipe carries the metadata and the slot's number
            claim, self._claim = self._claim, None
            if claim is not None and claim[1] is bgra:
                slot = claim[0]  # written in place by the processing thread
                self.ring.publish(slot)
            else:
                if claim is not None:
                    self.ring.abandon(claim[0])
                if self.ring is None or not self.ring.fits(bgra):
                    self.claim_slot(bgra.shape)
                    self._abandon()
                slot = self.ring.write(bgra)
            if slot is None:
                return  # the UI still holds every slot: this frame is dropped, a newer one follows
            meta["slot"], meta["dropped"] = slot, meta["dropped"] + self.ring.dropped
            meta["stages"] = {**shown.stages, "sent": time.perf_counter()}
            self.post(("frame", meta))
            return
        blobs = [memoryview(np.ascontiguousarray(bgra)).cast("B")]
        if self.full_frames:
            for img in (r.image, shown.frame):
                meta.setdefault("full_shape", list(img.shape))
                blobs.append(memoryview(np.ascontiguousarray(img)).cast("B"))
        meta["stages"] = {**shown.stages, "sent": time.perf_counter()}
        self.send(("frame", meta), *blobs)

    def run(self) -> None:
        threading.Thread(target=self.command_loop, name="arapp-commands", daemon=True).start()
        engine = self.engine
        engine.start()
        reniced: set[int] = set()
        while not self.stop.wait(0.5):
            renice_background(reniced)
            if not engine.running and engine.captured.peek() is None:
                break
        engine.stop(wait=10.0)

    def close_rings(self) -> None:
        for ring in self.rings:
            try:
                ring.close()
            except (OSError, BufferError):
                pass  # closed already (replaced by a bigger ring)
        self.rings = []


def renice_background(done: set[int]) -> None:
    """Lower the priority of this process's BACKGROUND_THREADS not yet in `done` (their native ids, added) by
    BACKGROUND_NICE below the calling thread's."""
    try:
        nice = min(19, os.getpriority(os.PRIO_PROCESS, 0) + BACKGROUND_NICE)
    except (OSError, AttributeError):
        return
    for t in threading.enumerate():
        tid = t.native_id
        if tid is None or tid in done or not t.name.startswith(BACKGROUND_THREADS):
            continue
        done.add(tid)
        try:
            os.setpriority(os.PRIO_PROCESS, tid, nice)  # Linux: one thread's niceness
        except (OSError, AttributeError):
            pass  # gone meanwhile, or a platform without per-thread niceness


def child_main(conn, frames, spec, anchors_json, speed, loop, playing, full_frames, display_size) -> None:
    """Entry point of the child process."""
    child = None
    try:
        child = _Child(conn, frames, spec, anchors_json, speed, loop, playing, full_frames, display_size)
        child.run()
    except Exception as exc:  # noqa: BLE001 - last resort: tell the UI why the process ends
        try:
            conn.send(("error", "The tracking process failed", f"{exc}\n{traceback.format_exc(limit=3)}"))
        except (OSError, EOFError):
            pass
    finally:
        if child is not None:
            child.close_rings()
        frames.close()
        conn.close()


# ------------------------------------------------------------------------------------------------ UI


class EngineSignals(QObject):
    """The signals of both GUI engines, delivered on the UI thread: opened(SourceInfo), frame_ready(),
    error(title, message), ended() (a recording reached its end without loop), recorded(folder),
    toolpaths_shown(info)."""

    opened = Signal(object)
    frame_ready = Signal()
    error = Signal(str, str)
    ended = Signal()
    recorded = Signal(str)
    toolpaths_shown = Signal(object)


class RemoteEngine(EngineSignals):
    """`workers.Engine`'s interface, with the LiveEngine in a child process."""

    def __init__(self, spec: str, *, name: str = "", anchors_json: list | None = None, speed: float = 1.0,
                 loop: bool = False, playing: bool = True, full_frames: bool = False, parent=None):
        super().__init__(parent)
        self.spec, self.name = spec, name or spec
        self.anchors_json = anchors_json or []
        self.speed, self.loop, self._playing = speed, loop, playing
        self.full_frames = full_frames
        self.shown = LatestSlot()
        self.info: SourceInfo | None = None
        self._notify_pending = threading.Event()
        self._send_lock = threading.Lock()
        self._stopping = False
        self.display_size = None
        self.process = None
        self.conn = None
        self._frames = None    # the frames pipe's reading end, watched by the UI thread's event loop
        self._notifier: QSocketNotifier | None = None
        self._receiver = None
        self._ring: RingReader | None = None
        self._taken: Shown | None = None  # the frame the UI took last (shown now): its slot is held
        self._events = {"ring": self._attach_ring, "opened": self._opened, "error": self.error.emit,
                        "ended": self._ended, "recorded": self.recorded.emit,
                        "toolpaths": self.toolpaths_shown.emit}

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        ctx = context()
        parent_conn, child_conn = ctx.Pipe(duplex=True)
        frames_in, frames_out = ctx.Pipe(duplex=False)
        self.conn, self._frames = parent_conn, frames_in
        self.process = ctx.Process(target=child_main, name="arapp-pipeline", daemon=True,
                                   args=(child_conn, frames_out, self.spec, self.anchors_json, self.speed,
                                         self.loop, self._playing, self.full_frames, self.display_size))
        # the frames wake this (the UI) thread's event loop themselves: no hop through another thread
        self._notifier = QSocketNotifier(frames_in.fileno(), QSocketNotifier.Type.Read, self)
        self._notifier.activated.connect(self._frames_arrived)
        self._receiver = threading.Thread(target=self._receive, args=(child_conn, frames_out),
                                          name="arapp-receive", daemon=True)
        self._receiver.start()

    def _receive(self, child_conn, frames_out) -> None:
        """Receiver thread: start the child (the fork server may take a moment), then turn its messages
        (all but the shared-memory frames) into slot items and signals."""
        try:
            self.process.start()
        except Exception as exc:  # noqa: BLE001
            self.error.emit("Cannot start the tracking process", str(exc))
            return
        child_conn.close()
        frames_out.close()
        conn = self.conn
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                break
            if msg[0] == "frame":
                self._frame(conn, msg[1])
            else:
                self._events[msg[0]](*msg[1:])
        if not self._stopping:
            self.process.join(2.0)
            code = self.process.exitcode
            if code not in (0, None):
                self.error.emit("The tracking process stopped",
                                f"the process running capture, tracking and rendering ended with code {code}")

    def _opened(self, d: dict) -> None:
        self.info = info_from_dict(d)
        self.opened.emit(self.info)

    def _ended(self) -> None:
        self._playing = False
        self.ended.emit()

    def _attach_ring(self, name: str, slot_bytes: int, count: int) -> None:
        try:
            self._ring = RingReader(name, slot_bytes, count)
        except FileNotFoundError:
            self._ring = None  # the child ended meanwhile and unlinked it; its frames are not shown

    @staticmethod
    def _release(shown) -> None:
        held = getattr(shown, "ring_slot", None) if shown is not None else None
        if held is not None:
            shown.ring_slot = None
            held[0].release(held[1])

    def _frames_arrived(self, *_args) -> None:
        """UI thread, the frames pipe readable: read every message waiting, then take the newest frame (the
        ones before it are dropped and their slots freed at once)."""
        frames = self._frames
        got = False
        try:
            while frames is not None and frames.poll():
                msg = frames.recv()
                if msg[0] == "frame":
                    self._frame(None, msg[1], notify=False)
                    got = True
                else:
                    self._events[msg[0]](*msg[1:])
        except (EOFError, OSError):
            self._close_frames()  # the child has ended
        if got:
            self._notify()

    def _close_frames(self) -> None:
        if self._notifier is not None:
            self._notifier.setEnabled(False)
            self._notifier.deleteLater()
            self._notifier = None
        if self._frames is not None:
            self._frames.close()
            self._frames = None

    def _notify(self) -> None:
        # one notification at a time: the UI takes the newest frame, however many came meanwhile
        if not self._notify_pending.is_set():
            self._notify_pending.set()
            self.frame_ready.emit()

    def _frame(self, conn, meta: dict, notify: bool = True) -> None:
        w, h = meta["w"], meta["h"]
        held = None
        if "slot" in meta:
            if self._ring is None:
                return
            bgra = self._ring.view(meta["slot"], (h, w, 4))  # in place, no copy
            held = (self._ring, meta["slot"])
            full = []
        else:
            data = conn.recv_bytes()
            full = [conn.recv_bytes() for _ in range(2)] if meta.get("full") else []
            bgra = np.frombuffer(data, np.uint8).reshape(h, w, 4)
        received = time.perf_counter()
        q = QImage(bgra.data, w, h, w * 4, QImage.Format.Format_RGB32)
        q._keep = bgra
        image = frame = None
        if full:
            shape = tuple(meta["full_shape"])
            image = np.frombuffer(full[0], np.uint8).reshape(shape)
            frame = np.frombuffer(full[1], np.uint8).reshape(shape)
        pose = None if meta["pose"] is None else np.asarray(meta["pose"], float)
        extra = {k: meta[k] for k in STATE_KEYS}
        if meta.get("ambiguous"):
            extra["ambiguous"] = True
        result = FrameResult(meta["index"], meta["t"], pose, meta["state"], meta["markers"], meta["inliers"],
                             meta["ms_track"], meta["ms_render"], image, extra)
        # timing marks (perf_counter seconds, one clock for both processes on Linux): the child's, received
        # here, taken by the UI thread (set in take)
        stages = {**meta.get("stages", {}), "received": received}
        shown = Shown(result, bgra, frame, meta["captured_at"], meta["processed_at"],
                      dropped_capture=meta["dropped"], qimage=q, marks=meta["marks"], stages=stages)
        shown.ring_slot = held
        self._release(self.shown.replace(shown))  # a frame nobody took is dropped: its slot is free again
        if notify:
            self._notify()

    def send(self, command) -> None:
        """Send an arapp.engine.commands command to the child (a model as its path and edits only)."""
        if isinstance(command, SetModel):
            command = command.for_transfer()
        elif isinstance(command, SetDisplaySize):
            self.display_size = command.size  # also the child's start value, when it is not started yet
        if isinstance(command, Play):
            self._playing = True
        elif isinstance(command, (Pause, Step)):
            self._playing = False
        if self.conn is None:
            return
        with self._send_lock:
            try:
                self.conn.send(command)
            except (OSError, BrokenPipeError):
                pass  # the child is gone; the receiver reports why

    def stop(self, wait: float = 0.0) -> None:
        self._stopping = True
        self.send(Stop())
        self._close_frames()  # nothing more is shown
        if wait > 0 and self.process is not None:
            deadline = time.perf_counter() + wait
            if self._receiver is not None:
                self._receiver.join(max(0.0, deadline - time.perf_counter()))
            if self.process.pid is not None:
                self.process.join(max(0.0, deadline - time.perf_counter()))
                if self.process.is_alive():
                    self.process.terminate()

    @property
    def running(self) -> bool:
        return (self._receiver is not None and self._receiver.is_alive()) or (
            self.process is not None and self.process.pid is not None and self.process.is_alive())

    # -- UI side -----------------------------------------------------------------------
    def take(self) -> Shown | None:
        self._notify_pending.clear()
        shown = self.shown.take()
        if shown is not None:
            shown.dropped_paint = self.shown.dropped
            # the UI now shows this frame instead of the previous one, whose slot the child may reuse
            self._release(self._taken)
            self._taken = shown
            shown.stages["taken"] = time.perf_counter()
        return shown

    @property
    def playing(self) -> bool:
        return self._playing
