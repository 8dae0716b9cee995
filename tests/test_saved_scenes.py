"""Saved scenes (issue 30 part 1): the map's arrays, the scene file (atomic, versioned, refusals), keyframe
culling, and a fresh run that relocalises against a saved map with the marker removed.

Oracles: hand-built maps compared field by field; ground truth of synthetic revisits
(tracking.synth.revisits, `test_scene` set: never used while tuning) in the first session's world frame.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from arapp.exchange.scene import SceneError, SceneFile, read_scene, write_scene
from tracking.camera import Camera
from tracking.slam.features import Features
from tracking.slam.map import Map
from tracking.slam.map_io import MapError, cull_keyframes, map_from_arrays, map_to_arrays

ROOT = Path(__file__).resolve().parents[1]
ANCHORS = [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 21, "length": 0.055}]


def camera(f: float = 530.0) -> Camera:
    return Camera([[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]], [0, 0, 0, 0, 0], 640, 480)


def toy_map(n_kf: int = 6, n_pts: int = 40, seed: int = 0) -> Map:
    """Keyframes looking at the same points (each sees all of them), built through Map's own API."""
    rng = np.random.default_rng(seed)
    m = Map()
    X = rng.uniform(-0.1, 0.1, (n_pts, 3)) * [1, 1, 0]
    D = rng.integers(0, 256, (n_pts, 32), dtype=np.uint8)
    for k in range(n_kf):
        pose = np.eye(4)
        pose[:3, 3] = [0.02 * k, 0, -0.4]
        nf = n_pts + 10   # ten features match no point
        xy = rng.uniform(0, 640, (nf, 2))
        feats = Features(xy, xy + 0.25, rng.integers(0, 4, nf), rng.integers(0, 256, (nf, 32), dtype=np.uint8))
        pid = np.full(nf, -1)
        if k > 0:
            pid[:n_pts] = np.arange(n_pts)
        anchor = (np.zeros((4, 3)), np.zeros((4, 2))) if k == 0 else (None, None)
        m.new_keyframe(0.1 * k, pose, feats, pid, *anchor)
        if k == 0:
            for i in range(n_pts):
                m.add_point(X[i], D[i], {0: i})
    m.count_matches(np.arange(n_pts), np.arange(0, n_pts, 2))
    return m


def same_map(a: Map, b: Map) -> None:
    assert sorted(a.keyframes) == sorted(b.keyframes) and sorted(a.points) == sorted(b.points)
    for k, ka in a.keyframes.items():
        kb = b.keyframes[k]
        np.testing.assert_array_equal(ka.pose, kb.pose)
        np.testing.assert_array_equal(ka.point_ids, kb.point_ids)
        np.testing.assert_array_equal(ka.feats.desc, kb.feats.desc)
        np.testing.assert_allclose(ka.feats.und, kb.feats.und, atol=1e-4)   # stored as float32
        np.testing.assert_array_equal(ka.anchor_world, kb.anchor_world)
    for p, pa in a.points.items():
        pb = b.points[p]
        np.testing.assert_array_equal(pa.xyz, pb.xyz)
        np.testing.assert_array_equal(pa.desc, pb.desc)
        assert pa.obs == pb.obs and a.match_counts(p) == b.match_counts(p)


def test_map_arrays_round_trip_keep_every_field():
    m = toy_map()
    back = map_from_arrays(map_to_arrays(m))
    same_map(m, back)
    # new keyframes and points continue the ids (a merged run never reuses a saved id)
    kf = back.new_keyframe(9.0, np.eye(4), m.keyframes[0].feats, np.full(len(m.keyframes[0].feats), -1))
    assert kf.id == max(m.keyframes) + 1


def test_covisibility_counts_shared_points():
    a = map_to_arrays(toy_map(n_kf=3, n_pts=20))
    # keyframe 0 created all 20 points and 1, 2 see them all: every pair shares 20
    assert sorted(map(tuple, a["covis"].tolist())) == [(0, 1, 20), (0, 2, 20), (1, 2, 20)]


