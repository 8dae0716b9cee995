"""Entering the bed anchor: touched corners and measured centre give the profile's bed_from_anchor."""

import json

import numpy as np
import pytest

from arapp.cli import main
from arapp.printing import load_profile
from arapp.printing.bed_anchor import bed_from_anchor_measured, bed_from_anchor_touched


def _corners_on_bed(T, L):
    # OpenCV corner order in the anchor frame (metres), taken in millimetres, mapped to the bed.
    c = 1000 * np.array([[-L / 2, L / 2, 0], [L / 2, L / 2, 0], [L / 2, -L / 2, 0], [-L / 2, -L / 2, 0]])
    return c @ T[:3, :3].T + T[:3, 3]


@pytest.mark.parametrize("angle", [0.0, 17.0, -120.0])
def test_touching_two_corners_recovers_the_marker(angle):
    truth = bed_from_anchor_measured((83.0, 141.5), angle)
    corners = _corners_on_bed(truth, 0.04)
    T = bed_from_anchor_touched(corners[3, :2], corners[2, :2], 0.04)
    assert np.allclose(T, truth, atol=1e-9)


def test_wrong_corners_are_refused():
    with pytest.raises(ValueError, match="apart but the marker's side is 40.0 mm"):
        bed_from_anchor_touched((10, 10), (60, 10), 0.04)


def test_cli_saves_a_valid_profile(tmp_path):
    path = tmp_path / "printer.json"
    assert main(["printer", "bed-anchor", "--printer", str(path), "--create", "--center", "30", "180"]) == 0
    profile = load_profile(path)
    assert np.allclose(profile.bed_from_anchor[:3, 3], [30, 180, 0])
    assert profile.bed_anchor.id == 42
    assert json.loads(path.read_text())["bed_anchor"]["kind"] == "aruco"
