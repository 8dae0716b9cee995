"""The built-in slicer: contours against trimesh's own sections, G-code arithmetic, features and the CLI."""

import re
import threading

import numpy as np
import pytest
import shapely
import trimesh

from arapp.printing import SliceSettings, parse_gcode, read_stats, slice_mesh
from arapp.printing.export import ModelDoesNotFitError
from arapp.printing.materials import MATERIALS
from arapp.printing.slicer import SliceCancelled
from arapp.printing.slicer.contours import layer_planes, loops_to_region, slice_loops

W = 0.45  # line width for the 0.4 mm nozzle


def reference_section(mesh, z):
    """The model's cross-section at height z, from trimesh's own plane cut (independent of our contours)."""
    sec = mesh.section(plane_origin=(0, 0, z), plane_normal=(0, 0, 1))
    if sec is None:
        return shapely.Polygon()
    planar, _ = sec.to_2D(to_2D=np.eye(4))
    return shapely.union_all([shapely.Polygon(p.exterior, p.interiors) for p in planar.polygons_full])


def stepped_block():
    """A block with a raised step and a through hole: holes, an upper top surface and overhang-free steps."""
    base = trimesh.creation.box(extents=(24, 16, 4))
    base.apply_translation((0, 0, 2))
    step = trimesh.creation.box(extents=(10, 16, 6))
    step.apply_translation((-7, 0, 7))
    hole = trimesh.creation.cylinder(radius=3, height=30, sections=48)
    hole.apply_translation((6, 0, 0))
    return trimesh.boolean.difference([trimesh.boolean.union([base, step], engine="manifold"), hole], engine="manifold")


@pytest.fixture(scope="module")
def sphere_result():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=10)
    return slice_mesh(mesh, SliceSettings())


@pytest.fixture(scope="module")
def block_result():
    return slice_mesh(stepped_block(), SliceSettings(infill=30, perimeters=3))


def test_layer_planes_follow_the_model_height():
    tops, heights, cut = layer_planes(10.0, 0.3, 0.2)
    assert tops[0] == pytest.approx(0.3) and heights[0] == pytest.approx(0.3)
    assert np.allclose(np.diff(tops), 0.2)
    assert np.all(cut < 10.0) and cut[-1] + 0.2 > 10.0 - 1e-9  # the next plane would lie above the top
    assert np.allclose(cut, tops - heights / 2)


def test_contours_match_trimesh_sections_with_holes_and_planes_through_vertices():
    mesh = stepped_block()
    # planes at 4.0 and 10.0 run exactly through vertices and horizontal facets
    planes = np.array([0.1, 2.0, 3.9, 4.0, 5.5, 9.95])
    loops = slice_loops(mesh, planes)
    for z, layer_loops in zip(planes, loops):
        region = loops_to_region(layer_loops)
        # a vertex on a plane counts as just above it, so the cut is the section just below the plane
        ref = reference_section(mesh, z - 1e-5)
        assert region.is_valid
        assert region.symmetric_difference(ref).area < 1e-3 * max(ref.area, 1.0), z
    assert len(loops[1]) == 2  # outline and the hole


def test_contours_survive_degenerate_and_missing_facets():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=10)
    v, f = mesh.vertices.copy(), mesh.faces.copy()
    # zero-area facets: a repeated vertex, and a sliver on an existing edge's midpoint
    mid = len(v)
    v = np.vstack([v, (v[f[0, 0]] + v[f[0, 1]]) / 2])
    extra = np.array([[f[5, 0], f[5, 0], f[5, 1]], [f[0, 0], mid, f[0, 1]]])
    broken = trimesh.Trimesh(v, np.vstack([f[3:], extra, f[10:12]]), process=False)  # 3 facets missing, 2 doubled
    planes = np.linspace(-9.5, 9.5, 20)
    loops = slice_loops(broken, planes, gap=2.0)
    for z, layer_loops in zip(planes, loops):
        region = loops_to_region(layer_loops)
        ref = reference_section(mesh, z)
        assert region.is_valid and abs(region.area - ref.area) < 0.02 * ref.area, z


