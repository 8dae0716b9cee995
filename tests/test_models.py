"""The model library, JSON validation, mesh files and the `arapp model` command."""

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from arapp.cli import main
from arapp.geometry import ModelError, NurbsSurface, load_model

from test_geometry_eval import EXAMPLE_KU, EXAMPLE_KV, EXAMPLE_P, EXAMPLE_W

MODELS = Path(__file__).resolve().parents[1] / "models"
LIBRARY = sorted(MODELS.glob("*.json"))


def test_library_holds_the_required_models():
    names = {p.stem for p in LIBRARY}
    assert {"rational_5x5", "hyperbolic_paraboloid", "sphere", "torus", "vase", "hull", "extrusion", "ruled"} <= names


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: p.stem)
def test_library_model_loads_tessellates_and_prints(path):
    model = load_model(path)
    assert model.surfaces and model.units in ("mm", "cm", "m", "in") and len(model.color) == 4
    mesh = model.mesh()
    assert len(mesh.faces) > 50 and mesh.is_winding_consistent
    assert model.lines() and all(line.shape[1] == 3 for line in model.lines())
    solid = model.printable()
    assert solid.is_watertight and solid.is_winding_consistent and solid.volume > 0
    # Sized for a 4-5 cm marker, standing on it.
    assert 40 <= model.placement.size_mm <= 60
    assert solid.bounds[0][2] == pytest.approx(-0.0, abs=3.0)
    assert 35 <= solid.extents.max() <= 65


def test_rational_example_file_is_the_domain_example():
    s = load_model(MODELS / "rational_5x5.json").surfaces[0]
    ref = NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)
    u, v = np.linspace(2, 5, 7), np.linspace(0, 2, 5)
    assert np.array_equal(s.evaluate_grid(u, v), ref.evaluate_grid(u, v))


def test_hyperbolic_paraboloid_is_z_equals_xy():
    s = load_model(MODELS / "hyperbolic_paraboloid.json").surfaces[0]
    u, v = np.random.default_rng(31).uniform(0, 1, (2, 200))
    p = s.evaluate(u, v)
    assert np.allclose(p, np.column_stack([u + v, u - v, u * u - v * v]), atol=1e-14)
    assert np.allclose(p[:, 2], p[:, 0] * p[:, 1], atol=1e-14)


def test_model_mesh_keeps_analytic_normals():
    model = load_model(MODELS / "sphere.json")
    for mesh in (model.mesh(), model.mesh()):  # second call comes from the cache
        assert np.abs(mesh.vertex_normals - mesh.vertices / 20).max() < 1e-6
    assert model.mesh(tolerance=0.5).faces.shape[0] < model.mesh().faces.shape[0]


def test_placement_matrix_sizes_and_stands_the_model():
    model = load_model(MODELS / "torus.json")
    m = model.placement_matrix()
    pts = trimesh.transform_points(model.mesh().vertices, m)
    assert np.ptp(pts, axis=0).max() == pytest.approx(50.0, rel=1e-3)
    assert pts[:, 2].min() == pytest.approx(0.0, abs=0.05)
    assert np.allclose(model.placement_matrix("m"), np.diag([1e-3, 1e-3, 1e-3, 1]) @ m)


def write(tmp_path, data) -> Path:
    p = tmp_path / "m.json"
    p.write_text(data if isinstance(data, str) else json.dumps(data))
    return p


def base(**surface):
    s = {"control_points": P, "knots_u": [0, 0, 0, 1, 1, 1], "knots_v": [0, 0, 0, 1, 1, 1]}
    s.update(surface)
    return {"version": 1, "units": "mm", "surfaces": [s]}


P = [[[i, j, 0] for j in range(3)] for i in range(3)]


@pytest.mark.parametrize("data, message", [
    (base(knots_u=[0, 0, 1, 0.5, 1, 1]), "surfaces[0].knots_u: must be non-decreasing, but 0.5 follows 1 at index 3"),
    (base(knots_u=[0, 1, 0.5, 1, 1, 1]), "surfaces[0].knots_u: must be non-decreasing, but 0.5 follows 1 at index 2"),
    (base(knots_v=[0, 0, 1, 1]), "surfaces[0].knots_v: 4 knots for 3 control points imply degree 0"),
    (base(degree_u=3), "surfaces[0].knots_u: expected 7 knots for 3 control points of degree 3"),
    (base(weights=[[1, 1], [1, 1]]), "surfaces[0].weights: must have shape (3, 3)"),
    (base(control_points=[[[0, 0, 0], [1, 0, 0]], [[0, 1, 0]]]),
     "surfaces[0].control_points[1]: has shape (1, 3), unlike the first entry's (2, 3)"),
    (base(knots_u=[0, 0, 0, "1", 1, 1]), "surfaces[0].knots_u[3]: must be a number, got '1'"),
    ('{"version": 1, "surfaces": [{"control_points": [[[0,0,NaN]]]}]}', "surfaces[0].control_points[0][0][2]: must be a finite number"),
    (base(weights=[[1, 1, 1], [1, -5, 1], [1, 1, 1]]), "surfaces[0].weights: the denominator sum(w N N) vanishes"),
    (base(knot_u=[0, 1]), "surfaces[0].knot_u: unknown key"),
    ({"version": 2, "surfaces": []}, "version: this arapp reads version 1, got 2"),
    ({"surfaces": []}, "version: is required but missing"),
    ({"version": 1, "surfaces": []}, "surfaces: must be a non-empty list"),
    ({"version": 1, "units": "furlong", "surfaces": [1]}, "units: must be one of"),
    ({"version": 1, "color": [1, 2, 0], "surfaces": [1]}, "color[1]: must be between 0 and 1"),
    ({"version": 1, "placement": {"size_mm": -4}, "surfaces": [1]}, "placement.size_mm: must be positive"),
    ({"version": 1, "surfaces": [{"type": "blob"}]}, "surfaces[0].type: unknown surface type"),
    ({"version": 1, "surfaces": [{"type": "sphere"}]}, "surfaces[0].radius: is required but missing"),
    ({"version": 1, "surfaces": [{"type": "revolve", "profile": {"control_points": [[1, 0], [-2, 1]]}}]},
     "surfaces[0].profile.control_points[1]: radius must be >= 0"),
    ({"version": 1, "surfaces": [{"type": "loft", "curves": [{"control_points": [[0, 0], [1, 1]]},
                                                             {"control_points": [[0, 0, 1], [1, 1]]}]}]},
     "surfaces[0].curves[1].control_points[1]: has shape (2,), unlike the first entry's (3,)"),
    ({"version": 1, "surfaces": [{"type": "ruled", "curves": [{"control_points": [[0, 0], [1, 1]]}]}]},
     "surfaces[0].curves: a ruled surface needs exactly 2 curves"),
    ({"version": 1, "surfaces": [{"type": "extrude", "direction": [0, 0, 1],
                                  "curve": {"control_points": [[0, 0], [1, 1], [2, 0]], "knots": [0, 0, 2, 1, 1]}}]},
     "surfaces[0].curve.knots: must be non-decreasing, but 1 follows 2 at index 3"),
    ("{not json", "invalid JSON at line 1 column 2"),
])
def test_load_errors_name_the_field(tmp_path, data, message):
    with pytest.raises(ModelError) as info:
        load_model(write(tmp_path, data))
    assert isinstance(info.value, ValueError)
    assert message in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(ModelError, match="no such file"):
        load_model(tmp_path / "nope.json")