@pytest.mark.parametrize("change, word", [
    (lambda a: a.pop("pt_xyz"), "pt_xyz"),
    (lambda a: a.__setitem__("kf_pose", a["kf_pose"][:-1]), "kf_pose"),
    (lambda a: a.__setitem__("feat_point", np.where(a["feat_point"] >= 0, a["feat_point"] + 1000, -1)), "feat_point"),
    (lambda a: a.__setitem__("pt_xyz", a["pt_xyz"] * np.nan), "NaN"),
])
def test_inconsistent_map_arrays_are_refused_naming_the_array(change, word):
    a = map_to_arrays(toy_map())
    change(a)
    with pytest.raises(MapError, match=word):
        map_from_arrays(a)


def test_keyframe_culling_drops_redundant_views_keeps_anchor_ones_and_bounds_the_count():
    m = toy_map(n_kf=10)
    removed = cull_keyframes(m, max_keyframes=100, redundancy=0.9, min_views=3)
    # every point is seen by all 10 keyframes: a keyframe is redundant while each of its points is seen by
    # 3 others (4 keyframes left), so one more goes and 3 stay; keyframe 0 (it saw the anchor) is kept
    assert removed == 7 and len(m.keyframes) == 3 and 0 in m.keyframes
    assert all(len(p.obs) == 3 for p in m.points.values())
    m = toy_map(n_kf=10)
    cull_keyframes(m, max_keyframes=3, redundancy=1.1)
    assert len(m.keyframes) == 3 and 0 in m.keyframes


def test_scene_file_round_trip_and_model_paths_relative(tmp_path):
    m = toy_map()
    model = tmp_path / "models" / "part.json"
    model.parent.mkdir()
    model.write_text("{}")
    path = write_scene(tmp_path / "desk.arscene", SceneFile(camera(), ANCHORS, [
        {"path": str(model), "placement": {"size_mm": 42.0, "offset": [1, 2, 0], "rotation_deg": [0, 0, 30]}}], m))
    with zipfile.ZipFile(path) as z:
        doc = json.loads(z.read("scene.json"))
    assert doc["format"] == "arapp-scene" and doc["version"] == 1
    assert doc["models"][0]["path"] == "models/part.json"   # beside the scene: moved together
    back = read_scene(path, camera())
    same_map(m, back.map)
    assert back.anchors == ANCHORS and back.models[0]["path"] == str(model.resolve())
    assert back.models[0]["placement"] == {"size_mm": 42.0, "offset": [1, 2, 0], "rotation_deg": [0, 0, 30]}
    np.testing.assert_array_equal(back.camera.K, camera().K)
    assert len(back.history) == 1


def _write_zip(path: Path, doc, arrays: dict | None = None) -> None:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("scene.json", json.dumps(doc))
        for name, arr in (arrays or {}).items():
            import io
            buf = io.BytesIO()
            np.save(buf, arr)
            z.writestr(f"map/{name}.npy", buf.getvalue())


@pytest.mark.parametrize("make, words", [
    (lambda p: p.write_bytes(b"not a zip at all"), ["corrupt", "start a new scene"]),
    (lambda p: _write_zip(p, {"format": "arapp-scene", "version": 99}), ["newer arapp", "version 99"]),
    (lambda p: _write_zip(p, {"format": "something-else", "version": 1}), ["not an arapp scene"]),
    (lambda p: _write_zip(p, {"format": "arapp-scene", "version": 1, "camera": camera().to_dict(),
                              "anchors": ANCHORS}), ["corrupt", "missing"]),
])
def test_unusable_scene_files_get_one_line_and_stay_untouched(tmp_path, make, words):
    p = tmp_path / "bad.arscene"
    make(p)
    before = p.read_bytes()
    with pytest.raises(SceneError) as e:
        read_scene(p, camera())
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and all(w in msg for w in words), msg
    assert p.read_bytes() == before


def test_a_scene_from_another_camera_is_refused(tmp_path):
    path = write_scene(tmp_path / "desk.arscene", SceneFile(camera(530.0), ANCHORS, [], toy_map()))
    read_scene(path, camera(532.0))   # a recalibration of the same webcam (0.4 %) is the same camera
    with pytest.raises(SceneError, match="another camera calibration.*recalibrate"):
        read_scene(path, camera(600.0))
    with pytest.raises(SceneError, match="another camera.*1280x720"):
        read_scene(path, camera().scaled(1280, 720))


