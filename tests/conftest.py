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


# `make test` hands whole groups of tests to its workers (--dist loadfile, with the scheduler below): a test file
# is a group, so its module fixtures are built once, except that the files using one real printer server are one
# group, so each server starts on one worker only (a session fixture is per worker). Groups go out longest first
# (--no-loadscope-reorder keeps the order given here; xdist's own puts the groups with most tests first, so
# files of a few long tests came last and one worker ran them alone at the end): FILE_SECONDS is what each
# file took (seconds, measured on the shared 2-core machine under load: relative figures); a group counts the
# sum of its files; files not listed keep their order after them.
FILE_SECONDS = {
    "test_synth_recordings.py": 97, "test_prusalink_server.py": 40, "test_slam_sequences.py": 69,
    "test_realphotos.py": 45, "test_gui_print.py": 43, "test_gui.py": 43, "test_link_faults.py": 35,
    "test_moving_anchor.py": 32, "test_anchor_rejection.py": 32, "test_realvideo.py": 31, "test_link_busy.py": 30,
    "test_slam_fast_motion.py": 29, "test_link_serial.py": 26, "test_gui_scan.py": 25, "test_synth.py": 22,
    "test_gui_habits.py": 22, "test_slicer_prusa.py": 20, "test_gui_printer_setup.py": 19, "test_app_model.py": 18,
    "test_gui_firsthour_window.py": 17, "test_scan_depth.py": 16, "test_scan.py": 16, "test_any_video.py": 16,
    "test_moonraker_server.py": 15, "test_slicer.py": 14, "test_pixel_convention.py": 14, "test_anchors.py": 14,
    "test_octoprint_server.py": 13, "test_render.py": 12, "test_anchor_border_jitter.py": 10, "test_image_folder.py": 9,
    "test_saved_scenes.py": 9, "test_calibration_quality.py": 9, "test_anchor_polarity.py": 9,
    "test_anchor_discovery.py": 9, "test_synth_camera.py": 7, "test_sources.py": 7, "test_gui_calibration.py": 7,
    "test_untracked.py": 5, "test_scan_session.py": 5, "test_octoprint_link.py": 5, "test_occlusion.py": 5,
    "test_link_cli.py": 5, "test_filter_reentry.py": 5, "test_gui_workers.py": 4, "test_gui_print_resume.py": 4,
}
# the files that share one real printer server (its session fixture): one group each
SERVER_GROUPS = {
    "octoprint": ("test_octoprint_server.py", "test_octoprint_link.py", "test_gui_printer_setup.py"),
    "moonraker": ("test_moonraker_server.py", "test_gui_printer_setup_moonraker.py", "test_gui_print_moonraker.py"),
    "prusalink": ("test_prusalink_server.py", "test_prusalink_link.py"),
}
GROUP_OF = {f: group for group, files in SERVER_GROUPS.items() for f in files}


def group_seconds(group: str) -> float:
    files = SERVER_GROUPS.get(group, (group,))
    return sum(FILE_SECONDS.get(f, 0) for f in files)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """xdist's load-by-file scheduling with each server group as one scope (xdist's own --dist loadgroup
    cannot be used: it renames test ids in a way pytest 9 no longer reads)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class ServerGroupScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = super()._split_scope(nodeid)
            return GROUP_OF.get(path.rsplit("/", 1)[-1], path)

    return ServerGroupScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    # a stable sort: each group's tests keep their order (and stay together)
    items.sort(key=lambda item: (-group_seconds(GROUP_OF.get(item.path.name, item.path.name)),
                                 GROUP_OF.get(item.path.name, item.path.name)))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed test that used a real printer server gets the end of that server's log in its report (CI
    prints only the report: the cause of a server-side stall is there, not in the test's own output)."""
    outcome = yield
    report = outcome.get_result()
    if report.when == "call" and report.failed:
        for name in ("prusalink_server", "moonraker_server"):
            server = getattr(item, "funcargs", {}).get(name)
            if server is not None:
                report.sections.append((f"{name}: end of its log", server.log_tail()))


# The real Moonraker + Klippy, started once per session for every test that asks (tests/moonraker_server.py).
from moonraker_server import moonraker_server  # noqa: E402,F401
# The real OctoPrint with its virtual printer, likewise (tests/octoprint_server.py).
from octoprint_server import octoprint  # noqa: E402,F401

