"""`arapp replay` / `arapp record` say why nothing was tracked and offer what the video shows (issue 26.1).

Oracles: the anchors recordings/board_orbit's session.json states (its video shows that 4x3 DICT_4X4_50
board), and a replay with the suggested anchors that tracks the clip.
"""

import json

import pytest

from arapp.cli import main
from scenes import plain_clip


@pytest.fixture(scope="module")
def clip(tmp_path_factory, repo_root):
    """A plain video cut from recordings/board_orbit (no session.json: the default anchor is looked for)."""
    return plain_clip(repo_root / "recordings" / "board_orbit" / "video.avi",
                      tmp_path_factory.mktemp("clip") / "clip.mp4", 20)


def _lines(capsys, prefix):
    return [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(prefix)]


def test_replay_that_tracks_nothing_says_why_and_the_suggestion_tracks(clip, tmp_path, capsys, repo_root):
    assert main(["replay", str(clip), "--out", str(tmp_path / "a"), "--no-video", "--no-slam"]) == 0
    lines = _lines(capsys, "replay: ")
    why = [ln for ln in lines if ln.startswith("replay: nothing tracked: ")]
    assert why == ["replay: nothing tracked: no anchors were given, so the default (ArUco id 0, DICT_ARUCO_MIP_36h12, "
                   "60 mm) was looked for; markers of another dictionary seen (DICT_4X4 ids 0-11), not the anchors' "
                   "DICT_ARUCO_MIP_36h12"]
    (offer,) = [ln for ln in lines if ln.startswith("replay: found ")]
    assert offer.startswith("replay: found a 4x3 DICT_4X4_50 board (ids 0-11); assuming 40 mm markers")
    # the anchor found is written into the output folder, and the line names that file for --anchors
    anchors = tmp_path / "a" / "anchors-found.json"
    assert offer.endswith(f"use --anchors {anchors} (written with that anchor)")
    (found,) = json.loads(anchors.read_text())
    (truth,) = json.loads((repo_root / "recordings" / "board_orbit" / "session.json").read_text())["anchors"]
    layout = ("kind", "dictionary", "squares_x", "squares_y")
    assert {k: found.get(k) for k in layout} == {k: truth.get(k) for k in layout}
    assert main(["replay", str(clip), "--anchors", str(anchors), "--out", str(tmp_path / "b"), "--no-video",
                 "--no-slam"]) == 0
    assert not [ln for ln in _lines(capsys, "replay: ") if "nothing tracked" in ln]
    report = json.loads((tmp_path / "b" / "report.json").read_text())
    assert report["tracked_fraction"] == 1.0


def test_replay_without_out_writes_to_out_replay_name(clip, tmp_path, capsys, monkeypatch, repo_root):
    # `arapp replay VIDEO` as the issue writes it: the outputs go to out/replay-NAME in the current folder, said
    anchors = tmp_path / "anchors.json"
    anchors.write_text(json.dumps(json.loads((repo_root / "recordings" / "board_orbit" / "session.json")
                                             .read_text())["anchors"]))
    monkeypatch.chdir(tmp_path)
    assert main(["replay", str(clip), "--anchors", str(anchors), "--no-video", "--no-slam", "--frames", "3"]) == 0
    lines = _lines(capsys, "replay: ")
    assert ("replay: wrote out/replay-clip/poses.tum, tracking.csv, report.json, trajectory.png (--out to choose "
            "the folder)") in lines
    assert (tmp_path / "out" / "replay-clip" / "poses.tum").is_file()
    assert not (tmp_path / "out" / "replay-clip" / "anchors-found.json").exists()   # it tracked: nothing offered


def test_record_with_the_default_anchor_says_why(clip, tmp_path, capsys):
    assert main(["record", "--source", str(clip), "--out", str(tmp_path / "rec")]) == 0
    (why,) = [ln for ln in _lines(capsys, "record: ") if "nothing tracked" in ln]
    assert "markers of another dictionary seen (DICT_4X4 ids 0-11)" in why


def test_record_with_anchors_in_view_says_nothing_more(clip, tmp_path, capsys, repo_root):
    anchors = tmp_path / "anchors.json"
    anchors.write_text(json.dumps(json.loads((repo_root / "recordings" / "board_orbit" / "session.json")
                                             .read_text())["anchors"]))
    assert main(["record", "--source", str(clip), "--anchors", str(anchors), "--out", str(tmp_path / "rec")]) == 0
    assert not [ln for ln in _lines(capsys, "record: ") if "nothing tracked" in ln or "found " in ln]
