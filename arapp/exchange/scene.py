"""Scene files (`.arscene`, docs/scene-format.md): the keypoint map, the anchors, the placed models and
the camera calibration of a desk, kept from one run to the next.

    scene = read_scene("desk.arscene", camera)      # SceneError (one line: what, what to do) when unusable
    tracker.load_map(scene.map)                     # relocalises against it (tracking.fusion)
    write_scene("desk.arscene", SceneFile(camera, anchor_blocks, models, tracker.export_map()))

The container is a zip (stdlib `zipfile`, deflate): `scene.json` (format, version, camera, anchors,
models, a summary of the map) beside one `.npy` array per map field under `map/` (tracking.slam.map_io
ARRAYS). One file to copy or mail; `unzip -l` shows what is inside; JSON where people read, .npy where
numpy reads (loaded with allow_pickle=False, so a scene file can carry no code). Written to a temporary
file in the same folder, flushed to disk and renamed over the target: a failed or interrupted save never
leaves half a file, and a failed load never touches the file.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError
from tracking.recording.schema import parse_anchors
from tracking.slam.map import Map
from tracking.slam.map_io import ARRAYS, MapError, cull_keyframes, map_from_arrays, map_to_arrays

from .files import DocumentFormat, register_document

FORMAT = "arapp-scene"
VERSION = 1
SUFFIX = ".arscene"
# the most keyframes a saved scene keeps (tracking.slam.map_io.cull_keyframes): ~60 kB each at 640x480
MAX_KEYFRAMES = 120
# how far the loading camera may differ from the scene's and still use its map: 1 % of focal length and
# principal point (a recalibration of the same webcam), the same image size
CAMERA_TOLERANCE = 0.01


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file and says what to do."""


@dataclass
class SceneFile:
    """One scene: `camera` the calibration the map was made with; `anchors` anchor blocks as in
    session.json (the first defines the world frame); `models` [{"path", "placement": {size_mm, offset,
    rotation_deg}, "anchor": index}]; `map` the keypoint map (world frame, metres); `history` one entry
    per save ({"saved": ISO time, "keyframes": n, "points": n})."""

    camera: Camera
    anchors: list[dict]
    models: list[dict] = field(default_factory=list)
    map: Map = field(default_factory=Map)
    history: list[dict] = field(default_factory=list)


def write_scene(path, scene: SceneFile, max_keyframes: int = MAX_KEYFRAMES) -> Path:
    """Write `scene` to `path` atomically, after culling redundant keyframes down to `max_keyframes`
    (the map is changed in place). Returns the path."""
    p = Path(path)
    parse_anchors(scene.anchors, f"{p}: anchors")   # a scene must name its world frame
    models = [_model_entry(m, i, p) for i, m in enumerate(scene.models)]
    with scene.map.lock:
        cull_keyframes(scene.map, max_keyframes)
        arrays = map_to_arrays(scene.map)
    history = list(scene.history) + [{"saved": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                      "keyframes": int(len(arrays["kf_id"])), "points": int(len(arrays["pt_id"]))}]
    doc = {
        "format": FORMAT, "version": VERSION,
        "camera": scene.camera.to_dict(),
        "anchors": scene.anchors,
        "models": models,
        "map": {"keyframes": int(len(arrays["kf_id"])), "points": int(len(arrays["pt_id"])),
                "features": int(len(arrays["feat_xy"])), "arrays": sorted(arrays)},
        "history": history,
    }
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as z:
                z.writestr("scene.json", json.dumps(doc, indent=2) + "\n")
                for name, arr in arrays.items():
                    buf = io.BytesIO()
                    np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
                    z.writestr(f"map/{name}.npy", buf.getvalue())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    scene.history = history
    return p


def _model_entry(m: dict, i: int, scene_path: Path) -> dict:
    where = f"{scene_path}: models[{i}]"
    if not isinstance(m, dict) or not isinstance(m.get("path"), str) or not m["path"]:
        raise SceneError(f"{where}: needs a 'path' (the model file)")
    pl = m.get("placement") or {}
    if not isinstance(pl, dict):
        raise SceneError(f"{where}.placement: must be an object with size_mm, offset, rotation_deg")
    path = Path(m["path"])
    # kept relative to the scene file when it lies beside or below it, so a folder can be moved whole
    try:
        rel = os.path.relpath(path.resolve(), scene_path.resolve().parent)
        stored = rel if not rel.startswith("..") else str(path.resolve())
    except ValueError:   # another drive (Windows)
        stored = str(path.resolve())
    return {"path": stored, "placement": {k: pl[k] for k in ("size_mm", "offset", "rotation_deg") if k in pl},
            "anchor": int(m.get("anchor", 0))}