def test_mesh_files_load_as_models(tmp_path):
    out = tmp_path / "sphere.stl"
    load_model(MODELS / "sphere.json").export(out)
    model = load_model(out)
    assert model.surfaces == [] and model.lines() == []
    assert model.mesh().volume == pytest.approx(4 / 3 * np.pi * 20**3, rel=0.01)
    assert model.placement.size_mm == pytest.approx(40.0, rel=1e-3)
    again = model.printable(size_mm=20)
    assert again.is_watertight and again.extents.max() == pytest.approx(20.0)
    (tmp_path / "bad.stl").write_bytes(b"solid nothing\nendsolid\n")
    with pytest.raises(ModelError):
        load_model(tmp_path / "bad.stl")


def test_cli_info(capsys):
    assert main(["model", "info", str(MODELS / "rational_5x5.json")]) == 0
    out = capsys.readouterr().out
    assert "degree (2, 2)" in out and "domain u [2, 5] v [0, 2]" in out
    assert "bounding box" in out and "triangles at default quality" in out


@pytest.mark.parametrize("ext", ["stl", "obj", "ply", "3mf", "glb"])
def test_cli_export_formats_are_watertight(tmp_path, ext, capsys):
    out = tmp_path / f"vase.{ext}"
    assert main(["model", "export", str(MODELS / "vase.json"), "-o", str(out), "--size", "30",
                 "--thickness", "1.5", "--tolerance", "0.1"]) == 0
    assert "watertight True" in capsys.readouterr().out
    mesh = trimesh.load(out, force="mesh")
    mesh.merge_vertices()
    assert mesh.is_watertight and mesh.volume > 0
    # The surface is scaled to 30 mm; the 1.5 mm wall may stick out at the rim, never more.
    assert 30.0 <= mesh.extents.max() <= 31.5


def test_cli_errors_exit_nonzero_without_traceback(tmp_path, capsys):
    bad = write(tmp_path, base(knots_u=[0, 1, 0.5, 1, 1, 1]))
    assert main(["model", "info", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "surfaces[0].knots_u: must be non-decreasing, but 0.5 follows 1 at index 2" in err
    assert "Traceback" not in err
    assert main(["model", "export", str(MODELS / "sphere.json"), "-o", str(tmp_path / "x.step")]) == 2
    assert "unsupported format" in capsys.readouterr().err
    assert main(["model", "export", str(MODELS / "sphere.json"), "-o", str(tmp_path / "x.stl"), "--size", "-3"]) == 2
    assert "size: must be a positive" in capsys.readouterr().err


def test_placement_accepts_a_single_turn_about_the_marker_normal():
    from arapp.geometry.placement import Placement

    p = Placement(size_mm=30, rotation_deg=90)
    assert p.rotation_deg == (0.0, 0.0, 90.0)
    assert np.allclose(p.rotation() @ [1, 0, 0], [0, 1, 0])
    assert Placement.from_any({"size_mm": 20}, p).size_mm == 20.0


def test_a_bare_name_is_the_library_model_of_that_name(tmp_path, monkeypatch, capsys):
    # from a folder without models/ (a user's own), `vase` is the checkout's models/vase.json; a path that
    # exists wins over the library, and a name the library lacks lists the names it has
    monkeypatch.chdir(tmp_path)
    by_name, by_file = load_model("vase"), load_model(MODELS / "vase.json")
    assert by_name.name == by_file.name and len(by_name.surfaces) == len(by_file.surfaces)
    np.testing.assert_array_equal(by_name.surfaces[0].control_points, by_file.surfaces[0].control_points)
    (tmp_path / "vase").write_text("not a model")
    with pytest.raises(ModelError, match="not a model file"):
        load_model("vase")
    with pytest.raises(ModelError, match=r"vasee: no such file \(the library's models, by name: .*\bvase\b"):
        load_model("vasee")
    assert main(["model", "info", "torus"]) == 0
    assert f"file: {MODELS / 'torus.json'}" in capsys.readouterr().out
