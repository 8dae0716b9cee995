"""The model as displayed, exported for printing: mm, +Z out of the paper, on the bed, watertight; STL and 3MF."""

import dataclasses
import struct
import zipfile

import numpy as np
import pytest
import trimesh

from arapp.printing import load_profile, placed_solid
from arapp.printing.export import ModelDoesNotFitError, fit_on_bed, thicken, write_3mf, write_stl


def test_trimesh_is_dropped_and_centred_on_the_bed():
    mesh = trimesh.creation.box(extents=(30, 20, 10))
    mesh.apply_translation((-50, 7, 33))
    out = placed_solid(mesh)
    lo, hi = out.bounds
    assert lo[2] == pytest.approx(0.0, abs=1e-9)
    assert (lo[:2] + hi[:2]) / 2 == pytest.approx([125.0, 105.0])
    assert out.extents == pytest.approx([30, 20, 10])
    assert out.is_watertight and out.volume == pytest.approx(6000.0)


def test_placement_scales_and_turns_about_the_anchor_normal():
    from arapp.geometry.placement import Placement

    mesh = trimesh.creation.box(extents=(2.0, 1.0, 0.5))  # model units
    out = placed_solid(mesh, Placement.from_any({"size_mm": 80.0, "rotation_deg": 90.0}))
    # largest horizontal extent becomes 80 mm; a quarter turn about +Z swaps x and y
    assert out.extents == pytest.approx([40.0, 80.0, 20.0])
    assert out.bounds[0, 2] == pytest.approx(0.0)


def test_open_patch_is_thickened_into_a_solid():
    # a flat disc (open surface) of radius 20 mm, area pi r^2 (up to the polygon)
    disc = trimesh.creation.cylinder(radius=20, height=1, sections=64)
    top = disc.faces[disc.face_normals[:, 2] > 0.9]
    patch = trimesh.Trimesh(disc.vertices, top)
    patch.remove_unreferenced_vertices()
    assert not patch.is_watertight
    out = placed_solid(patch, thickness_mm=2.0)
    assert out.is_watertight
    assert out.volume == pytest.approx(patch.area * 2.0, rel=1e-6)
    assert out.extents[2] == pytest.approx(2.0)
    solid = thicken(patch, 1.0)
    assert solid.is_watertight and solid.volume > 0


def test_geometry_model_keeps_its_displayed_size_and_up(repo_root):
    from arapp.geometry import load_model

    model = load_model(repo_root / "models" / "torus.json")
    out = placed_solid(model, dataclasses.replace(model.placement, size_mm=60.0))
    assert out.is_watertight and out.volume > 0
    assert out.bounds[0, 2] == pytest.approx(0.0, abs=1e-6)
    # as displayed on the marker: the model's placement map (model units -> marker mm, +Z out of the paper)
    M = model.placement_matrix("mm")
    disp = model.mesh().copy()
    disp.apply_transform(M)
    scale = 60.0 / model.placement.size_mm
    assert out.extents == pytest.approx(disp.extents * scale, rel=0.02)
    assert (out.bounds[0, :2] + out.bounds[1, :2]) / 2 == pytest.approx(load_profile().bed_center, abs=1e-6)


def test_binary_stl_and_3mf_round_trip(tmp_path):
    mesh = placed_solid(trimesh.creation.icosphere(subdivisions=2, radius=10))
    stl = write_stl(mesh, tmp_path / "part.stl")
    data = stl.read_bytes()
    (count,) = struct.unpack("<I", data[80:84])
    assert count == len(mesh.faces) and len(data) == 84 + 50 * count  # binary STL layout
    tri = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    assert np.allclose(tri["v"].reshape(-1, 3).min(axis=0), mesh.bounds[0], atol=1e-4)
    back = trimesh.load(stl)
    assert back.volume == pytest.approx(mesh.volume, rel=1e-5)
    three = write_3mf(mesh, tmp_path / "part.3mf")
    with zipfile.ZipFile(three) as z:
        xml = z.read("3D/3dmodel.model").decode()
    assert 'unit="millimeter"' in xml
    back = trimesh.load(three, force="mesh")
    assert back.volume == pytest.approx(mesh.volume, rel=1e-5)


def test_model_larger_than_the_bed_is_refused_or_scaled():
    profile = load_profile()
    big = trimesh.creation.box(extents=(300, 100, 50))
    with pytest.raises(ModelDoesNotFitError, match=r"300\.0 x 100\.0 x 50\.0 mm.*250 x 210 x 210.*--scale-to-fit"):
        fit_on_bed(big, profile, margin=5.0)
    fitted, scale = fit_on_bed(big, profile, margin=5.0, scale_to_fit=True)
    assert scale < 1 and fitted.extents[0] <= 240.0 and fitted.bounds[0, 0] >= 5.0
    assert fitted.bounds[1, 0] <= 245.0


def test_3mf_units_are_honoured(tmp_path):
    from arapp.printing.export import load_mesh

    write_3mf(trimesh.creation.box(extents=(10, 10, 4)), tmp_path / "mm.3mf")
    with zipfile.ZipFile(tmp_path / "mm.3mf") as src, zipfile.ZipFile(tmp_path / "cm.3mf", "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "3D/3dmodel.model":
                data = data.replace(b'unit="millimeter"', b'unit="centimeter"')
            dst.writestr(name, data)
    assert load_mesh(tmp_path / "mm.3mf").extents == pytest.approx([10, 10, 4])
    assert load_mesh(tmp_path / "cm.3mf").extents == pytest.approx([100, 100, 40])
