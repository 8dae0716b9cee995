"""Occlusion of the overlay (arapp/render/occlusion.py, docs/occlusion.md).

Oracles: rules written here (a hole is filled by the farther neighbour; where the measured surface is
clearly nearer than the model the model is never drawn), the synthesiser's own ray-cast geometry (the
model box's depth and the ground-truth masks of tracking.synth.occlusion, independent of OpenGL), and
cv2.undistortPoints for the plane. The synthetic recordings are the test scenes (test_occlusion_*, seeds
never used for tuning), rendered small and short once per session.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import trimesh

from arapp.render import occlusion as oc
from tracking.errors import SessionError
from tracking.poses import invert, read_tum
from tracking.synth import synthesize
from tracking.synth.occlusion import MASK_HIDDEN, MASK_NONE, OcclusionRenderer, read_truth
from tracking.synth.presets import OCCLUSION_TEST, OCCLUSION_TUNING, occlusion_scene
from tracking.synth.scene import parse_scene


# -- numpy rules -----------------------------------------------------------------------------
def test_holes_take_the_farther_neighbour_and_open_ones_stay_unknown():
    d = np.array([[0.5, 0.0, 0.0, 0.8, 0.8],
                  [0.8, 0.0, 0.0, 0.5, 0.0],
                  [0.0, 0.0, 0.0, 0.0, 0.0]], np.float32)
    f = oc.fill_holes(d)
    assert f[0].tolist() == pytest.approx([0.5, 0.8, 0.8, 0.8, 0.8])  # the background side wins
    # a hole open to the edge may be background a near object hides from one camera: unknown (0)
    assert f[1].tolist() == pytest.approx([0.8, 0.8, 0.8, 0.5, 0.0])
    assert f[2].tolist() == [0.0] * 5  # nothing known in the row: unknown (the model stays drawn)


def test_model_behind_a_nearer_surface_is_never_drawn():
    rng = np.random.default_rng(5)
    h, w = 60, 80
    scene = (0.4 + 0.4 * rng.random((h // 10, w // 10))).astype(np.float32)
    scene = cv2.resize(scene, (w, h), interpolation=cv2.INTER_NEAREST)  # blocks: real depth edges
    model = np.full((h, w), 0.6, np.float32)
    crop = np.full((h, w, 4), 200, np.uint8)
    occ = oc.Occluder("depth", depth=scene)
    out = occ(crop, 0, 0, model)
    p = oc.DEFAULT_PARAMS
    clearly_behind = model > scene + p.tolerance_m + p.noise_per_m2 * scene ** 2 + 0.002
    clearly_front = model < scene
    r = 3 + p.shrink_px  # beyond the soft edge (3 sigma) and the occluder's erosion
    k = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
    inner_behind = cv2.erode(clearly_behind.astype(np.uint8), k).astype(bool)
    inner_front = cv2.erode(clearly_front.astype(np.uint8), k).astype(bool)
    assert inner_behind.any() and inner_front.any()
    assert np.all(out[inner_behind] == 0)
    assert np.all(out[inner_front] == crop[inner_front])
    # the soft edge: some pixels between fully drawn and hidden
    a = occ.last_alpha
    assert np.any((a > 0.05) & (a < 0.95))


def test_unknown_depth_and_pixels_without_model_depth_leave_the_model_drawn():
    crop = np.full((20, 20, 4), 255, np.uint8)
    occ = oc.Occluder("depth", depth=np.zeros((20, 20), np.float32))
    assert np.array_equal(occ(crop, 0, 0, np.full((20, 20), 0.5, np.float32)), crop)
    occ = oc.Occluder("depth", depth=np.full((20, 20), 0.3, np.float32))
    assert np.array_equal(occ(crop, 0, 0, np.full((20, 20), np.inf, np.float32)), crop)


def test_bad_mode_is_refused():
    with pytest.raises(ValueError, match="off, depth, plane"):
        oc.Occluder("sometimes")


# -- synthetic recordings --------------------------------------------------------------------
@pytest.fixture(scope="session")
def occlusion_recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("occlusion")
    out = {}
    for name in OCCLUSION_TEST:
        synthesize(parse_scene(occlusion_scene(name, 320, 240, 1.0), name), root / name)
        out[name] = root / name
    return out


def test_tuning_and_test_scenes_use_different_seeds():
    seeds = lambda names: {occlusion_scene(n)["seed"] for n in names} | {occlusion_scene(n)["desk"]["seed"]  # noqa: E731
                                                                        for n in names}
    assert not seeds(OCCLUSION_TUNING) & seeds(OCCLUSION_TEST)
    from tracking.synth.presets import EXTRA_TUNING, HELD, PRESETS

    others = [p for group in (PRESETS, EXTRA_TUNING, HELD) for p in group.values()]
    assert not seeds(OCCLUSION_TEST) & ({p["seed"] for p in others} | {p["desk"]["seed"] for p in others})


def test_recording_has_depth_masks_and_model(occlusion_recordings):
    rec = occlusion_recordings["test_occlusion_hand"]
    session = json.loads((rec / "session.json").read_text())
    assert session["depth"]["aligned_to"] == "camera"
    wfm, size, masks = read_truth(rec)
    assert len(masks) == 15 and len(list((rec / "depth").glob("*.png"))) == 15
    hidden = sum(int((m == MASK_HIDDEN).sum()) for m in masks.values())
    shown = sum(int((m != MASK_NONE).sum()) for m in masks.values())
    assert 0.2 * shown < hidden < 0.9 * shown  # the hand covers the model in some frames, in part


def test_bad_occlusion_block_is_one_clear_line():
    data = occlusion_scene("test_occlusion_hand")
    data["occlusion"]["occluder"]["kind"] = "cat"
    with pytest.raises(SessionError, match=r"occlusion\.occluder\.kind: must be 'hand' or 'object'"):
        parse_scene(data, "scene")
    data = occlusion_scene("test_occlusion_hand")
    data["occlusion"]["depth"]["noise"] = 1
    with pytest.raises(SessionError, match=r"occlusion\.depth\.noise: unknown key"):
        parse_scene(data, "scene")
    data = occlusion_scene("test_occlusion_hand")
    data["effects"]["rolling_shutter"] = 0.02
    with pytest.raises(SessionError, match="global shutter"):
        parse_scene(data, "scene")


# a CPU rasteriser's choice, a GPU's: a multisampled depth resolves to one sample off the pixel centre, and
# the surface's polygon offset (lines win over it) pushes it back by about a pixel's depth slope
@pytest.mark.parametrize("antialias, median_m, p95_m", [("ssaa", 0.5e-3, 3e-3), ("msaa", 1.5e-3, 4e-3)])
def test_model_depth_from_the_renderer_matches_the_ray_cast_box(occlusion_recordings, antialias, median_m, p95_m):
    """The renderer's depth read-back (GL depth buffer -> metres, lens distortion applied) against the
    synthesiser's own ray casting of the same box (float geometry, no GL)."""
    from arapp.render import OverlayRenderer

    rec = occlusion_recordings["test_occlusion_object"]
    scene = parse_scene(occlusion_scene("test_occlusion_object", 320, 240, 1.0))
    synth = OcclusionRenderer(scene)
    wfm, size, _ = read_truth(rec)
    box = trimesh.creation.box(tuple(size))
    cam = scene.camera
    with OverlayRenderer(cam.K, cam.dist, cam.width, cam.height, antialias=antialias) as r:
        for i in (0, 7):
            f = synth.render_full(i)
            occ = oc.Occluder("depth", depth=f.depth)
            r.draw(f.image, box, invert(f.pose) @ wfm, occlusion=occ)
            z, x0, y0 = r._last_depth
            truth = f.model_depth[y0:y0 + z.shape[0], x0:x0 + z.shape[1]]
            both = np.isfinite(z) & np.isfinite(truth)
            assert both.sum() > 300
            # nearest-pixel silhouettes differ by a pixel at most: they agree on all but the rim
            assert np.count_nonzero(np.isfinite(z) != np.isfinite(truth)) < 0.12 * both.sum()
            err = np.abs(z[both] - truth[both])
            assert np.median(err) < median_m and np.percentile(err, 95) < p95_m, (np.median(err),
                                                                                  np.percentile(err, 95))


