"""The print preview's stack of layers: during a print the printed layers are solid, the current one
highlighted, the rest dimmed (the rule checked against the G-code's own layer heights); the renderer draws
a dense stack with only every k-th layer where k layers sit closer than half a line's width on screen,
and the picture stays the one with every layer (compared pixel by pixel)."""

import numpy as np
import pytest
import trimesh

from arapp.printing import SliceSettings, load_profile, slice_mesh
from arapp.printing.bed_anchor import bed_from_anchor_measured, save_bed_anchor
from arapp.printing.gcode import parse_gcode
from arapp.engine.toolpath_overlay import CURRENT_COLOUR, DIM_ALPHA, toolpath_line_sets, world_from_bed
from tracking.poses import invert, read_tum
from tracking.recording.schema import load_session

RECORDING = "recordings/printer_bed"


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("stack")
    profile = load_profile(save_bed_anchor(tmp / "printer.json",
                                           {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.04},
                                           bed_from_anchor_measured((125.0 - 60.0, 105.0 - 60.0))))
    part = trimesh.creation.cylinder(radius=10.0, height=16.0, sections=48)
    result = slice_mesh(part, SliceSettings(layer_height=0.2, first_layer_height=0.2, infill=10), profile)
    return parse_gcode(result.gcode), profile


def z_of(ls) -> set:
    return {round(float(z), 3) for z in np.asarray(ls.segments())[:, 2]}


def test_printed_layers_solid_current_highlighted_rest_dimmed(stack):
    layers, profile = stack
    bed = (profile.bed.width, profile.bed.depth, profile.bed.height)
    k = len(layers) // 2
    zk = round(float(layers[k].z), 3)
    sets = toolpath_line_sets(layers, bed, current=k)[:-1]  # the last is the bed outline
    current = [s for s in sets if tuple(s.rgba) == tuple(CURRENT_COLOUR)]
    assert current and set().union(*map(z_of, current)) == {zk}
    solid = [s for s in sets if s.rgba[3] == 1.0 and s not in current]
    dim = [s for s in sets if s.rgba[3] < 1.0 and s.width_px > 1.0 - 1e-9 and s not in current]
    printed = set().union(*map(z_of, solid))
    assert printed == {round(float(gl.z), 3) for gl in layers[:k]}  # every printed layer, opaque
    later = set().union(*(z_of(s) for s in dim if s.rgba[3] <= DIM_ALPHA + 1e-9))
    assert later == {round(float(gl.z), 3) for gl in layers[k + 1:]}  # the rest, dimmed


def test_dense_stack_drawn_with_fewer_layers_looks_the_same(stack, repo_root):
    import arapp.render.modes as modes
    from arapp.render import OverlayRenderer

    layers, profile = stack
    bed = (profile.bed.width, profile.bed.depth, profile.bed.height)
    sets = toolpath_line_sets(layers, bed)
    session = load_session(repo_root / RECORDING)
    cam = session.camera
    _, gt = read_tum(repo_root / RECORDING / "groundtruth.tum")
    T = invert(gt[0]) @ world_from_bed(np.eye(4), profile.bed_from_anchor)
    with OverlayRenderer(cam.K, cam.dist, cam.width, cam.height) as r:
        items = [(s, r._gpu_lineset(s, True)) for s in sets]
        ranges = r._stack_ranges(items, T, 1e-3)
        full_stack = [s for s in sets if s.layer_starts is not None and s.width_px == 2.0]
        assert full_stack and all(id(s) in ranges for s in full_stack)  # left out layers at this distance
        drawn = sum(int(c.sum()) for f, c in ranges.values())
        assert drawn < 0.7 * sum(len(s.segments()) for s in full_stack)
        fewer = r.render(None, T, line_sets=sets)
        old = modes.LAYER_PX_PER_WIDTH
        modes.LAYER_PX_PER_WIDTH = 0.0  # every layer
        try:
            r._memo = None
            every = r.render(None, T, line_sets=sets)
        finally:
            modes.LAYER_PX_PER_WIDTH = old
    a, b = fewer[..., 3] > 100, every[..., 3] > 100
    assert b.sum() > 2000
    assert (a & b).sum() / (a | b).sum() > 0.98
    assert np.abs(fewer.astype(int) - every.astype(int)).max(axis=2).mean() < 1.0
