"""A run on a saved scene (arapp.exchange.scene): load its map into the tracker, note when and how the
first pose came, check the marker against the map, and save the scene (extended by this run) at the end.

    run = SceneRun.start(tracker, camera, anchor_blocks, load="desk.arscene")   # or load=None: a new scene
    ... per frame: run.observe(image_bgr, t, world_from_camera, state)
    run.summary()          # {"loaded", "first_pose_s", "first_pose_state", "marker_vs_map": {...}, ...}
    run.save("desk.arscene", models)

Used by `arapp replay --scene/--save-scene` and the GUI. Headless.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from arapp.exchange.scene import SceneError, SceneFile, read_scene, write_scene
from tracking.camera import Camera
from tracking.poses import rotation_angle
from tracking.recording.schema import parse_anchors
from tracking.slam.map_io import map_from_arrays, map_to_arrays
from tracking.slam.relocalise import relocalise

# the marker and the saved map agree when the camera pose each gives is this close (metres, degrees):
# a few times the relocalisation's own error (measured: ~2 mm, ~0.2 degrees)
AGREE_M = 0.01
AGREE_DEG = 1.0
# frames with the marker in view on which the map's relocalisation is tried for the check, at most
CHECK_FRAMES = 15


@dataclass
class SceneRun:
    tracker: object
    camera: Camera
    anchors: list[dict]
    scene: SceneFile | None = None         # the scene loaded (None: a new one)
    path: Path | None = None
    _frozen = None                         # a copy of the loaded map: the check compares against it unchanged
    _t0: float | None = None
    first_pose_s: float | None = None
    first_pose_state: str | None = None
    check: dict | None = None
    checks_left: int = CHECK_FRAMES
    notes: list[str] = field(default_factory=list)

    @classmethod
    def start(cls, tracker, camera: Camera, anchors: list[dict], load=None) -> "SceneRun":
        """Load scene file `load` (if given) into `tracker` (SceneError when it cannot be used: another
        camera, another world anchor, corrupt, newer)."""
        run = cls(tracker, camera, anchors)
        if load is not None:
            scene = read_scene(load, camera)
            check_anchors(scene.anchors, anchors, load)
            run._frozen = map_from_arrays(map_to_arrays(scene.map))
            tracker.load_map(scene.map)
            run.scene, run.path = scene, Path(load)
        return run

    @property
    def models(self) -> list[dict]:
        return self.scene.models if self.scene is not None else []

    def observe(self, image: np.ndarray, t: float, world_from_camera: np.ndarray | None, state: str) -> None:
        """One tracked frame: when the first pose came; while the marker gives the pose, whether the
        saved map puts the camera where the marker does."""
        if self._t0 is None:
            self._t0 = t
        if world_from_camera is not None and self.first_pose_s is None:
            self.first_pose_s, self.first_pose_state = t - self._t0, state
        if (self._frozen is not None and self.check is None and state == "marker" and world_from_camera is not None
                and self.checks_left > 0):
            self.checks_left -= 1
            gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            feats = self.tracker.extractor.extract(gray)
            pose, inliers = relocalise(self._frozen, feats, self.camera.K)
            if pose is not None:
                d = float(np.linalg.norm(pose[:3, 3] - world_from_camera[:3, 3]))
                a = float(np.degrees(rotation_angle(pose[:3, :3].T @ world_from_camera[:3, :3])))
                self.check = {"position_m": d, "rotation_deg": a, "inliers": int(inliers), "t": float(t),
                              "agree": bool(d <= AGREE_M and a <= AGREE_DEG)}
                if not self.check["agree"]:
                    self.notes.append(f"the marker and the saved map disagree by {d * 100:.1f} cm, {a:.1f} deg: "
                                      "was the marker moved since the scene was saved? The marker wins; save the "
                                      "scene again to keep the new place, or put the marker back")

    def summary(self) -> dict:
        out = {"loaded": str(self.path) if self.path else None, "first_pose_s": self.first_pose_s,
               "first_pose_state": self.first_pose_state, "marker_vs_map": self.check}
        if self.scene is not None:
            out["loaded_keyframes"] = len(self._frozen.keyframes)
            out["loaded_points"] = len(self._frozen.points)
        return out

    def save(self, path, models: list[dict] | None = None) -> Path:
        """Write the scene (the map as this run left it: the loaded one extended) to `path`, atomically."""
        m = self.tracker.export_map()
        history = self.scene.history if self.scene is not None else []
        scene = SceneFile(self.camera, self.anchors, self.models if models is None else models, m, history)
        return write_scene(path, scene)


def check_anchors(saved: list[dict], current: list[dict], where) -> None:
    """SceneError unless the world anchor (the first) is the one the scene was made on."""
    a, b = parse_anchors(saved, "scene anchors")[0], parse_anchors(current, "anchors")[0]
    if a.to_dict() != b.to_dict():
        raise SceneError(f"{where}: made on another world anchor ({_name(a)}; this run tracks {_name(b)}); "
                         "track the scene's anchor (--anchors), or start a new scene")


def _name(anchor) -> str:
    d = anchor.to_dict()
    return ", ".join(f"{k} {d[k]}" for k in ("kind", "dictionary", "id", "length", "text") if k in d)


__all__ = ["SceneError", "SceneRun", "check_anchors"]