def test_a_failed_save_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = write_scene(tmp_path / "desk.arscene", SceneFile(camera(), ANCHORS, [], toy_map()))
    before = path.read_bytes()
    calls = []

    def failing(buf, arr, allow_pickle=False):
        calls.append(1)
        if len(calls) > 3:
            raise OSError("disk full")
        np.save(buf, arr)

    monkeypatch.setattr(np.lib.format, "write_array", failing)
    with pytest.raises(OSError, match="disk full"):
        write_scene(path, SceneFile(camera(), ANCHORS, [], toy_map(seed=1)))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["desk.arscene"]


# -- relocalising against a saved map (synthetic revisits, ground truth) -----------------------------------

@pytest.fixture(scope="module")
def saved_desk(tmp_path_factory):
    """The test set's mapping session tracked and saved as a scene file (the first session)."""
    from arapp.engine.scene_run import SceneRun
    from scenes import load_recording
    from tracking.synth.cache import cached_recording
    from tracking.fusion import Tracker

    frames, session = load_recording(cached_recording("test_scene_map"))
    path = tmp_path_factory.mktemp("scene") / "desk.arscene"
    with Tracker(session.camera, session.anchors, slam=True) as tr:
        run = SceneRun.start(tr, session.camera, [a.to_dict() for a in session.anchors])
        for t, img, _ in frames:
            res = tr.process(img, t)
            tr.catch_up()
            run.observe(img, t, res.world_from_camera, res.state)
        run.save(path)
    return path


def _revisit(name: str, scene_path, frames: int = 12):
    from arapp.engine.scene_run import SceneRun
    from scenes import load_recording
    from tracking.synth.cache import cached_recording
    from tracking.fusion import Tracker

    data, session = load_recording(cached_recording(name), slice(0, frames))
    out = []
    with Tracker(session.camera, session.anchors, slam=True) as tr:
        run = SceneRun.start(tr, session.camera, [a.to_dict() for a in session.anchors], load=scene_path)
        for t, img, gt in data:
            res = tr.process(img, t)
            tr.catch_up()
            run.observe(img, t, res.world_from_camera, res.state)
            out.append((t, res, gt))
        n_kf = len(tr.map.keyframes)
    return out, run, n_kf


def test_without_the_marker_a_saved_scene_places_the_camera_where_ground_truth_does(saved_desk):
    from tracking.poses import rotation_angle

    # without the scene file nothing defines the world: every frame is lost
    lost, _, _ = _revisit("test_scene_revisit_0_bare", None, frames=6)
    assert all(r.world_from_camera is None for _, r, _ in lost)
    got, run, _ = _revisit("test_scene_revisit_0_bare", saved_desk)
    posed = [(t, r, gt) for t, r, gt in got if r.world_from_camera is not None]
    assert posed and posed[0][0] - got[0][0] <= 1.0   # within 1 s of the desk in view (from the start)
    assert all(r.state == "slam" and r.markers == 0 for _, r, _ in posed)
    for _, r, gt in posed:
        p = r.world_from_camera
        assert np.linalg.norm(p[:3, 3] - gt[:3, 3]) < 0.01
        assert np.degrees(rotation_angle(p[:3, :3].T @ gt[:3, :3])) < 1.0
    assert run.summary()["first_pose_state"] == "slam"


def test_with_the_marker_the_saved_map_agrees_with_it_and_a_run_extends_the_scene(saved_desk, tmp_path):
    got, run, n_kf = _revisit("test_scene_revisit_0_evening", saved_desk, frames=20)
    check = run.summary()["marker_vs_map"]
    assert check is not None and check["agree"], check
    assert check["position_m"] < 0.01 and check["rotation_deg"] < 1.0
    loaded = run.summary()["loaded_keyframes"]
    assert n_kf >= loaded
    # saved again: the loaded keyframes are kept (ids of the first run), what this run added comes after
    path = run.save(tmp_path / "extended.arscene")
    back = read_scene(path)
    assert len(back.history) == 2
    first = read_scene(saved_desk)
    assert set(first.map.keyframes) & set(back.map.keyframes)


