"""The tests' own scenes read from the recordings cache (tests/scene_book.py) are the pixels and poses a fresh
render gives: the oracle is `scenes.render_sequence`, the renderer itself, run here beside the cache."""

from __future__ import annotations

import numpy as np

from scene_book import SCENES, book_frames, cached_folder, scene_json
from scenes import render_sequence


def test_cached_frames_are_the_fresh_render():
    fresh, scene = render_sequence(scene_json("still_board"))
    cached, parsed = book_frames("still_board")
    assert len(cached) == len(fresh) == scene.frame_count
    for (t0, img0, pose0), (t1, img1, pose1) in zip(fresh, cached):
        assert t0 == t1 and np.array_equal(pose0, pose1)
        assert img0.dtype == img1.dtype and np.array_equal(img0, img1)   # lossless, every channel
    assert np.array_equal(parsed.camera.K, scene.camera.K) and len(parsed.anchors) == len(scene.anchors)
    part, _ = book_frames("still_board", slice(3, 6))
    assert [f[0] for f in part] == [f[0] for f in fresh[3:6]]


def test_a_folder_is_built_once_and_a_new_key_replaces_the_old(tmp_path, monkeypatch):
    monkeypatch.setenv("ARAPP_RECORDINGS_CACHE", str(tmp_path))
    built = []

    def build(out):
        built.append(out)
        out.mkdir()
        (out / "x.txt").write_text(str(len(built)))

    a = cached_folder("thing", "aaaaaaaaaaaa", build)
    assert cached_folder("thing", "aaaaaaaaaaaa", build) == a and len(built) == 1
    b = cached_folder("thing", "bbbbbbbbbbbb", build)
    assert (b / "x.txt").read_text() == "2" and not a.exists()
    assert not list((tmp_path / "scenes").glob(".*partial"))


def test_every_scene_has_a_distinct_name_and_parses():
    from tracking.synth.scene import parse_scene

    names = {scene_json(n)["name"] for n in SCENES}
    assert len(names) == len(SCENES)
    for n in SCENES:
        assert parse_scene(scene_json(n)).frame_count > 0
