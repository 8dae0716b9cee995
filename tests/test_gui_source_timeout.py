"""A source that never gives a picture is given up (pytest-qt, offscreen; and the app model without Qt).

The fake camera: its opening blocks (as a camera held by another program or a hung driver can) until the
test lets it go. Old code: the window said "Opening v4l2:0..." for as long as it waited, with no message."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from gui_helpers import TIMEOUT_MS, write_arc_recording

SHORT_S = 0.5  # the test's time limit for a first picture (the app's is 15 s)


class StuckCamera:
    """What the engine's opener returns once `release` is set: a live source with one frame. Until then
    the opener blocks. `closed` is set when the engine closes it."""

    live = True
    seekable = False

    def __init__(self):
        self.release = threading.Event()
        self.closed = threading.Event()

    def open(self):
        self.release.wait(30.0)  # a camera whose opening hangs until the test lets it go
        return self

    def __iter__(self):
        yield np.zeros((48, 64, 3), np.uint8)

    def close(self) -> None:
        self.closed.set()


@pytest.fixture()
def window(threads_window):
    return threads_window


def stuck_engines(window, camera: StuckCamera, made: list):
    """A `make_engine` for the window's session: the thread engine over `camera`'s blocking opener."""
    from arapp.gui.hosts.local import Engine, connect_handlers

    def make(spec, *, name, anchors, speed, loop, handlers):
        engine = Engine(opener=camera.open, name=name, anchors=anchors, speed=speed, loop=loop, parent=window)
        made.append(engine)
        return connect_handlers(engine, handlers)

    return make


def test_a_camera_with_no_picture_is_given_up_with_one_clear_line(qtbot, window, tmp_path):
    w, s = window, window.session
    camera, made = StuckCamera(), []
    real_factory = s.make_engine
    s.make_engine = stuck_engines(w, camera, made)
    s.first_picture.timeout_s = SHORT_S
    try:
        w.open_source("v4l2:0")
        assert w.view.message.startswith("Opening v4l2:0")
        qtbot.waitUntil(lambda: len(w.errors) > 0, timeout=TIMEOUT_MS)
        title, line = w.errors[0]
        assert len(w.errors) == 1 and title == "Camera not answering"
        assert line.startswith(f"No picture from v4l2:0 after {SHORT_S:g} s:") and "\n" not in line
        assert "another program" in line and "choose another source" in line
        # back to a usable state: no source, no 'Opening...', Play off, the source chooser at hand
        assert w.engine is None and w.source_spec is None and not s.first_picture.waiting
        assert w.view.message == line and "opening" not in w.status_source.text()
        assert not w.replay.play_button.isEnabled() and w.replay.play_button.text() == "Play"
        assert w.statusBar().currentMessage().endswith(line)
        assert "v4l2:0" not in s.recent("recent_sources")
        file_menu = next(a.menu() for a in w.menuBar().actions() if a.text().replace("&", "") == "File")
        assert next(a for a in file_menu.actions() if a.text() == "Open source...").isEnabled()
        # the engine was stopped: when the camera answers late, it is closed and nothing keeps running
        engine = made[0]
        camera.release.set()
        assert camera.closed.wait(5.0)
        qtbot.waitUntil(lambda: not engine.running, timeout=5000)
        assert engine.live.stage.current() is None  # no processing thread was started for it
        qtbot.wait(300)
        assert len(w.errors) == 1  # the late camera adds nothing
    finally:
        camera.release.set()
        s.make_engine = real_factory
    # another source opens and shows pictures as usual
    folder = write_arc_recording(tmp_path / "arc", n=6)
    w.open_source(str(folder))
    qtbot.waitUntil(lambda: w.last_shown is not None, timeout=TIMEOUT_MS)
    qtbot.wait(int(3 * SHORT_S * 1000))  # well past the limit: a source with pictures is not given up
    assert w.engine is not None and w.source_spec == str(folder) and len(w.errors) == 1


def test_the_session_gives_up_without_qt_on_its_own_clock():
    """The time limit lives in the app model: a fake engine that never answers, a fake clock."""
    from arapp.app.session import Session

    class SilentEngine:
        running, playing = True, True

        def __init__(self):
            self.stopped = False

        def send(self, command):
            pass

        def start(self):
            pass

        def stop(self, wait=0.0):
            self.stopped = True
            self.running = False

        def take(self):
            return None

    engines, failed = [], []
    s = Session(lambda spec, **_kw: engines.append(SilentEngine()) or engines[-1])
    now = [100.0]
    s.first_picture.clock = lambda: now[0]
    s.first_picture.timeout_s = 15.0
    s.events.source_failed.connect(lambda name, line: failed.append((name, line)))
    s.open_source("recordings/board_orbit")
    now[0] += 14.9
    s.tick()
    assert s.engine is engines[0] and not s.errors
    now[0] += 0.2
    s.tick()
    assert engines[0].stopped and s.engine is None and s.source_spec is None
    assert s.errors == [("Source not answering", failed[0][1])]
    assert failed[0][0] == "board_orbit" and failed[0][1].startswith("No picture from board_orbit after 15 s: ")
    s.tick()  # nothing more to give up
    assert len(s.errors) == 1
