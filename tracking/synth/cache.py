"""Synthetic recordings rendered on demand and kept in a cache, so the repository holds only a few.

`recordings/` bundles the recordings a user replays and the ones the tests read most (recordings/README.md);
every other preset (tracking.synth.presets) is rendered by `arapp synth` the first time a test, a benchmark
or `arapp synth NAME --cached` asks for it, into the cache folder (`.cache/recordings/` of the source
checkout, git-ignored; `ARAPP_RECORDINGS_CACHE` names another). Each cached recording lives in
`NAME-<key>`, the key a hash of the preset's scene JSON and of the renderer (the source of tracking/synth
and of the recording writer, OpenCV's and NumPy's versions): a changed preset or renderer gets a new folder,
rendered anew, and the stale one is removed. Rendering is deterministic (same scene, same code: the same
bytes), and several processes asking at once (pytest-xdist workers, a benchmark) render it once: the others
wait on a file lock. A half-rendered folder is never seen: it is written under another name and renamed.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from tracking.recording.writer import RecordingWriter
from tracking.synth import synthesize
from tracking.synth.presets import preset
from tracking.synth.revisits import revisit_by_name
from tracking.synth.scene import parse_scene

SOURCE_ROOT = Path(__file__).resolve().parents[2]
# the bundled recordings (a source checkout's recordings/ folder)
BUNDLED = SOURCE_ROOT / "recordings"
CACHE_ENV = "ARAPP_RECORDINGS_CACHE"


def cache_root() -> Path:
    """The cache folder: $ARAPP_RECORDINGS_CACHE, else the checkout's .cache/recordings (next to
    recordings/), else the user's cache folder (an installed arapp)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    if BUNDLED.is_dir():
        return SOURCE_ROOT / ".cache" / "recordings"
    import platformdirs   # only for an installed copy without the source tree's recordings/

    return platformdirs.user_cache_path("arapp") / "recordings"


@functools.lru_cache(maxsize=1)   # read once per process
def renderer_fingerprint() -> str:
    """A hash of what turns a scene into a recording's bytes: tracking/synth's source (the presets left out:
    a preset's own JSON is hashed with it), the recording writer's source, OpenCV's and NumPy's versions."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    # (the presets package, a folder, is not among them)
    files = sorted(p for p in here.glob("*.py") if p.name != "cache.py")
    files.append(Path(inspect.getsourcefile(RecordingWriter)).resolve())
    for p in files:
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    h.update(f"opencv {cv2.__version__} numpy {np.__version__}".encode())
    return h.hexdigest()


def scene_key(scene_json: dict) -> str:
    """The cache key of a scene: 12 hex digits of a hash of its JSON (keys sorted) and the renderer's."""
    h = hashlib.sha256(json.dumps(scene_json, sort_keys=True).encode())
    h.update(renderer_fingerprint().encode())
    return h.hexdigest()[:12]


def bundled_folder(name: str) -> Path | None:
    """recordings/NAME when the repository bundles that recording (its ground truth included), else None."""
    folder = BUNDLED / name
    return folder if (folder / "groundtruth.tum").is_file() else None


@contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """An exclusive lock on `path` across processes (flock; no lock where flock does not exist)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl   # POSIX only
    except ImportError:  # not POSIX: one process at a time is then the caller's business
        yield
        return
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def cached_recording(name: str, root: Path | None = None,
                     progress: Callable[[int, int], None] | None = None) -> Path:
    """The folder of preset (or scene revisit, tracking.synth.revisits) `name` rendered into the cache (rendered now when it is not there yet)."""
    data = revisit_by_name(name) or preset(name)   # preset(): a clear error for an unknown name
    root = cache_root() if root is None else Path(root)
    folder = root / f"{name}-{scene_key(data)}"
    with file_lock(root / f".{name}.lock"):
        for partial in root.glob(f".{name}-*.partial"):   # left by a process killed while rendering it
            shutil.rmtree(partial, ignore_errors=True)
        if not (folder / "groundtruth.tum").is_file():
            tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".partial", dir=root))
            try:
                synthesize(parse_scene(data, f"preset {name}"), tmp / "rec", force=True, progress=progress)
                shutil.rmtree(folder, ignore_errors=True)
                os.replace(tmp / "rec", folder)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
            for stale in root.glob(f"{name}-*"):   # the same preset rendered from another scene or renderer
                if stale != folder and stale.is_dir() and len(stale.name) == len(folder.name):
                    shutil.rmtree(stale, ignore_errors=True)
    return folder


def recording_folder(name: str) -> Path:
    """The bundled recordings/NAME when there is one, else preset `name` rendered into the cache."""
    return bundled_folder(name) or cached_recording(name)
