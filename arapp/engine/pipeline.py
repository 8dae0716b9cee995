"""The AR pipeline shared by `arapp replay` and the GUI: frame -> tracking -> overlay.

Headless; no Qt. One `Pipeline` per video stream: it owns the tracker (which
keeps state between frames) and the renderer (which keeps GPU buffers).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from arapp.geometry import load_model
from arapp.geometry.placement import Placement, world_from_model
from arapp.render import occlusion
from arapp.render.occlusion import MODES as OCCLUSION_MODES
from tracking.camera import Camera
from tracking.poses import invert
from tracking.anchors.kinds import AnchorSpec
from tracking.fusion import Tracker

MODES = ("shaded", "wireframe", "isolines", "translucent")
STATE_COLOURS = {"marker": (80, 220, 80), "slam": (60, 200, 255), "lost": (60, 60, 255)}


@dataclass
class FrameResult:
    """What the pipeline made of one frame. `image` is the composited BGR frame (the input when not drawing)."""

    index: int
    t: float
    world_from_camera: np.ndarray | None
    state: str
    markers: int
    inliers: int
    ms_track: float
    ms_render: float
    image: np.ndarray
    extra: dict = field(default_factory=dict)


class Pipeline:
    """Tracks each frame against the anchors and draws the placed model over it.

    camera: the stream's intrinsics; anchors: the session's anchors (the first
    defines the world); model: an `arapp.geometry` model (or None for tracking
    only); placement: size/offset/rotation on the world anchor.
    """

    def __init__(
        self,
        camera: Camera,
        anchors: list[AnchorSpec],
        *,
        model=None,
        placement: Placement | None = None,
        mode: str = "shaded",
        slam: bool = True,
        draw: bool = True,
        status_line: bool = True,
        tracker_params: dict | None = None,
        occlusion: str | None = None,
    ):
        self.camera = camera
        self.anchors = anchors
        self.tracker = Tracker(camera, anchors, slam=slam, **(tracker_params or {}))
        self.draw = draw
        self.status_line = status_line
        self._renderer = None
        self._fps = 0.0
        self._last_time = None
        self.mode = mode
        self.model = None
        self.mesh = None
        self.lines = None
        self.color = None
        self.world_from_model = np.eye(4)
        self.toolpaths = None  # (line_sets, world_from_bed) set by set_toolpaths
        # what the last draw_overlay composited onto its frame, in order: [(premultiplied RGBA crop, x0, y0)]
        # (frame pixels; the live view composites them again onto its picture scaled to the window)
        self.overlay: list = []
        self.occlusion: str | None = None  # "off", "depth", "plane"; None: depth when a frame has depth
        self._plane = None  # arapp.render.occlusion.PlaneDepth, made on first use
        self.set_occlusion(occlusion)
        # fn(image, t, world_from_camera, state) after each tracked frame (a saved scene's marker check)
        self.observers: list = []
        if model is not None:
            self.set_model(model, placement)

    # -- configuration -------------------------------------------------------------
    def set_model(self, model, placement: Placement | None = None) -> None:
        """Show `model` (an arapp.geometry Model) placed on the world anchor; None hides it.

        placement: replaces the model's own placement (None keeps it).
        """
        self.model = model
        if model is None:
            self.mesh = None
            return
        if placement is not None:
            model.placement = placement
        self.mesh = model.mesh()
        self.lines = model.lines() if hasattr(model, "lines") else None
        self.color = getattr(model, "color", None)
        self._update_model_matrix()

    def set_mesh(self, mesh, lines=None) -> None:
        """Replace the displayed mesh (e.g. after editing a control point), keeping the placement."""
        self.mesh = mesh
        self.lines = lines
        self._update_model_matrix()  # the model's bounds may have changed with its net

    def set_placement(self, placement: Placement) -> None:
        """Move/resize the shown model."""
        if self.model is not None:
            self.model.placement = placement
            self._update_model_matrix()

    def set_mode(self, mode: str) -> None:
        if mode not in MODES:
            raise ValueError(f"display mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.mode = mode

    def set_occlusion(self, mode: str | None) -> None:
        """How real things hide the model (arapp.render.occlusion): "off", "depth" (the frame's measured
        depth; frames without depth are drawn unoccluded), "plane" (the world anchor's plane: parts below
        the table are hidden), or None: "depth" for frames that carry depth, else "off"."""
        if mode is not None and mode not in OCCLUSION_MODES:
            raise ValueError(f"occlusion must be one of {', '.join(OCCLUSION_MODES)}, got {mode!r}")
        self.occlusion = mode

    def occlusion_for(self, depth) -> str:
        """The occlusion mode used for a frame with (or without, None) depth."""
        mode = self.occlusion if self.occlusion is not None else ("depth" if depth is not None else "off")
        return "off" if mode == "depth" and depth is None else mode

    def _occluder(self, depth, camera_from_world):
        mode = self.occlusion_for(depth)
        if mode == "off":
            return None
        if mode == "plane" and self._plane is None:
            self._plane = occlusion.PlaneDepth(self.camera)
        return occlusion.Occluder(mode, depth=depth, plane=self._plane, camera_from_world=camera_from_world)

    def set_toolpaths(self, line_sets, world_from_bed: np.ndarray) -> None:
        """Draw toolpaths: line_sets as the renderer takes them (polylines in bed mm), placed by world_from_bed."""
        self.toolpaths = (line_sets, world_from_bed)

    def _update_model_matrix(self) -> None:
        if self.model is None:
            return
        self.world_from_model = world_from_model(self.anchors[0], self.model)

    def reset(self) -> None:
        self.tracker.reset()

    # -- per frame ---------------------------------------------------------------------
    @property
    def renderer(self):
        if self._renderer is None:
            # here, not at the top: PyOpenGL binds its platform on import, and processes that import this
            # module without drawing (the GUI process, for FrameResult) must not load GL at all
            from arapp.render import OverlayRenderer

            c = self.camera
            self._renderer = OverlayRenderer(c.K, c.dist, c.width, c.height)
        return self._renderer

    def process(self, image: np.ndarray, t: float, index: int = 0, depth: np.ndarray | None = None) -> FrameResult:
        """Track one BGR frame taken at time t (seconds) and, when drawing, composite the overlay.
        depth: the frame's depth (float32 metres on its pixels, 0 = none) for depth occlusion."""
        res = self.tracker.process(image, t)
        for fn in list(self.observers):
            fn(image, t, res.world_from_camera, res.state)
        t1 = time.perf_counter()
        out = self.draw_overlay(image, res.world_from_camera, depth) if self.draw else image
        t2 = time.perf_counter()
        if self._last_time is not None and t2 > self._last_time:
            inst = 1.0 / (t2 - self._last_time)
            self._fps = inst if self._fps == 0 else 0.9 * self._fps + 0.1 * inst
        self._last_time = t2
        if self.draw and self.status_line:
            draw_status(out, res.state, self._fps, res.markers, res.inliers)
        # "ambiguous": a lone head-on marker's tilt not yet decided (TrackResult.ambiguous; the view asks for a tilt)
        return FrameResult(index, t, res.world_from_camera, res.state, res.markers, res.inliers,
                           float(res.ms), (t2 - t1) * 1e3, out,
                           extra={"ambiguous": True} if getattr(res, "ambiguous", False) else {})

    def idle(self) -> bool:
        """Between frames, once the last one is shown: the keypoint work its tracking left for later
        (`TrackerConfig.defer_upkeep`; the next `process` does it otherwise). Whether there was any."""
        return self.tracker.upkeep()

    def draw_overlay(self, image: np.ndarray, world_from_camera: np.ndarray | None,
                     depth: np.ndarray | None = None) -> np.ndarray:
        """A copy of the BGR `image` with the model (and toolpaths) drawn as seen from `world_from_camera`,
        hidden where real things are nearer (set_occlusion; `depth` is the frame's, if it has one).

        The drawing half of `process`, without tracking: a paused view redraws
        with new settings through it, and the tracker never sees a frame twice.
        """
        out = image.copy()
        self.overlay = []
        if world_from_camera is None:
            return out
        camera_from_world = invert(world_from_camera)
        occ = self._occluder(depth, camera_from_world) if (self.mesh is not None or self.toolpaths) else None
        if self.mesh is not None:
            out = self.renderer.draw(out, self.mesh, camera_from_world @ self.world_from_model, mode=self.mode,
                                     lines=self.lines if self.mode == "isolines" else None, color=self.color,
                                     inplace=True, occlusion=occ)
            self._note_overlay()
        if self.toolpaths is not None:
            line_sets, world_from_bed = self.toolpaths
            out = self.renderer.draw(out, None, camera_from_world @ world_from_bed, line_sets=line_sets,
                                     inplace=True, occlusion=occ)
            self._note_overlay()
        return out

    def _note_overlay(self) -> None:
        if self.renderer.last_crop is not None:
            self.overlay.append(self.renderer.last_crop)

    def close(self) -> None:
        self.tracker.close()
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def draw_status(image: np.ndarray, state: str, fps: float, markers: int, inliers: int) -> None:
    """Write the status line (state, fps, markers, inliers) in the top-left corner, in place."""
    text = f"{state}  {fps:5.1f} fps  markers {markers}  inliers {inliers}"
    scale = max(0.4, image.shape[0] / 1200)
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(image, (4, 4), (12 + w, 12 + h + base), (0, 0, 0), -1)
    cv2.putText(image, text, (8, 8 + h), cv2.FONT_HERSHEY_SIMPLEX, scale,
                STATE_COLOURS.get(state, (255, 255, 255)), 1, cv2.LINE_AA)


def load_display_model(path: str | Path):
    """Load a model file for display (NURBS JSON or a mesh file); errors name the file and the problem."""
    return load_model(path)