def test_filament_and_extrusion_follow_the_e_formula(sphere_result):
    r = sphere_result
    layers = parse_gcode(r.gcode)
    area = np.pi * (1.75 / 2) ** 2
    zs = [l.z for l in layers]
    heights = np.diff([0.0] + zs)
    for layer, h in zip(layers, heights):
        for m in layer.moves:
            if m.extruding:
                length = np.hypot(m.end[0] - m.start[0], m.end[1] - m.start[1])
                # bound: coordinates rounded to 1e-3 mm and E to 1e-5 mm in the file
                assert m.e == pytest.approx(W * h * length / area, abs=8e-5)
    parsed = sum(l.filament_mm for l in layers)
    stats = read_stats(r.gcode)
    assert stats["filament_mm"] == pytest.approx(parsed, abs=0.02)
    assert r.filament_mm == pytest.approx(parsed, abs=0.02)
    assert r.filament_g == pytest.approx(parsed * area * MATERIALS["PLA"].density / 1000, rel=1e-6)
    assert stats["filament_g"] == pytest.approx(r.filament_g, abs=0.01)
    assert stats["print_time_s"] == pytest.approx(r.print_time_s, abs=1)


def test_solid_print_volume_matches_the_model_volume():
    # Fubini: with 100 % infill, the extruded volume is the integral of the slices, ~ the model's volume
    mesh = stepped_block()
    r = slice_mesh(mesh, SliceSettings(infill=100, skirts=0))
    volume = r.filament_mm * np.pi * (1.75 / 2) ** 2
    assert volume == pytest.approx(mesh.volume, rel=0.08)


def test_every_extrusion_lies_in_the_slice_grown_by_half_a_line(block_result):
    r = block_result
    layers = parse_gcode(r.gcode)
    assert len(layers) == r.layers == 50
    z_prev = 0.0
    for layer in layers:
        ref = reference_section(r.mesh, (layer.z + z_prev) / 2)
        z_prev = layer.z
        segs = layer.segments(kinds=("perimeter", "infill"))
        assert len(segs)
        grown = ref.buffer(W / 2 + 0.02)
        assert shapely.covers(grown, shapely.linestrings(segs[:, :, :2])).all(), layer.index


def test_layers_types_and_solid_layers(block_result):
    text = block_result.gcode
    numbers = [int(n) for n in re.findall(r"^;LAYER:(\d+)$", text, re.M)]
    assert numbers == list(range(block_result.layers))
    types = set(re.findall(r"^;TYPE:(\w+)$", text, re.M))
    assert types == {"SKIRT", "EXTERNAL_PERIMETER", "PERIMETER", "SOLID_INFILL", "SPARSE_INFILL"}
    chunks = re.split(r"^;LAYER:\d+$", text, flags=re.M)[1:]
    kinds = [set(re.findall(r"^;TYPE:(\w+)$", c, re.M)) for c in chunks]
    # bottom 3 layers and the top 3 are solid through; the step's top (z = 4) is solid right below it
    for k in (0, 1, 2, 47, 48, 49):
        assert "SPARSE_INFILL" not in kinds[k] and "SOLID_INFILL" in kinds[k]
    assert "SPARSE_INFILL" in kinds[10] and "SOLID_INFILL" in kinds[19]  # layer 19: z 3.8-4.0, under the open top
    assert "SKIRT" in kinds[0] and all("SKIRT" not in k for k in kinds[1:])


def test_sparse_infill_angle_alternates_per_layer(block_result):
    layers = parse_gcode(block_result.gcode)

    def main_direction(layer):
        segs = [(m.start, m.end) for m in layer.moves if m.kind == "infill" and m.extruding]
        d = np.array([[e[0] - s[0], e[1] - s[1]] for s, e in segs])
        length = np.linalg.norm(d, axis=1)
        d = d[length > 3.0]
        ang = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180
        return np.median(ang)

    a10, a11 = main_direction(layers[10]), main_direction(layers[11])
    assert abs(((a10 - a11) % 180) - 90) < 1.0
    assert min(abs(a10 - 45), abs(a10 - 135)) < 1.0


