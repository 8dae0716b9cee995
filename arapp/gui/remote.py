"""The live view's pipeline in a child process: capture, tracking and rendering never share the UI's GIL.

Why: the tracker and renderer are Python code running on several threads;
in the GUI's own process they hold the interpreter lock often enough that
the UI thread stalls for hundreds of milliseconds on a loaded 2-core machine
(benchmarks/bench_gui.py measures it). In a child process they cannot.

The child (started from a fork server that has the heavy modules imported
already, so it starts in a fraction of a second) runs the same `Player` and
`Processor` threads as `workers.Engine`. Finished frames, already scaled to
the view and converted to the screen's 32-bit format, come back over a pipe;
a receiver thread in the UI process wraps them as QImages into a
latest-frame-wins slot and signals the UI thread, which only paints.
Commands go the other way as small tuples (a model travels as its path plus
control-point edits; the child loads and tessellates it itself).

`RemoteEngine` has the interface of `workers.Engine`.
"""

from __future__ import annotations

import multiprocessing as mp
import threading
import time
import traceback

import numpy as np
from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QImage

from arapp.gui.slots import LatestSlot
from arapp.gui.workers import ProcessingStage, Shown, SourceInfo
from arapp.pipeline import FrameResult

PRELOAD = ["numpy", "cv2", "arapp.pipeline", "arapp.gui.workers", "arapp.gui.sourcespec", "arapp.gui.editing",
           "tracking.sources", "tracking.tracker", "arapp.geometry.model", "trimesh"]
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
        from multiprocessing import forkserver

        forkserver.ensure_running()

    threading.Thread(target=start, name="arapp-forkserver", daemon=True).start()


# Results cross the process boundary as the pipeline's own FrameResult (`image`: the full-size composite,
# only with full_frames, else None). `extra` holds the child's view of the model: mesh_faces, model_gen,
# mode, resets, and `toolpaths`: the print preview drawn (arapp.gui.toolpaths info dict, None before any).


# ---------------------------------------------------------------------------------------------- child


