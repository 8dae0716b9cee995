"""Every bad input raises a ValueError subclass that names the field and the problem."""

import numpy as np
import pytest

from arapp.geometry import DenominatorError, DomainError, GeometryError, NurbsCurve, NurbsSurface

from test_geometry_eval import EXAMPLE_KU, EXAMPLE_KV, EXAMPLE_P, EXAMPLE_W

P3 = np.zeros((3, 3, 3)) + np.arange(3)[:, None, None]
K3 = [0, 0, 0, 1, 1, 1]


@pytest.mark.parametrize("kwargs, field, message", [
    (dict(knots_u=[0, 0, 1, 0.5, 1, 1]), "knots_u", "must be non-decreasing, but 0.5 follows 1 at index 3"),
    (dict(knots_u=[0, 0, 0, 1, 1], degree_u=2), "knots_u", "expected 6 knots for 3 control points of degree 2"),
    (dict(knots_u=[0, 0, 0, 1, 1, 1], degree_u=3), "knots_u", "expected 7 knots for 3 control points of degree 3"),
    (dict(knots_u=[0, 0, 1, 1]), "knots_u", "imply degree 0"),
    (dict(knots_u=[0, 0, 0, 1, 1, 1], degree_u=1.5), "degree_u", "integer"),
    (dict(knots_u=[0, 0, 0, 0, 1, 1, 1, 1], degree_u=None, control_points=np.zeros((4, 3, 3)) + 1),
     None, None),  # a valid cubic: sanity row
    (dict(knots_u=[0, 0, 0, 0, 0, 1], control_points=np.zeros((3, 3, 3))), "knots_u", "repeated 5 times"),
    (dict(knots_u=[1, 1, 1, 1, 1, 1]), "knots_u", "repeated 6 times"),
    (dict(knots_u=[0, 0, 0, float("nan"), 1, 1]), "knots_u[3]", "finite"),
    (dict(weights=np.ones((3, 2))), "weights", "must have shape (3, 3)"),
    (dict(weights=[[1, 1, 1], [1, np.inf, 1], [1, 1, 1]]), "weights[1][1]", "finite"),
    (dict(control_points=np.zeros((3, 3, 2))), "control_points", "(n_u >= 2, n_v >= 2, 3)"),
    (dict(control_points=[[[0, 0, 0]], [[0, 0]]]), "control_points[1]", "rows must have equal lengths"),
    (dict(control_points=[[[0, 0, 0]], [[0, 0, None]]]), "control_points[1][0][2]", "must be a number, got None"),
    (dict(knots_u=[0, 0, 0, True, 1, 1]), "knots_u[3]", "must be a number, got True"),
    (dict(control_points=np.full((3, 3, 3), np.nan)), "control_points[0][0][0]", "finite"),
    (dict(weights=np.zeros((3, 3))), "weights", "all weights are zero"),
])
def test_surface_input_errors(kwargs, field, message):
    args = dict(control_points=P3, knots_u=K3, knots_v=K3)
    args.update(kwargs)
    if field is None:
        NurbsSurface(**args)
        return
    with pytest.raises(GeometryError) as info:
        NurbsSurface(**args)
    assert isinstance(info.value, ValueError)
    assert info.value.field == field
    assert message in info.value.problem
    assert str(info.value).startswith(field + ": ")


def test_empty_domain():
    with pytest.raises(GeometryError, match="empty domain"):
        NurbsSurface(P3, knots_u=[0, 0, 1, 1, 1, 2], knots_v=K3, degree_u=2)


def test_vanishing_denominator_is_reported_not_returned():
    w = np.array(EXAMPLE_W, float)
    w[2, 0] = -4.0  # the weighted sum turns negative near that corner
    with pytest.raises(DenominatorError) as info:
        NurbsSurface(EXAMPLE_P, w, EXAMPLE_KU, EXAMPLE_KV)
    assert info.value.field == "weights" and "vanishes inside the domain" in str(info.value)
    assert isinstance(info.value, ValueError)
    with pytest.raises(DenominatorError, match="vanishes"):
        NurbsCurve([[0, 0], [1, 1], [2, 0]], [1, -3, 1])
    # Zero weights are legal while the sum stays non-zero.
    c = NurbsCurve([[0, 0], [1, 1], [2, 0]], [1, 0, 1])
    assert np.allclose(c.evaluate(0.5), [1, 0])


def test_parameters_outside_the_domain():
    s = NurbsSurface(EXAMPLE_P, EXAMPLE_W, EXAMPLE_KU, EXAMPLE_KV)
    with pytest.raises(DomainError) as info:
        s.evaluate(1.9, 0.5)
    assert info.value.field == "u" and "outside the domain [2, 5]" in str(info.value)
    with pytest.raises(DomainError, match=r"\[0, 2\]"):
        s.normal(3.0, 2.5)
    with pytest.raises(GeometryError):
        s.tessellate(count=1)


def test_a_file_that_is_no_model_is_named_as_such(tmp_path):
    """A video (or any file neither a JSON model nor a mesh) handed where a model goes: one line naming the
    file and the kinds that are models, not a JSON parse error."""
    from arapp.geometry.model import ModelError, load_model

    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"\x00\x00\x00\x18ftypmp42")
    with pytest.raises(ModelError) as info:
        load_model(clip)
    text = str(info.value)
    assert str(clip) in text and "not a model file (.mp4)" in text and ".json" in text and ".stl" in text
    assert "\n" not in text
