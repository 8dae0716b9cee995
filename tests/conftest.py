"""Test-wide settings: headless GL and Qt, and paths to the bundled data."""

import os
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

import atexit  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402

# Each test process (the one process, or each pytest-xdist worker of `make test`) gets its own empty user
# config folder: QSettings("arapp", "arapp") and platformdirs read XDG_CONFIG_HOME, so parallel workers never
# share (or race on) an arapp.conf, no test sees what another left there, and the user's own stays untouched.
_XDG_CONFIG = tempfile.mkdtemp(prefix="arapp-test-config-")
os.environ["XDG_CONFIG_HOME"] = _XDG_CONFIG
atexit.register(shutil.rmtree, _XDG_CONFIG, True)

import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


@pytest.fixture()
def config_dir(tmp_path, monkeypatch) -> Path:
    """The app's config folder (ARAPP_CONFIG_DIR) in tmp_path, so no test reads or writes the user's."""
    d = tmp_path / "config"
    monkeypatch.setenv("ARAPP_CONFIG_DIR", str(d))
    return d


@pytest.fixture()
def threads_window(qtbot, tmp_path, config_dir, monkeypatch):
    """The main window, shown, with the in-process engine (ARAPP_GUI_ENGINE=threads) and its own config."""
    from gui_helpers import close_main_window, open_main_window

    monkeypatch.setenv("ARAPP_GUI_ENGINE", "threads")
    w = open_main_window(qtbot, tmp_path)
    w.show()
    yield w
    close_main_window(w)


# Synthetic recordings the repository does not bundle are rendered on first use into the recordings cache
# (tracking/synth/cache.py), each once per run under a file lock. test_synth_recordings.py checks every preset,
# and loadfile scheduling hands it out late (collection order): rendered there, one after another, the ~2 min
# of rendering on a fresh checkout would be the run's tail. So when the parallel run holds that file, the
# controller renders the missing ones in a background process from the start (those read by early test files
# first); a worker that needs one meanwhile waits on its lock or renders it itself, never twice.
_prefetch = None
EARLY_RECORDINGS = ["marker_occluded", "test_webcam_board"]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    global _prefetch
    if _prefetch is not None or not any("test_synth_recordings.py::" in i for i in ids):
        return
    import subprocess
    import sys

    from tracking.synth.cache import bundled_folder
    from tracking.synth.presets import HELD, PRESETS

    names = [n for n in dict.fromkeys([*EARLY_RECORDINGS, *HELD, *PRESETS]) if bundled_folder(n) is None]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    _prefetch = subprocess.Popen(
        [sys.executable, "-c", "import sys\nfrom tracking.synth.cache import cached_recording\n"
         "for name in sys.argv[1:]:\n    cached_recording(name)", *names],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL)


def pytest_sessionfinish(session, exitstatus):
    if _prefetch is not None and _prefetch.poll() is None:   # the tests are done: what is left is not needed
        _prefetch.terminate()
        _prefetch.wait(timeout=30)


# `make test` hands whole files to its workers (--dist loadfile) in the order the tests are collected
# (--no-loadscope-reorder; xdist's own order puts the files with most tests first, so files of a few long tests,
# a whole GUI session or a real printer server, came last and one worker ran them alone at the end). The files
# are sorted here by what each took (seconds, measured on the shared 2-core machine under load: relative
# figures), longest first, so the short ones fill in at the end; files not listed keep their order after them.
FILE_SECONDS = {
    "test_slam_sequences.py": 315, "test_synth_recordings.py": 140, "test_anchor_rejection.py": 120,
    "test_slam_fast_motion.py": 118, "test_app_model.py": 115, "test_gui.py": 91, "test_gui_print.py": 81,
    "test_moving_anchor.py": 80, "test_gui_scan.py": 79, "test_link_faults.py": 77, "test_scan.py": 71,
    "test_gui_habits.py": 61, "test_anchor_border_jitter.py": 60, "test_prusalink_server.py": 90,
    "test_realphotos.py": 38, "test_scan_depth.py": 37, "test_moonraker_server.py": 29, "test_realvideo.py": 29,
    "test_gui_printer_setup.py": 28, "test_octoprint_server.py": 27, "test_gui_calibration.py": 27,
    "test_blur_stretch.py": 26, "test_gui_firsthour_window.py": 25, "test_filter_reentry.py": 23,
    "test_sources.py": 22, "test_slicer_prusa.py": 16, "test_scan_session.py": 14, "test_any_video.py": 14,
    "test_slam_start.py": 12,
}


def pytest_collection_modifyitems(config, items):
    # a stable sort: each file's tests keep their order (and stay together)
    items.sort(key=lambda item: -FILE_SECONDS.get(item.path.name, 0))


# The real Moonraker + Klippy, started once per session for every test that asks (tests/moonraker_server.py).
from moonraker_server import moonraker_server  # noqa: E402,F401
