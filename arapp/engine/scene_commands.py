"""Engine commands for saved scenes (arapp.exchange.scene): load a scene's map into the open source's
tracker, save the map as it stands. Picklable, applied in the engine's process like arapp.engine.commands; the
work runs in the processing thread between frames (it owns the tracker).

After a load or a save, `engine.state["scene"]` (copied into each frame's `extra`) says what happened:
{"loaded": path, "keyframes": n, "points": n} or {"saved": path, ...} or {"error": line}.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from arapp.engine.scene_run import SceneRun


@dataclass(frozen=True)
class LoadScene:
    """Start tracking from the saved scene at `path`: the next frames relocalise against its map."""

    path: str

    def apply(self, engine) -> None:
        def load(pipe):
            try:
                run = SceneRun.start(pipe.tracker, pipe.camera, [a.to_dict() for a in pipe.anchors], load=self.path)
            except (ValueError, OSError) as exc:
                engine.state["scene"] = {"error": str(exc)}
                engine.events.error.emit("Cannot open the scene", str(exc))
                return
            pipe.scene_run = run
            s = run.summary()
            engine.state["scene"] = {"loaded": self.path, "keyframes": s["loaded_keyframes"],
                                     "points": s["loaded_points"]}

            def check(image, t, pose, state):
                # the first frames the marker gives the pose on: does the saved map agree with it?
                run.observe(image, t, pose, state)
                if run.check is not None or run.checks_left == 0:
                    pipe.observers.remove(check)
                    engine.state["scene"] = {**engine.state["scene"], "marker_vs_map": run.check}
                    if run.notes:
                        engine.events.error.emit("The marker and the saved scene disagree", run.notes[-1])

            pipe.observers.append(check)

        engine.submit(load)


@dataclass(frozen=True)
class SaveScene:
    """Save the scene to `path` (atomically): the tracker's map (the loaded scene's, extended by this run),
    the anchors, the camera and `models` ([{"path", "placement"}])."""

    path: str
    models: list = field(default_factory=list)

    def apply(self, engine) -> None:
        def save(pipe):
            run = getattr(pipe, "scene_run", None) or SceneRun.start(pipe.tracker, pipe.camera,
                                                                     [a.to_dict() for a in pipe.anchors])
            try:
                path = run.save(self.path, list(self.models))
            except (ValueError, OSError) as exc:
                engine.state["scene"] = {"error": str(exc)}
                engine.events.error.emit("Cannot save the scene", str(exc))
                return
            m = pipe.tracker.map
            engine.state["scene"] = {"saved": str(path), "keyframes": len(m.keyframes), "points": len(m.points)}

        engine.submit(save)
