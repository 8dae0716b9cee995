"""Undo / redo of control-point edits and placement in the app model (arapp.app.history), without Qt or an engine.

Oracles: the model file itself (the control point and weight read from the JSON
before any edit) and the placements the test set; the rule written here: undo
walks back one user step at a time, a whole drag is one step, redo walks forward,
a new change after undo drops the redo steps, loading a model clears the history.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from arapp.app.session import Session, read_model
from arapp.geometry.placement import Placement

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "rational_5x5.json"


def _session():
    s = Session(lambda *a, **k: None)  # no source opened: no engine is made
    model, mesh_lines = read_model(str(MODEL))
    s.set_model(model, mesh_lines, str(MODEL))
    return s


def _file_point(i, j):
    data = json.loads(MODEL.read_text())
    surf = data["surfaces"][0]
    return np.array(surf["control_points"][i][j], float), float(np.array(surf["weights"])[i][j])


def test_undo_redo_control_point_edit():
    s = _session()
    xyz0, w0 = _file_point(1, 1)
    assert np.allclose(s.model.surfaces[0].control_points[1, 1], xyz0)
    s.edit_control_point(0, 1, 1, xyz0 + [0, 0, 1.5], 2.0 * w0)
    assert np.allclose(s.model.surfaces[0].control_points[1, 1], xyz0 + [0, 0, 1.5])
    assert s.history.can_undo and not s.history.can_redo
    assert s.history.undo()
    assert np.allclose(s.model.surfaces[0].control_points[1, 1], xyz0)
    assert np.isclose(s.model.surfaces[0].weights[1, 1], w0)
    assert s.edits == {}
    assert not s.history.can_undo and s.history.can_redo
    assert s.history.redo()
    assert np.allclose(s.model.surfaces[0].control_points[1, 1], xyz0 + [0, 0, 1.5])
    assert np.isclose(s.model.surfaces[0].weights[1, 1], 2.0 * w0)
    assert not s.history.redo()


def test_undo_placement_steps_and_new_change_drops_redo():
    s = _session()
    p0 = s.placement
    p1, p2, p3 = (Placement(30.0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)), Placement(40.0, (1.0, 2.0, 0.0), (0.0, 0.0, 15.0)),
                  Placement(60.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
    s.set_placement(p1)
    s.set_placement(p2)
    s.history.undo()
    assert s.placement == p1
    s.history.undo()
    assert s.placement == p0
    assert not s.history.undo()
    s.history.redo()
    assert s.placement == p1
    s.set_placement(p3)  # a new change: the undone p2 can no longer be redone
    assert not s.history.can_redo
    s.history.undo()
    assert s.placement == p1


def test_edits_and_placement_interleaved():
    s = _session()
    xyz0, w0 = _file_point(2, 3)
    p0 = s.placement
    s.edit_control_point(0, 2, 3, xyz0 + [0.5, 0, 0], w0)
    s.set_placement(Placement(25.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
    s.history.undo()
    assert s.placement == p0 and (0, 2, 3) in s.edits
    s.history.undo()
    assert s.edits == {} and np.allclose(s.model.surfaces[0].control_points[2, 3], xyz0)


def test_a_drag_is_one_step():
    s = _session()
    p0 = s.placement
    s._drag = ("move", (0.0, 0.0), p0, np.eye(4))  # what drag_start sets when the pointer grabs the paper
    for x in (1.0, 2.0, 3.0, 4.0):
        s.set_placement(Placement(p0.size_mm, (x, 0.0, 0.0), p0.rotation_deg))
    s.drag_end()
    s.set_placement(Placement(p0.size_mm, (9.0, 0.0, 0.0), p0.rotation_deg))
    s.history.undo()
    assert s.placement.offset[0] == 4.0
    s.history.undo()
    assert s.placement == p0


def test_loading_a_model_clears_the_history():
    s = _session()
    s.set_placement(Placement(33.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
    assert s.history.can_undo
    model, mesh_lines = read_model(str(MODEL))
    s.set_model(model, mesh_lines, str(MODEL))
    assert not s.history.can_undo and not s.history.can_redo
