"""The replay bar's time label: elapsed / total for a source of known length, elapsed only otherwise."""

from arapp.gui.panels.replay import ReplayBar


def test_time_label_shows_a_total_only_when_the_length_is_known(qtbot):
    bar = ReplayBar()
    qtbot.addWidget(bar)
    bar.set_source(seekable=True, frame_count=90, fps=30.0)
    bar.set_position(45, 1.5)
    assert bar.time_label.text() == "0:01.5 / 0:03.0"
    # a plain video read straight through: its length is not known, and "/ 0:00.0" would read as empty
    bar.set_source(seekable=False, frame_count=0, fps=30.0)
    bar.set_position(90, 3.0)
    assert bar.time_label.text() == "0:03.0"