def test_material_temperatures_fan_and_first_layer_speed():
    mesh = trimesh.creation.box(extents=(10, 10, 2))
    for name in ("PLA", "ABS", "TPU"):
        mat = MATERIALS[name]
        r = slice_mesh(mesh, SliceSettings(material=name))
        text = r.gcode
        assert f"M104 S{mat.hotend:.0f}" in text and f"M109 S{mat.hotend:.0f}" in text
        assert mat.hotend_range[0] <= mat.hotend <= mat.hotend_range[1]
        assert f"M190 S{mat.bed:.0f}" in text
        assert ("M106" in text) == (mat.fan > 0)
        layer0 = text.split(";LAYER:0", 1)[1].split(";LAYER:1", 1)[0]
        feeds = {float(f) for f in re.findall(r"^G1 F(\d+)", layer0, re.M)}
        assert feeds == {20.0 * 60 * mat.speed_factor}
        home = text.index("G28")
        assert text.index("M140") < home < text.index("M190") < text.index("M109") < text.index(";LAYER:0")


def test_retraction_and_z_hop_on_long_travel():
    mesh = trimesh.util.concatenate([trimesh.creation.box(extents=(8, 8, 1)).apply_translation((x, 0, 0.5))
                                     for x in (-15, 15)])
    r = slice_mesh(mesh, SliceSettings(z_hop=0.4, retract_length=1.2, retract_min_travel=2.0))
    lines = [l for l in r.gcode.splitlines() if l and not l.startswith(";")]
    layers = parse_gcode(r.gcode)
    hops = [(m.start[2], l.z) for l in layers for m in l.moves
            if m.kind == "travel" and np.hypot(m.end[0] - m.start[0], m.end[1] - m.start[1]) > 10 and m.start[:2] != (0, 0)]
    assert len(hops) >= len(layers) and all(z == pytest.approx(lz + 0.4) for z, lz in hops)
    # each long XY travel (G0) is preceded by a retraction and a lift and followed by a drop and an un-retract
    prev, checked = None, 0
    for i, line in enumerate(lines):
        xy = [float(v) for v in re.findall(r"[XY](-?[\d.]+)", line)]
        if line.startswith("G0 ") and prev is not None and np.hypot(xy[0] - prev[0], xy[1] - prev[1]) > 10:
            assert lines[i - 1].startswith("G1 Z") and re.fullmatch(r"G1 E-?[\d.]+ F\d+", lines[i - 2])
            assert lines[i + 1].startswith("G1 Z") and re.fullmatch(r"G1 E-?[\d.]+ F\d+", lines[i + 2])
            e_before = float(re.search(r"E(-?[\d.]+)", lines[i - 2]).group(1))
            e_after = float(re.search(r"E(-?[\d.]+)", lines[i + 2]).group(1))
            assert e_after - e_before == pytest.approx(1.2, abs=1e-4)
            checked += 1
        if len(xy) == 2:
            prev = xy
    assert checked >= len(layers)


def test_too_large_model_is_refused_or_scaled_to_fit():
    big = trimesh.creation.box(extents=(260, 20, 5))
    with pytest.raises(ModelDoesNotFitError, match="--scale-to-fit"):
        slice_mesh(big, SliceSettings())
    r = slice_mesh(big, SliceSettings(scale_to_fit=True, infill=0, top_layers=1, bottom_layers=1, perimeters=1))
    assert r.scale < 1
    pts = np.concatenate([l.segments(kinds=("perimeter", "infill", "skirt", "travel"), extruding=False).reshape(-1, 3)
                          for l in parse_gcode(r.gcode)])
    assert pts[:, 0].min() >= 0 and pts[:, 0].max() <= 250 and pts[:, 1].min() >= 0 and pts[:, 1].max() <= 210


