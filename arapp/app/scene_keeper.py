"""The app model's saved scene: which scene file the session tracks against, opening and saving it, and the
last one used (remembered per user, arapp.store.user_config, to offer reopening it). No Qt.

    keeper = SceneKeeper(session)
    keeper.open("desk.arscene")     # its map goes to the engine (now and for each source opened later),
                                    # its model is shown where it was placed
    keeper.save()                   # to the open scene's file (or keeper.save(path): save as)
    keeper.last()                   # the last scene opened or saved, when the file still exists
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from arapp.store import user_config
from arapp.engine.scene_commands import LoadScene, SaveScene
from arapp.exchange.scene import SUFFIX, SceneError, read_scene_models
from arapp.geometry.placement import Placement

LAST_KEY = "last_scene"


class SceneKeeper:
    def __init__(self, session):
        self.session = session
        self.path: str | None = None

    def last(self) -> str | None:
        p = user_config.recall(LAST_KEY)
        return p if isinstance(p, str) and Path(p).is_file() else None

    def open(self, path: str) -> None:
        """Track against the scene at `path` and show its model (SceneError, one line, when unusable)."""
        models = read_scene_models(path)
        self.path = str(Path(path).resolve())
        user_config.remember(LAST_KEY, self.path)
        self.session.send(LoadScene(self.path))
        if models and Path(models[0]["path"]).is_file():
            entry = models[0]
            if entry.get("placement"):
                events = self.session.events

                def placed(model, path, placement):
                    # the model loads in a worker and arrives at its own placement: the scene's replaces it
                    if path == entry["path"]:
                        events.model_loaded.disconnect(placed)
                        self.session.set_placement(Placement.from_any(entry["placement"], placement))

                events.model_loaded.connect(placed)
            self.session.open_model(entry["path"])
        self.session.status(f"Scene {Path(path).name}: relocalising against its map", 5000)

    def engine_started(self) -> None:
        """A source was opened: it tracks against the open scene too."""
        if self.path is not None:
            self.session.send(LoadScene(self.path))

    def save(self, path: str | None = None) -> str:
        """Save to `path` (default: the open scene's file); the engine writes it between frames."""
        path = path or self.path
        if not path:
            raise SceneError("no scene file yet: choose where to save it (File > Save scene as...)")
        if not str(path).endswith(SUFFIX):
            path = f"{path}{SUFFIX}"
        if self.session.engine is None:
            raise SceneError("nothing to save: open a source and let the map grow first")
        s = self.session
        models = []
        if s.model_path and s.placement is not None:
            models = [{"path": s.model_path, "placement": json.loads(json.dumps(asdict(s.placement)))}]
        self.path = str(Path(path).resolve())
        user_config.remember(LAST_KEY, self.path)
        s.send(SaveScene(self.path, models))
        s.status(f"Saving scene {Path(path).name}", 4000)
        return self.path


__all__ = ["SceneKeeper", "LAST_KEY"]