def test_a_moved_marker_is_reported(saved_desk, tmp_path):
    """The scene's anchor says the world is 3 cm off: the map (saved before the move) disagrees with the
    marker by about that much, and the run says so."""
    from arapp.engine.scene_run import SceneRun
    from scenes import load_recording
    from tracking.synth.cache import cached_recording
    from tracking.fusion import Tracker

    scene = read_scene(saved_desk)
    shift = np.eye(4)
    shift[0, 3] = 0.03
    arrays = map_to_arrays(scene.map)
    arrays["pt_xyz"] = arrays["pt_xyz"] + [0.03, 0, 0]
    arrays["kf_pose"] = shift @ arrays["kf_pose"]
    moved = write_scene(tmp_path / "moved.arscene", SceneFile(scene.camera, scene.anchors, [],
                                                              map_from_arrays(arrays)))
    data, session = load_recording(cached_recording("test_scene_revisit_0_evening"),
                                   slice(0, 8))
    with Tracker(session.camera, session.anchors, slam=True) as tr:
        run = SceneRun.start(tr, session.camera, [a.to_dict() for a in session.anchors], load=moved)
        for t, img, _ in data:
            res = tr.process(img, t)
            run.observe(img, t, res.world_from_camera, res.state)
    check = run.summary()["marker_vs_map"]
    assert check is not None and not check["agree"] and abs(check["position_m"] - 0.03) < 0.006
    assert any("disagree" in n and "moved" in n for n in run.notes)


def test_a_scene_of_another_world_anchor_is_refused(saved_desk):
    from arapp.engine.scene_run import SceneRun
    from tracking.fusion import Tracker

    other = [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05}]
    from tracking.recording.schema import parse_anchors

    with Tracker(camera(read_scene(saved_desk).camera.K[0, 0]), parse_anchors(other), slam=True) as tr:
        with pytest.raises(SceneError, match="another world anchor"):
            SceneRun.start(tr, read_scene(saved_desk).camera, other, load=saved_desk)


def test_gui_tracks_against_a_scene_without_the_marker_and_saves_it_on_request(qtbot, threads_window, saved_desk,
                                                                               tmp_path):
    """`arapp gui --scene` as run_gui does it: the scene opened, then the source; the first poses come from
    the map (no marker on the desk) where ground truth puts the camera; File > Save scene writes the file
    (history grows by one) and the last scene is remembered for File > Reopen last scene."""
    from arapp.store import user_config
    from tracking.poses import read_tum
    from tracking.synth.cache import cached_recording

    w = threads_window
    rec = cached_recording("test_scene_revisit_1_bare")
    model = ROOT / "models" / "vase.json"
    placed = {"size_mm": 37.0, "offset": [5.0, -3.0, 0.0], "rotation_deg": [0.0, 0.0, 20.0]}
    first = read_scene(saved_desk)
    scene = write_scene(tmp_path / "desk.arscene", SceneFile(first.camera, first.anchors,
                                                             [{"path": str(model), "placement": placed}], first.map))
    w.session.scenes.open(str(scene))
    w.open_source(str(rec))
    qtbot.waitUntil(lambda: w.last_shown is not None and w.last_shown.result.world_from_camera is not None,
                    timeout=60_000)
    res = w.last_shown.result
    assert res.state == "slam" and res.markers == 0
    qtbot.waitUntil(lambda: w.session.placement is not None and w.session.placement.size_mm == 37.0, timeout=30_000)
    assert Path(w.session.model_path) == model
    assert w.session.placement.offset == (5.0, -3.0, 0.0) and w.session.placement.rotation_deg == (0.0, 0.0, 20.0)
    gt_t, gt = read_tum(rec / "groundtruth.tum")
    truth = gt[int(np.argmin(np.abs(gt_t - res.t)))]
    assert np.linalg.norm(res.world_from_camera[:3, 3] - truth[:3, 3]) < 0.01
    out = tmp_path / "saved.arscene"
    w.session.scenes.save(str(out))
    qtbot.waitUntil(out.is_file, timeout=30_000)
    saved = read_scene(out)
    assert len(saved.history) == 2
    assert saved.models[0]["path"] == str(model) and saved.models[0]["placement"]["size_mm"] == 37.0
    assert user_config.recall("last_scene") == str(out.resolve())
    assert w.session.scenes.last() == str(out.resolve())