def test_progress_rises_to_one_and_cancel_stops():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=5)
    seen = []
    slice_mesh(mesh, SliceSettings(), progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and np.all(np.diff(seen) >= 0)
    cancel = threading.Event()

    def stop_half_way(f):
        if f > 0.5:
            cancel.set()

    with pytest.raises(SliceCancelled):
        slice_mesh(mesh, SliceSettings(), progress=stop_half_way, cancel=cancel)


def test_bad_settings_name_the_setting():
    with pytest.raises(ValueError, match="infill"):
        SliceSettings(infill=150)
    with pytest.raises(ValueError, match="material"):
        SliceSettings(material="WOOD")
    with pytest.raises(ValueError, match="layer_height"):
        SliceSettings(layer_height=0)


def test_cli_slices_mesh_and_model_files(tmp_path, repo_root, capsys):
    from arapp.cli import main

    stl = tmp_path / "block.stl"
    stepped_block().export(stl)
    out = tmp_path / "block.gcode"
    assert main(["slice", str(stl), "-o", str(out), "--material", "petg", "--infill", "15", "--perimeters", "3"]) == 0
    text = out.read_text()
    assert "M104 S235" in text and "perimeters = 3" in text and "infill = 15%" in text
    assert len(parse_gcode(text)) == 50
    assert "50 layers" in capsys.readouterr().out
    out2 = tmp_path / "torus.gcode"
    assert main(["slice", str(repo_root / "models" / "torus.json"), "-o", str(out2), "--size", "30",
                 "--layer-height", "0.3"]) == 0
    layers = parse_gcode(out2.read_text())
    assert np.allclose(np.diff([l.z for l in layers]), 0.3)
    assert main(["slice", str(stl), "-o", str(out), "--size", "400"]) == 2
    assert "--scale-to-fit" in capsys.readouterr().err
    assert main(["slice", str(stl), "-o", str(out), "--size", "400", "--scale-to-fit"]) == 0


def test_prusa_option_says_clearly_when_prusaslicer_is_missing(tmp_path, monkeypatch, capsys):
    from arapp.cli import main
    from arapp.printing import prusa

    monkeypatch.setattr(prusa, "find_prusa", lambda: None)
    stl = tmp_path / "cube.stl"
    trimesh.creation.box(extents=(10, 10, 10)).export(stl)
    assert main(["slice", str(stl), "-o", str(tmp_path / "c.gcode"), "--slicer", "prusa"]) == 2
    err = capsys.readouterr().err
    assert "prusa-slicer" in err and "not installed" in err and "--slicer builtin" in err


def test_printer_profile_sets_bed_nozzle_filament_and_gcode(tmp_path):
    import json

    from arapp.printing import load_profile

    path = tmp_path / "small.json"
    path.write_text(json.dumps({
        "format": "arapp-printer/1", "name": "Tiny", "bed": {"width": 60, "depth": 50, "height": 40},
        "nozzle_diameter": 0.6, "filament_diameter": 2.85,
        "start_gcode": "G28 ; tiny home\nG29 ; level", "end_gcode": "M84 ; tiny done"}))
    profile = load_profile(path)
    cube = trimesh.creation.box(extents=(30, 30, 3))
    r = slice_mesh(cube, SliceSettings(), profile)
    text = r.gcode
    assert "G28 ; tiny home\nG29 ; level" in text and text.rstrip().endswith("M84 ; tiny done")
    assert "line width = 0.675" in text
    layers = parse_gcode(text)
    area = np.pi * (2.85 / 2) ** 2
    m = next(m for m in layers[3].moves if m.extruding)
    length = np.hypot(m.end[0] - m.start[0], m.end[1] - m.start[1])
    assert m.e == pytest.approx(0.675 * 0.2 * length / area, abs=8e-5)
    xy = np.concatenate([l.segments(extruding=False).reshape(-1, 3) for l in layers])
    assert (xy[:, 0].min() + xy[:, 0].max()) / 2 == pytest.approx(30.0, abs=0.5)  # centred on this bed
    with pytest.raises(ModelDoesNotFitError, match="Tiny"):
        slice_mesh(trimesh.creation.box(extents=(50, 20, 5)), SliceSettings(), profile)  # 50 + 2 x 6.7 skirt > 60