class _Child:
    """Everything that runs in the child process."""

    def __init__(self, conn, spec: str, anchors_json: list, speed: float, loop: bool, playing: bool,
                 full_frames: bool, display_size):
        from arapp.gui.workers import Player

        self.conn = conn
        self.spec = spec
        self.anchors_json = anchors_json
        self.full_frames = full_frames
        self.lock = threading.Lock()
        self.captured, self.shown = LatestSlot(), LatestSlot()
        self.info = None
        self.autoplay = playing
        self.first_ready = False
        self.stage = ProcessingStage(display_size)
        self.state = {"mesh_faces": 0, "model_gen": 0, "mode": "shaded", "resets": 0, "toolpaths": None}
        self.models: dict = {}
        self.stop = threading.Event()
        self.player = Player(self._open, self.captured, speed=speed, loop=loop, playing=False,
                             on_open=self._opened, on_error=self.send_error, on_end=lambda: self.send(("ended",)))
        self.player._steps = 1
        from arapp.gui.toolpaths import ToolpathStage

        self.toolpaths = ToolpathStage(self.submit, self._toolpaths_shown, self.send_error)

    def _toolpaths_shown(self, info: dict) -> None:
        """Pipeline thread: the print preview `info` is drawn from the next frame on."""
        self.state["toolpaths"] = info
        self.send(("toolpaths", info))

    def send(self, msg, *blobs) -> None:
        with self.lock:
            try:
                self.conn.send(msg)
                for b in blobs:
                    self.conn.send_bytes(b)
            except (OSError, EOFError, BrokenPipeError):
                self.stop.set()  # the UI is gone

    def send_error(self, title: str, message: str) -> None:
        self.send(("error", title, message))

    def _open(self):
        from arapp.gui.sourcespec import open_spec

        return open_spec(self.spec)

    def _opened(self, source) -> None:
        from arapp.gui.workers import Processor, source_info
        from tracking.session import parse_anchors

        from arapp.gui.sourcespec import display_name

        info = source_info(source, display_name(self.spec), parse_anchors(self.anchors_json))
        if not info.anchors:
            raise RuntimeError(f"{self.spec}: no anchors are configured; set them in the tracking panel")
        self.info = info
        processor = Processor(lambda: self._make_pipeline(info), self.captured, self.shown,
                              on_ready=self._ready, on_error=self.send_error, skipped=lambda: self.player.skipped)
        self.stage.start(processor)
        if info.live and self.autoplay:
            self.player.play()
        self.send(("opened", {"name": info.name, "seekable": info.seekable, "frame_count": info.frame_count,
                              "fps": info.fps, "camera": info.camera.to_dict(), "live": info.live,
                              "anchors": [a.to_dict() for a in info.anchors]}))

    @staticmethod
    def _make_pipeline(info):
        from arapp.pipeline import Pipeline

        return Pipeline(info.camera, info.anchors, status_line=False)

    def _ready(self) -> None:
        if not self.first_ready:
            self.first_ready = True
            if self.autoplay:
                self.player.play()

    def submit(self, fn) -> None:
        """fn(pipeline) between frames in the pipeline thread (queued until it exists); any thread."""
        self.stage.submit(fn)

    # -- commands from the UI ------------------------------------------------------------
    def _load(self, path: str, edits: dict):
        from arapp.gui.editing import edited_model, model_mesh
        from arapp.pipeline import load_display_model

        base = self.models.get(path)
        if base is None:
            base = self.models[path] = load_display_model(path)
        model = edited_model(base, edits) if edits else base
        model_mesh(model)  # tessellate here, in the command thread, not between frames
        return model

    def command(self, msg) -> None:
        kind = msg[0]
        p = self.player
        if kind == "play":
            self.autoplay = True
            p.play()
        elif kind == "pause":
            self.autoplay = False
            p.pause()
        elif kind == "step":
            self.autoplay = False
            p.step(msg[1])
        elif kind == "seek":
            p.seek(msg[1])
        elif kind == "speed":
            p.set_speed(msg[1])
        elif kind == "loop":
            p.set_loop(msg[1])
        elif kind == "display_size":
            self.stage.set_display_size(msg[1])
        elif kind == "reset":
            def reset(pipe):
                pipe.reset()
                self.state["resets"] += 1

            self.submit(reset)
        elif kind == "mode":
            mode = msg[1]

            def set_mode(pipe):
                pipe.set_mode(mode)
                self.state["mode"] = mode

            self.submit(set_mode)
        elif kind == "highlight":
            self.stage.set_highlight(msg[1])
        elif kind == "placement":
            placement = msg[1]
            self.submit(lambda pipe: pipe.set_placement(placement))
        elif kind == "model":
            _, gen, path, edits, placement, mode = msg
            try:
                model = self._load(path, edits) if path else None
            except Exception as exc:  # noqa: BLE001 - the UI shows it
                self.send_error("Cannot open the model", str(exc))
                return

            def set_model(pipe):
                pipe.set_mode(mode)
                pipe.set_model(model, placement)
                self.state.update(mode=mode, model_gen=gen,
                                  mesh_faces=0 if pipe.mesh is None else int(len(pipe.mesh.faces)))

            self.submit(set_model)
        elif kind == "toolpaths":
            self.toolpaths.request(msg[1], gen=msg[2])
        elif kind == "record_start":
            from arapp.gui import recording

            try:
                p.recorder = recording.start(msg[1], self.info, p.source)
            except Exception as exc:  # noqa: BLE001
                self.send_error("Cannot record", str(exc))
                return
            self.send(("recording", str(msg[1])))
        elif kind == "record_stop":
            rec, p.recorder = p.recorder, None
            if rec is not None:
                try:
                    rec.close()
                except Exception as exc:  # noqa: BLE001
                    self.send_error("Recording failed", str(exc))
                    return
                self.send(("recorded", str(rec.folder)))
        elif kind == "stop":
            self.stop.set()

    def command_loop(self) -> None:
        while not self.stop.is_set():
            try:
                msg = self.conn.recv()
            except (EOFError, OSError):
                break
            try:
                self.command(msg)
            except Exception as exc:  # noqa: BLE001
                self.send_error("Cannot apply the change", str(exc) or type(exc).__name__)
        self.stop.set()
        self.shown.wake()

    def run(self) -> None:
        threading.Thread(target=self.command_loop, name="arapp-commands", daemon=True).start()
        self.player.start()
        while not self.stop.is_set():
            shown = self.shown.take(timeout=0.5)
            if shown is None:
                if not self.player.is_alive() and not self.stage.is_alive():
                    if self.captured.peek() is None:
                        break
                continue
            r = shown.result
            bgra = shown.qimage._keep
            meta = {"index": int(r.index), "t": float(r.t), "state": r.state, "markers": int(r.markers),
                    "inliers": int(r.inliers), "ms_track": float(r.ms_track), "ms_render": float(r.ms_render),
                    "pose": None if r.world_from_camera is None else np.asarray(r.world_from_camera).tolist(),
                    "captured_at": shown.captured_at, "processed_at": shown.processed_at,
                    "dropped": shown.dropped_capture, "w": bgra.shape[1], "h": bgra.shape[0],
                    "full": self.full_frames, **self.state}
            blobs = [memoryview(np.ascontiguousarray(bgra)).cast("B")]
            if self.full_frames:
                for img in (r.image, shown.frame):
                    meta.setdefault("full_shape", list(img.shape))
                    blobs.append(memoryview(np.ascontiguousarray(img)).cast("B"))
            self.send(("frame", meta), *blobs)
        self.player.stop()
        self.toolpaths.stop()
        processor = self.stage.current()
        if processor is not None:
            processor.stop()
            processor.join(5.0)
        self.player.join(5.0)