def test_replay_saves_a_scene_then_starts_from_it_and_refuses_a_bad_one_in_one_line(saved_desk, tmp_path, capsys):
    """`arapp replay --save-scene` writes the scene with the model and placement; `--scene` starts from it
    (report.json says how the first pose came); a corrupt scene file: one line, exit 2, no --out, file kept."""
    from arapp.cli import main
    from tracking.synth.cache import cached_recording

    rec = cached_recording("test_scene_revisit_0_bare")
    first = read_scene(saved_desk)
    scene = write_scene(tmp_path / "desk.arscene", SceneFile(first.camera, first.anchors, [
        {"path": str(ROOT / "models" / "vase.json"), "placement": {"size_mm": 33.0}}], first.map))
    out = tmp_path / "out"
    assert main(["replay", str(rec), "--scene", str(scene), "--save-scene", str(tmp_path / "after.arscene"),
                 "--out", str(out), "--no-video", "--frames", "8"]) == 0
    report = json.loads((out / "report.json").read_text())["scene"]
    assert report["first_pose_s"] == 0.0 and report["first_pose_state"] == "slam"
    after = read_scene(tmp_path / "after.arscene")
    assert after.models[0]["placement"] == {"size_mm": 33.0, "offset": [0.0, 0.0, 0.0], "rotation_deg": [0.0, 0.0, 0.0]}
    assert len(after.history) == 2
    assert "saved scene" in capsys.readouterr().out
    bad = tmp_path / "bad.arscene"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["replay", str(rec), "--scene", str(bad), "--out", str(tmp_path / "o2"), "--no-video"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "corrupt scene file" in err[0] and "start a new scene" in err[0]
    assert not (tmp_path / "o2").exists() and bad.read_bytes() == b"PK\x03\x04 truncated"


def test_revisits_share_the_desk_and_world_and_bare_ones_have_no_marker():
    """OpenCV's own detector finds the marker on a revisit with it and nothing on one without; every
    session of a set names the same anchor (the same world frame) and desk; sets use seeds of their own."""
    import cv2

    from scenes import load_recording
    from tracking.synth import scene_from_arg
    from tracking.synth.cache import cached_recording
    from tracking.synth.revisits import SETS

    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    found = {}
    for name in ("test_scene_revisit_0_evening", "test_scene_revisit_0_bare"):
        frames, _ = load_recording(cached_recording(name), slice(0, 1))
        _, ids, _ = det.detectMarkers(cv2.cvtColor(frames[0][1], cv2.COLOR_BGR2GRAY))
        found[name] = [] if ids is None else ids.ravel().tolist()
    assert found == {"test_scene_revisit_0_evening": [21], "test_scene_revisit_0_bare": []}
    base = scene_from_arg("test_scene_map")
    for name in ("test_scene_revisit_3_bare_wide", "test_scene_revisit_2_path"):
        s = scene_from_arg(name)
        assert s.anchor_blocks == base.anchor_blocks and s.desk_seed == base.desk_seed
        assert s.desk_size == base.desk_size and s.seed != base.seed
    assert scene_from_arg("test_scene_revisit_1_bare").anchors_shown is False
    tune = {SETS["tune_scene"][k] for k in ("seed", "desk")}
    assert not tune & {SETS["test_scene"][k] for k in ("seed", "desk")}


def test_gui_says_when_the_marker_and_the_saved_scene_disagree(qtbot, threads_window, saved_desk, tmp_path):
    """A scene whose map sits 3 cm off the marker (the marker moved since): the window shows it, once."""
    from tracking.synth.cache import cached_recording

    scene = read_scene(saved_desk)
    arrays = map_to_arrays(scene.map)
    arrays["pt_xyz"] = arrays["pt_xyz"] + [0.0, 0.03, 0.0]
    arrays["kf_pose"][:, 1, 3] += 0.03
    moved = write_scene(tmp_path / "moved.arscene", SceneFile(scene.camera, scene.anchors, [],
                                                              map_from_arrays(arrays)))
    w = threads_window
    w.session.scenes.open(str(moved))
    w.open_source(str(cached_recording("test_scene_revisit_0_evening")))
    qtbot.waitUntil(lambda: any("disagree" in t for t, _ in w.session.errors), timeout=60_000)
    (title, message), = [e for e in w.session.errors if "disagree" in e[0]]
    assert "cm" in message and "moved" in message
    cm = float(message.split(" by ")[1].split(" cm")[0])
    assert abs(cm - 3.0) < 0.6
