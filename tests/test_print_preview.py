"""The AR print preview: sliced toolpaths drawn on the real bed, registered to the G-code coordinates."""

import cv2
import numpy as np
import pytest
import trimesh

from arapp.printing import SliceSettings, load_profile, slice_mesh
from arapp.printing.bed_anchor import save_bed_anchor, bed_from_anchor_measured
from arapp.printing.gcode import parse_gcode
from arapp.engine.toolpath_overlay import (KIND_COLOURS, OUT_OF_BED_COLOUR, out_of_bed, toolpath_line_sets, toolpath_overlay)
from tracking.poses import invert, read_tum
from tracking.recording.schema import load_session

RECORDING = "recordings/printer_bed"


@pytest.fixture(scope="module")
def sliced(tmp_path_factory):
    """A 24 mm box sliced at the bed centre, and a profile whose bed marker lies 60 mm in front-left of it
    (where the recording's camera looks)."""
    tmp = tmp_path_factory.mktemp("preview")
    profile_path = tmp / "printer.json"
    save_bed_anchor(profile_path, {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.04},
                    bed_from_anchor_measured((125.0 - 60.0, 105.0 - 60.0)))
    profile = load_profile(profile_path)
    box = trimesh.creation.box(extents=(24.0, 24.0, 3.0))
    result = slice_mesh(box, SliceSettings(layer_height=0.3, first_layer_height=0.3, infill=15), profile)
    gcode = tmp / "box.gcode"
    gcode.write_text(result.gcode)
    return gcode, profile_path


def _samples(segments: np.ndarray, step: float = 0.1) -> np.ndarray:
    pts = []
    for a, b in segments:
        n = max(2, int(np.linalg.norm(b - a) / step) + 1)
        pts.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
    return np.concatenate(pts)


@pytest.mark.parametrize("frame_index", [0, 37, 74])
def test_toolpath_pixels_match_projected_gcode(sliced, repo_root, frame_index):
    from arapp.render import OverlayRenderer

    gcode, profile_path = sliced
    session = load_session(repo_root / RECORDING)
    cam = session.camera
    _, gt = read_tum(repo_root / RECORDING / "groundtruth.tum")
    layers = parse_gcode(gcode.read_text())
    layer = len(layers) // 2
    sets, world_from_bed = toolpath_overlay(gcode, profile_path, session.anchors, layer=layer)
    camera_from_bed = invert(gt[frame_index]) @ world_from_bed
    with OverlayRenderer(cam.K, cam.dist, cam.width, cam.height) as renderer:
        rgba = renderer.render(None, camera_from_bed, line_sets=sets)

    # Independent reference: layer `layer`'s perimeters from the G-code, projected by OpenCV with the true pose.
    seg = layers[layer].segments(kinds=("perimeter",))
    assert len(seg) > 4
    pts = _samples(seg)
    in_camera = pts @ camera_from_bed[:3, :3].T + camera_from_bed[:3, 3]  # bed mm -> camera metres
    proj, _ = cv2.projectPoints(in_camera, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    proj = proj.reshape(-1, 2)
    assert np.all((proj > 5) & (proj < [cam.width - 5, cam.height - 5])), "the part must be in view"

    colour = np.array(KIND_COLOURS["perimeter"][:3]) * 255
    drawn = (rgba[..., 3] > 200) & (np.abs(rgba[..., :3].astype(float) - colour).max(axis=2) < 40)
    ys, xs = np.nonzero(drawn)
    assert len(xs) > 100
    # every perimeter pixel drawn lies on the projected path (a 2 px line: centres within 1 px, plus rounding)
    ref = np.full((cam.height, cam.width), 255, np.uint8)
    ref[np.round(proj[:, 1]).astype(int), np.round(proj[:, 0]).astype(int)] = 0
    dist_to_path = cv2.distanceTransform(ref, cv2.DIST_L2, 5)
    assert np.percentile(dist_to_path[ys, xs], 99) <= 1.5
    # and the path is drawn all along: each projected point has a drawn pixel within 1 px (in any colour:
    # infill drawn over the inner perimeter where they touch hides it there)
    hit = np.full((cam.height, cam.width), 255, np.uint8)
    hit[rgba[..., 3] > 200] = 0
    dist_to_drawn = cv2.distanceTransform(hit, cv2.DIST_L2, 5)
    d = dist_to_drawn[np.round(proj[:, 1]).astype(int), np.round(proj[:, 0]).astype(int)]
    assert np.mean(d <= 1.0) > 0.99


def test_layers_above_are_hidden_and_below_dimmed(sliced):
    gcode, _ = sliced
    layers = parse_gcode(gcode.read_text())
    sets = toolpath_line_sets(layers, (250, 210, 210), layer=2)
    toolpaths = [s for s in sets if np.asarray(s.polylines).ndim == 3]  # the bed outline is one polyline
    z_full = {round(float(z), 3) for s in toolpaths if s.rgba[3] > 0.9 and s.width_px > 1.5
              for z in np.asarray(s.polylines)[:, :, 2].ravel()}
    assert z_full == {round(layers[2].z, 3)}
    z_dim = {round(float(z), 3) for s in toolpaths if s.rgba[3] < 0.3 for z in np.asarray(s.polylines)[:, :, 2].ravel()}
    assert z_dim == {round(layers[0].z, 3), round(layers[1].z, 3)}


def test_part_off_the_bed_is_flagged():
    seg = np.array([[[10, 10, 0.2], [20, 10, 0.2]], [[240, 100, 0.2], [260, 100, 0.2]]], float)
    assert out_of_bed(seg, 250, 210).tolist() == [False, True]

    class Layer:
        index, z = 0, 0.2

        def segments(self, kinds, extruding=True):
            return seg if kinds == ("perimeter",) else np.zeros((0, 2, 3))

    sets = toolpath_line_sets([Layer()], (250, 210, 210))
    assert any(s.rgba == tuple(OUT_OF_BED_COLOUR) or tuple(s.rgba) == tuple(OUT_OF_BED_COLOUR) for s in sets)


def test_replay_with_toolpaths_writes_the_overlay(sliced, repo_root, tmp_path):
    from arapp.cli import main

    gcode, profile_path = sliced
    rc = main(["replay", str(repo_root / RECORDING), "--out", str(tmp_path), "--toolpaths", str(gcode),
               "--printer", str(profile_path), "--layer", "3", "--frames", "10", "--no-slam"])
    assert rc == 0
    cap = cv2.VideoCapture(str(tmp_path / "overlay.mp4"))
    ok, frame = cap.read()
    assert ok
    src = cv2.VideoCapture(str(repo_root / RECORDING / "video.avi"))
    _, original = src.read()
    diff = np.abs(frame.astype(int) - original.astype(int)).max(axis=2)
    assert np.mean(diff[60:] > 60) > 0.002  # toolpaths (and the bed outline) drawn below the status line