def _existing(path) -> Path:
    """`path` as a Path, refused in one line when there is no such file."""
    p = Path(path)
    if not p.is_file():
        raise SceneError(f"{p}: no such scene file; save one first (GUI: File > Save scene, "
                         "replay: --save-scene)")
    return p


def read_scene(path, camera: Camera | None = None) -> SceneFile:
    """Read a scene file. With `camera`, refuse a scene made with another camera (size, focal length or
    principal point more than CAMERA_TOLERANCE apart). Model paths come back absolute."""
    p = _existing(path)
    try:
        with zipfile.ZipFile(p) as z:
            names = set(z.namelist())
            if "scene.json" not in names:
                raise SceneError(f"{p}: not a scene file (no scene.json inside); start a new scene")
            doc = json.loads(z.read("scene.json"))
            _check_header(doc, p)
            arrays = {}
            for name in ARRAYS:
                entry = f"map/{name}.npy"
                if entry not in names:
                    if name == "covis":
                        continue
                    raise SceneError(f"{p}: corrupt scene file ({entry} missing); start a new scene")
                arrays[name] = np.lib.format.read_array(io.BytesIO(z.read(entry)), allow_pickle=False)
    except zipfile.BadZipFile:
        raise SceneError(f"{p}: corrupt scene file (not a readable zip); start a new scene") from None
    except (ValueError, KeyError, OSError, EOFError) as e:
        if isinstance(e, SceneError):
            raise
        raise SceneError(f"{p}: corrupt scene file ({e}); start a new scene") from None
    try:
        saved_camera = Camera.from_dict(doc.get("camera"), "camera")
        parse_anchors(doc.get("anchors"), "anchors")
        m = map_from_arrays(arrays)
    except (CalibrationError, SessionError, MapError) as e:
        raise SceneError(f"{p}: corrupt scene file ({e}); start a new scene") from None
    if camera is not None:
        check_camera(saved_camera, camera, p)
    models = []
    for i, entry in enumerate(doc.get("models") or []):
        if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
            raise SceneError(f"{p}: corrupt scene file (models[{i}] has no path); start a new scene")
        mp = Path(entry["path"])
        models.append({**entry, "path": str(mp if mp.is_absolute() else (p.parent / mp).resolve())})
    return SceneFile(saved_camera, doc["anchors"], models, m, list(doc.get("history") or []))


def read_scene_models(path) -> list[dict]:
    """The placed models of a scene file (paths absolute), from its scene.json alone (the map is not read)."""
    p = _existing(path)
    try:
        with zipfile.ZipFile(p) as z:
            doc = json.loads(z.read("scene.json"))
    except (zipfile.BadZipFile, KeyError, ValueError, OSError):
        raise SceneError(f"{p}: corrupt scene file (no readable scene.json); start a new scene") from None
    _check_header(doc, p)
    out = []
    for entry in doc.get("models") or []:
        if isinstance(entry, dict) and isinstance(entry.get("path"), str):
            mp = Path(entry["path"])
            out.append({**entry, "path": str(mp if mp.is_absolute() else (p.parent / mp).resolve())})
    return out


def _check_header(doc, p: Path) -> None:
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise SceneError(f"{p}: not an arapp scene file (format {doc.get('format') if isinstance(doc, dict) else None!r}); "
                         "start a new scene")
    v = doc.get("version")
    if not isinstance(v, int) or v < 1:
        raise SceneError(f"{p}: corrupt scene file (version {v!r}); start a new scene")
    if v > VERSION:
        raise SceneError(f"{p}: made by a newer arapp (scene format version {v}, this one reads up to {VERSION}); "
                         "update arapp, or start a new scene")


def check_camera(saved: Camera, camera: Camera, where) -> None:
    """SceneError unless `camera` is the camera the scene was made with (within CAMERA_TOLERANCE)."""
    if saved.size != camera.size:
        raise SceneError(f"{where}: made with another camera ({saved.width}x{saved.height}, this one is "
                         f"{camera.width}x{camera.height}); use that camera, or start a new scene")
    f0, f1 = np.array([saved.K[0, 0], saved.K[1, 1]]), np.array([camera.K[0, 0], camera.K[1, 1]])
    c0, c1 = saved.K[:2, 2], camera.K[:2, 2]
    if (np.abs(f1 / f0 - 1).max() > CAMERA_TOLERANCE
            or np.abs(c1 - c0).max() > CAMERA_TOLERANCE * max(camera.width, camera.height)):
        raise SceneError(f"{where}: made with another camera calibration (focal length {f0[0]:.1f} px, this one "
                         f"{f1[0]:.1f} px); recalibrate that camera, or start a new scene")


def _read_for_table(path: Path) -> SceneFile:
    return read_scene(path)


register_document("scene", DocumentFormat("arapp scene (map, anchors, placed models)", (SUFFIX,), _read_for_table,
                                          SceneError, "docs/scene-format.md"))
