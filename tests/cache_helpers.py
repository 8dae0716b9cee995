"""Data rendered once per test run and shared by every pytest-xdist worker of that run.

`make test` runs the suite in parallel workers (pytest-xdist, `--dist loadfile`): a module's own
module-scoped fixtures are built once, on the one worker that runs the module, but data that several
modules use (a synthetic recording two test files read) would be built once per worker. `once_per_run`
builds such a folder once in the run's shared temporary folder, under an exclusive file lock, so a second
worker that needs it meanwhile waits for the first instead of rendering it again; a half-built folder is
never seen (it is built under another name and renamed when complete).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

from tracking.synth.cache import file_lock  # one lock for the recordings cache and the tests' shared builds


def run_folder(tmp_path_factory) -> Path:
    """The temporary folder of this whole run: pytest's base temp, or with xdist its parent, which all
    workers of the run share (each worker's base temp is `<run folder>/popen-gwN`)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


def once_per_run(tmp_path_factory, name: str, build: Callable[[Path], object]) -> Path:
    """The folder `name` in this run's shared folder, made by `build(folder)` the first time any worker asks
    for it; later callers, in this worker or another, get the finished folder."""
    root = run_folder(tmp_path_factory)
    folder = root / name
    with file_lock(root / f"{name}.lock"):
        if not folder.is_dir():
            partial = root / f"{name}.partial"
            shutil.rmtree(partial, ignore_errors=True)
            build(partial)
            partial.rename(folder)
    return folder