def child_main(conn, spec, anchors_json, speed, loop, playing, full_frames, display_size) -> None:
    """Entry point of the child process."""
    try:
        _Child(conn, spec, anchors_json, speed, loop, playing, full_frames, display_size).run()
    except Exception as exc:  # noqa: BLE001 - last resort: tell the UI why the process ends
        try:
            conn.send(("error", "The tracking process failed", f"{exc}\n{traceback.format_exc(limit=3)}"))
        except (OSError, EOFError):
            pass
    finally:
        conn.close()


# ------------------------------------------------------------------------------------------------ UI


class _PlayerView:
    """What the window reads of the player (`recorder`) in the remote case."""

    recorder = None


class RemoteEngine(QObject):
    """`workers.Engine`'s interface, with the pipeline in a child process. Signals are delivered on the
    UI thread. Extra: recorded(folder) after a recording of a live source is finished."""

    opened = Signal(object)
    frame_ready = Signal()
    error = Signal(str, str)
    ended = Signal()
    recorded = Signal(str)
    toolpaths_shown = Signal(object)

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
        self.player = _PlayerView()
        self.process = None
        self.conn = None
        self._receiver = None
        self._first_ready = False

    # -- lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        ctx = context()
        parent_conn, child_conn = ctx.Pipe(duplex=True)
        self.conn = parent_conn
        self.process = ctx.Process(target=child_main, name="arapp-pipeline", daemon=True,
                                   args=(child_conn, self.spec, self.anchors_json, self.speed, self.loop,
                                         self._playing, self.full_frames, self.display_size))
        self._receiver = threading.Thread(target=self._receive, args=(child_conn,), name="arapp-receive",
                                          daemon=True)
        self._receiver.start()

    def _receive(self, child_conn) -> None:
        """Receiver thread: start the child (the fork server may take a moment), then turn its messages
        into slot items and signals."""
        try:
            self.process.start()
        except Exception as exc:  # noqa: BLE001
            self.error.emit("Cannot start the tracking process", str(exc))
            return
        child_conn.close()
        conn = self.conn
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                break
            kind = msg[0]
            if kind == "frame":
                self._frame(conn, msg[1])
            elif kind == "opened":
                self.info = self._info(msg[1])
                self.opened.emit(self.info)
            elif kind == "error":
                self.error.emit(msg[1], msg[2])
            elif kind == "ended":
                self._playing = False
                self.ended.emit()
            elif kind == "recorded":
                self.recorded.emit(msg[1])
            elif kind == "toolpaths":
                self.toolpaths_shown.emit(msg[1])
        if not self._stopping:
            self.process.join(2.0)
            code = self.process.exitcode
            if code not in (0, None):
                self.error.emit("The tracking process stopped",
                                f"the process running capture, tracking and rendering ended with code {code}")

    def _info(self, d: dict) -> SourceInfo:
        from tracking.camera import Camera
        from tracking.session import parse_anchors

        return SourceInfo(name=d["name"], seekable=d["seekable"], frame_count=d["frame_count"], fps=d["fps"],
                          camera=Camera.from_dict(d["camera"]), anchors=parse_anchors(d["anchors"]), live=d["live"])

    def _frame(self, conn, meta: dict) -> None:
        data = conn.recv_bytes()
        full = [conn.recv_bytes() for _ in range(2)] if meta.get("full") else []
        w, h = meta["w"], meta["h"]
        bgra = np.frombuffer(data, np.uint8).reshape(h, w, 4)
        q = QImage(bgra.data, w, h, w * 4, QImage.Format.Format_RGB32)
        q._keep = bgra
        image = frame = None
        if full:
            shape = tuple(meta["full_shape"])
            image = np.frombuffer(full[0], np.uint8).reshape(shape)
            frame = np.frombuffer(full[1], np.uint8).reshape(shape)
        pose = None if meta["pose"] is None else np.asarray(meta["pose"], float)
        extra = {k: meta[k] for k in ("mesh_faces", "model_gen", "mode", "resets", "toolpaths")}
        result = FrameResult(meta["index"], meta["t"], pose, meta["state"], meta["markers"], meta["inliers"],
                              meta["ms_track"], meta["ms_render"], image, extra)
        self.shown.put(Shown(result, q, frame, meta["captured_at"], meta["processed_at"],
                             dropped_capture=meta["dropped"]))
        self._first_ready = True
        if not self._notify_pending.is_set():
            self._notify_pending.set()
            self.frame_ready.emit()

    def _send(self, *msg) -> None:
        if self.conn is None:
            return
        with self._send_lock:
            try:
                self.conn.send(msg)
            except (OSError, BrokenPipeError):
                pass  # the child is gone; the receiver reports why

    def stop(self, wait: float = 0.0) -> None:
        self._stopping = True
        self._send("stop")
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
        return shown

    def set_display_size(self, width: int, height: int) -> None:
        self.display_size = (int(width), int(height))
        self._send("display_size", self.display_size)

    def set_model(self, gen: int, path: str | None, edits: dict, placement: dict | None, mode: str,
                  model=None) -> None:
        """Show the model file at `path` with control-point `edits` applied (the child loads and tessellates
        it; `model`, the UI's own copy, stays here)."""
        self._send("model", gen, path, dict(edits), placement, mode)

    def set_placement(self, placement: dict) -> None:
        self._send("placement", dict(placement))

    def set_highlight(self, point: tuple[int, int, int] | None) -> None:
        """Ring control point (surface, i, j) of the shown model on screen; None: no ring."""
        self._send("highlight", None if point is None else tuple(int(x) for x in point))

    def set_mode(self, mode: str) -> None:
        self._send("mode", mode)

    def set_toolpaths(self, spec: dict | None, gen: int = 0) -> None:
        """Show the print preview `spec` (arapp.gui.toolpaths.preview_spec: G-code path, printer profile,
        layer, layer being printed) on the bed; None clears it. The child parses and builds the line sets;
        `toolpaths_shown(info)` follows once they are drawn."""
        self._send("toolpaths", None if spec is None else dict(spec), int(gen))

    def reset(self) -> None:
        self._send("reset")

    def record_start(self, folder) -> None:
        self._send("record_start", str(folder))

    def record_stop(self) -> None:
        self._send("record_stop")

    def play(self) -> None:
        self._playing = True
        self._send("play")

    def pause(self) -> None:
        self._playing = False
        self._send("pause")

    def step(self, n: int = 1) -> None:
        self._playing = False
        self._send("step", n)

    def seek(self, frame: int) -> None:
        self._send("seek", int(frame))

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"replay speed must be positive, got {speed}")
        self._send("speed", float(speed))

    def set_loop(self, loop: bool) -> None:
        self._send("loop", bool(loop))

    @property
    def playing(self) -> bool:
        return self._playing
