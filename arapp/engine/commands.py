"""Commands to the live engine, defined once: what the app model asks of the capture and processing threads.

Each command is a small picklable dataclass with `apply(engine)`, where
`engine` is an `arapp.engine.live.LiveEngine`. The GUI's thread engine applies
them in its own process; its process engine sends them over a pipe and the
child applies the same objects (a model travels as its path plus
control-point edits there: `SetModel.model` is dropped before sending and the
child loads and tessellates the file itself).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from arapp.geometry.placement import Placement


@dataclass(frozen=True)
class Play:
    """Play (a recording from where it is; a camera delivers at its own pace)."""

    def apply(self, engine) -> None:
        engine.autoplay = True
        engine.player.play()


@dataclass(frozen=True)
class Pause:
    def apply(self, engine) -> None:
        engine.autoplay = False
        engine.player.pause()


@dataclass(frozen=True)
class Step:
    """While paused, read the next `n` frames."""

    n: int = 1

    def apply(self, engine) -> None:
        engine.autoplay = False
        engine.player.step(self.n)


@dataclass(frozen=True)
class Seek:
    """Go to frame `frame` (0-based) of a seekable source."""

    frame: int

    def apply(self, engine) -> None:
        engine.player.seek(int(self.frame))


@dataclass(frozen=True)
class SetSpeed:
    """Replay speed factor (1.0: the recording's own pace)."""

    speed: float

    def __post_init__(self):
        if not self.speed > 0:
            raise ValueError(f"replay speed must be positive, got {self.speed}")

    def apply(self, engine) -> None:
        engine.player.set_speed(float(self.speed))


@dataclass(frozen=True)
class SetLoop:
    loop: bool

    def apply(self, engine) -> None:
        engine.player.set_loop(bool(self.loop))


@dataclass(frozen=True)
class SetDisplaySize:
    """The size (width, height, device pixels) the view shows frames at; frames are scaled to it in the
    processing thread. None: full size."""

    size: tuple[int, int] | None

    def apply(self, engine) -> None:
        engine.stage.set_display_size(None if self.size is None else (int(self.size[0]), int(self.size[1])))


@dataclass(frozen=True)
class Reset:
    """Forget the tracking state (map, filter); the next frames start afresh."""

    def apply(self, engine) -> None:
        def reset(pipe):
            pipe.reset()
            engine.state["resets"] += 1

        engine.submit(reset)


@dataclass(frozen=True)
class SetMode:
    """Display mode of the model (arapp.engine.pipeline.MODES)."""

    mode: str

    def apply(self, engine) -> None:
        def set_mode(pipe):
            pipe.set_mode(self.mode)
            engine.state["mode"] = self.mode

        engine.submit(set_mode)


@dataclass(frozen=True)
class SetOcclusion:
    """How real things hide the model (arapp.engine.pipeline.OCCLUSION_MODES), or None: depth when the frames carry
    depth, else off."""

    mode: str | None

    def apply(self, engine) -> None:
        def set_occlusion(pipe):
            pipe.set_occlusion(self.mode)
            engine.state["occlusion"] = self.mode

        engine.submit(set_occlusion)


@dataclass(frozen=True)
class Highlight:
    """Ring control point (surface, i, j) of the shown model on screen; None: no ring."""

    point: tuple[int, int, int] | None

    def apply(self, engine) -> None:
        engine.stage.set_highlight(None if self.point is None else tuple(int(x) for x in self.point))


@dataclass(frozen=True)
class ShowMarks:
    """Outline the detected markers and draw the anchors' axes on the frames (under the model), or not."""

    on: bool

    def apply(self, engine) -> None:
        engine.stage.set_marks(bool(self.on))


@dataclass(frozen=True)
class SetPlacement:
    """Move, turn or resize the shown model on the world anchor."""

    placement: Placement

    def apply(self, engine) -> None:
        engine.submit(lambda pipe: pipe.set_placement(self.placement))


@dataclass(frozen=True)
class SetModel:
    """Show a model as placed. `gen` numbers the request (reported back in each frame's `extra`);
    `path` None hides the model. `model`, when given, is the model already loaded and edited (used as it
    is, in the same process); otherwise the engine loads `path` and applies `edits`
    ((surface, i, j) -> ((x, y, z), weight)) itself."""

    gen: int
    path: str | None
    edits: dict = field(default_factory=dict)
    placement: Placement | None = None
    mode: str = "shaded"
    model: Any = field(default=None, compare=False)

    def for_transfer(self) -> "SetModel":
        """The command as it crosses a process boundary: without the in-process model."""
        return replace(self, model=None, edits=dict(self.edits))

    def apply(self, engine) -> None:
        try:
            model = self.model if self.model is not None else (engine.load(self.path, self.edits) if self.path
                                                                else None)
        except Exception as exc:  # noqa: BLE001 - a bad model file is told to the user, the view goes on
            engine.events.error.emit("Cannot open the model", str(exc) or type(exc).__name__)
            return

        def set_model(pipe):
            pipe.set_mode(self.mode)
            pipe.set_model(model, self.placement)
            engine.state.update(mode=self.mode, model_gen=self.gen,
                                mesh_faces=0 if pipe.mesh is None else int(len(pipe.mesh.faces)))

        engine.submit(set_model)


@dataclass(frozen=True)
class ShowToolpaths:
    """Show the print preview `spec` (arapp.engine.toolpaths.preview_spec) on the bed; None clears it. Built in
    a worker thread; the engine's `toolpaths` event follows once drawn, with `gen`."""

    spec: dict | None
    gen: int = 0

    def apply(self, engine) -> None:
        engine.toolpath_stage().request(None if self.spec is None else dict(self.spec), gen=int(self.gen))


@dataclass(frozen=True)
class RecordStart:
    """Start recording a live source into the folder `folder` (an arapp-recording/1 folder is written)."""

    folder: str

    def apply(self, engine) -> None:
        engine.record_start(self.folder)


@dataclass(frozen=True)
class RecordStop:
    """Finish the recording; the engine's `recorded(folder)` event follows once the files are closed."""

    def apply(self, engine) -> None:
        engine.record_stop()


@dataclass(frozen=True)
class ArRecordStart:
    """Start writing the composited view (what is on screen, at the source's resolution) to the video `path`."""

    path: str

    def apply(self, engine) -> None:
        engine.ar_record_start(self.path)


@dataclass(frozen=True)
class ArRecordStop:
    """Finish the AR video; the engine's `recorded(path)` event follows once the file is closed."""

    def apply(self, engine) -> None:
        engine.ar_record_stop()


@dataclass(frozen=True)
class EndDiscovery:
    """Stop looking for other anchors in the picture (the offer was answered; arapp.engine.discovery)."""

    def apply(self, engine) -> None:
        engine.end_discovery()


@dataclass(frozen=True)
class Stop:
    """End the engine: both threads finish, closing the source and the pipeline."""

    def apply(self, engine) -> None:
        engine.stop()