# measured at 320x240: hand IoU 0.937, edge 0.66 px; object 0.967, 0.22 px
@pytest.mark.parametrize("name, iou_min, edge_max", [("test_occlusion_hand", 0.92, 0.9),
                                                     ("test_occlusion_object", 0.95, 0.5)])
def test_depth_occlusion_matches_ground_truth(occlusion_recordings, name, iou_min, edge_max):
    from arapp.render.occlusion_score import score_recording

    s = score_recording(occlusion_recordings[name], "depth")
    assert s.frames >= 4
    assert s.iou_hidden >= iou_min, s.per_frame
    assert s.edge_px <= edge_max
    off = score_recording(occlusion_recordings[name], "plane")  # knows nothing of the hand: hides nothing
    assert off.iou_hidden < 0.05


def test_plane_mode_hides_exactly_what_is_below_the_table():
    """A box sunk half into the anchor's plane: every hidden pixel's model point (unprojected with
    cv2.undistortPoints) is below the plane, every fully drawn one above it."""
    from arapp.render import OverlayRenderer

    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    dist = np.array([-0.05, 0.02, 0.0, 0.0, 0.0])
    world_from_camera = np.eye(4)
    a = np.radians(140)  # looking down at the table from 0.4 m, 40 degrees from the vertical
    world_from_camera[:3, :3] = [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    world_from_camera[:3, 3] = [0.0, 0.4 * np.sin(np.radians(40)), 0.4 * np.cos(np.radians(40))]
    camera_from_world = invert(world_from_camera)
    box = trimesh.creation.box((0.08, 0.08, 0.08))  # centred on the plane: half above, half below
    frame = np.zeros((240, 320, 3), np.uint8)
    from tracking.camera import Camera

    cam = Camera(K, dist, 320, 240)
    occ = oc.Occluder("plane", plane=oc.PlaneDepth(cam), camera_from_world=camera_from_world)
    with OverlayRenderer(K, dist, 320, 240) as r:
        r.draw(frame, box, camera_from_world, occlusion=occ)
        z, x0, y0 = r._last_depth
    alpha = occ.last_alpha
    ys, xs = np.nonzero(np.isfinite(z))
    und = cv2.undistortPoints(np.stack([xs + x0, ys + y0], -1).astype(np.float64).reshape(-1, 1, 2), K, dist)
    p_cam = np.column_stack([und.reshape(-1, 2), np.ones(len(xs))]) * z[ys, xs, None]
    z_world = (p_cam @ world_from_camera[:3, :3].T + world_from_camera[:3, 3])[:, 2]
    a_px = alpha[ys, xs]
    assert (a_px < 0.01).sum() > 200 and (a_px > 0.99).sum() > 200
    assert np.all(z_world[a_px < 0.01] < 0.0005)
    assert np.all(z_world[a_px > 0.99] > -0.0015)


def test_pipeline_leaves_hidden_pixels_as_the_camera_saw_them(occlusion_recordings):
    """Through the app's pipeline (default: depth because the frame has depth): where the ground truth
    says the hand hides the model, and not near its edge, the output is the camera frame unchanged."""
    from arapp.engine.pipeline import Pipeline
    from tracking.recording.schema import load_session
    from tracking.sources.recording import RecordingSource

    rec = occlusion_recordings["test_occlusion_hand"]
    session = load_session(rec)
    wfm, size, masks = read_truth(rec)
    _, gt = read_tum(rec / "groundtruth.tum")
    pipe = Pipeline(session.camera, session.anchors, draw=True, status_line=False)
    pipe.mesh = trimesh.creation.box(tuple(size))
    pipe.world_from_model = wfm
    assert pipe.occlusion_for(np.zeros((2, 2), np.float32)) == "depth" and pipe.occlusion_for(None) == "off"
    src = RecordingSource(rec)
    checked = 0
    try:
        for frame in src:
            hidden = cv2.erode((masks[frame.index] == MASK_HIDDEN).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
            visible = cv2.erode((masks[frame.index] == 255).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
            out = pipe.draw_overlay(frame.image, gt[frame.index], frame.depth)
            if hidden.sum() > 50:
                changed = np.abs(out.astype(int) - frame.image.astype(int)).max(axis=2) > 0
                assert changed[hidden].mean() < 0.02
                checked += 1
            if visible.sum() > 50:
                changed = np.abs(out.astype(int) - frame.image.astype(int)).max(axis=2) > 0
                assert changed[visible].mean() > 0.95
    finally:
        src.close()
        pipe.close()
    assert checked >= 3


def test_replay_refuses_depth_occlusion_without_depth(tmp_path, capsys):
    from arapp.cli import main
    from tracking.camera import Camera
    from tracking.recording.writer import RecordingWriter

    cam = Camera(np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]]), None, 160, 120)
    with RecordingWriter(tmp_path / "rec", cam, 10.0) as w:
        for i in range(3):
            w.write(np.zeros((120, 160, 3), np.uint8), i / 10)
    rc = main(["replay", str(tmp_path / "rec"), "--out", str(tmp_path / "out"), "--occlusion", "depth",
               "--no-video"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "has no depth stream" in err[0] and "--occlusion plane" in err[0]
    assert not (tmp_path / "out").exists()


def test_replay_runs_with_occlusion_from_the_recordings_depth(occlusion_recordings, tmp_path, capsys):
    from arapp.cli import main

    rec = occlusion_recordings["test_occlusion_object"]
    model = tmp_path / "box.stl"
    trimesh.creation.box((40.0, 40.0, 60.0)).export(model)
    for mode in ("depth", "plane"):
        rc = main(["replay", str(rec), "--out", str(tmp_path / mode), "--model", str(model), "--frames", "4",
                   "--occlusion", mode])
        assert rc == 0, capsys.readouterr()
        assert (tmp_path / mode / "overlay.mp4").stat().st_size > 0


# -- app model and GUI -----------------------------------------------------------------------
class _Engine:
    def __init__(self, spec, **options):
        self.sent, self.state = [], {}

    def send(self, command):
        self.sent.append(command)

    def start(self):
        pass

    def stop(self, wait=0.0):
        pass

    def submit(self, fn):
        fn(self.pipe)


def test_the_session_keeps_the_occlusion_choice_and_tells_the_pipeline(occlusion_recordings):
    from arapp.engine import commands as cmd
    from arapp.app.session import MemorySettings, Session
    from arapp.engine.pipeline import Pipeline
    from tracking.recording.schema import load_session

    engines, settings = [], MemorySettings()
    session = Session(lambda spec, **o: engines.append(_Engine(spec, **o)) or engines[-1], settings)
    assert session.occlusion == "auto"
    session.open_source(str(occlusion_recordings["test_occlusion_object"]))
    assert not [c for c in engines[-1].sent if isinstance(c, cmd.SetOcclusion)]  # auto: the pipeline's default
    session.set_occlusion("plane")
    sent = [c for c in engines[-1].sent if isinstance(c, cmd.SetOcclusion)]
    assert [c.mode for c in sent] == ["plane"]
    with pytest.raises(ValueError, match="auto, off, depth, plane"):
        session.set_occlusion("x-ray")
    # the command on a real pipeline; auto is None there (depth when a frame has depth)
    s = load_session(occlusion_recordings["test_occlusion_object"])
    engine = engines[-1]
    engine.pipe = Pipeline(s.camera, s.anchors, draw=False)
    try:
        sent[0].apply(engine)
        assert engine.pipe.occlusion_for(None) == "plane" and engine.state["occlusion"] == "plane"
        cmd.SetOcclusion(None).apply(engine)
        assert engine.pipe.occlusion_for(np.zeros((1, 1), np.float32)) == "depth"
    finally:
        engine.pipe.close()
    # a new session (the app started again) comes back with the choice
    again = Session(lambda spec, **o: engines.append(_Engine(spec, **o)) or engines[-1], settings)
    assert again.occlusion == "plane"
    again.open_source(str(occlusion_recordings["test_occlusion_object"]))
    assert [c.mode for c in engines[-1].sent if isinstance(c, cmd.SetOcclusion)] == ["plane"]


def test_the_model_panel_offers_the_occlusion_modes(qtbot):
    from arapp.gui.panels.model import ModelPanel

    panel = ModelPanel()
    qtbot.addWidget(panel)
    assert [panel.occlusion.itemText(i) for i in range(panel.occlusion.count())] == ["auto", "off", "depth", "plane"]
    with qtbot.waitSignal(panel.occlusion_changed) as sig:
        panel.occlusion.setCurrentText("depth")
    assert sig.args == ["depth"]


def test_print_preview_toolpaths_are_occluded_too():
    """The pipeline hands the same occluder to the toolpath draw (the AR print preview): toolpaths behind a
    nearer surface are not drawn, in front of a farther one they are."""
    from arapp.engine.pipeline import Pipeline
    from arapp.render.modes import LineSet
    from tracking.camera import Camera
    from tracking.recording.schema import parse_anchors

    cam = Camera(np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]]), None, 320, 240)
    anchors = parse_anchors([{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 0, "length": 0.05}])
    pipe = Pipeline(cam, anchors, draw=True, status_line=False)
    world_from_camera = np.diag([1.0, -1.0, -1.0, 1.0])  # looking straight down at the plane from 0.4 m
    world_from_camera[2, 3] = 0.4
    lines = LineSet([np.array([[-0.05, y, 0.0], [0.05, y, 0.0]]) for y in np.linspace(-0.03, 0.03, 7)],
                    (1.0, 0.5, 0.0, 1.0), 3.0)
    pipe.set_toolpaths([lines], np.eye(4))
    frame = np.zeros((240, 320, 3), np.uint8)
    try:
        near = pipe.draw_overlay(frame, world_from_camera, np.full((240, 320), 0.2, np.float32))
        far = pipe.draw_overlay(frame, world_from_camera, np.full((240, 320), 0.6, np.float32))
        none = pipe.draw_overlay(frame, world_from_camera, None)  # no depth this frame: drawn
    finally:
        pipe.close()
    assert np.count_nonzero(far.max(axis=2) > 60) > 500
    assert np.count_nonzero(near.max(axis=2) > 4) == 0  # (the line ends' faint rims blur to 2 levels of 255)
    assert np.array_equal(none, far)
