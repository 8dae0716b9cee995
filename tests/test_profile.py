"""Printer profiles (docs/printer-profile.md): the generic printer, defaults, and errors that name the key."""

import json

import numpy as np
import pytest

from arapp.printing import load_profile
from arapp.printing.profile import ProfileError


def _write(tmp_path, data, name="p.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def test_generic_profile_is_the_contract_printer():
    p = load_profile()
    assert (p.bed.width, p.bed.depth, p.bed.height) == (250.0, 210.0, 210.0)
    assert p.nozzle_diameter == 0.4 and p.filament_diameter == 1.75 and p.flavor == "marlin"
    assert p.link.port == "/dev/ttyUSB0" and p.link.baud == 115200
    assert p.bed_anchor.kind == "aruco" and p.bed_anchor.id == 42 and p.bed_anchor.length == 0.04
    # the contract's example: the marker's centre lies at bed (30, 180); a point 1 cm to its
    # right (anchor frame, metres) lies at bed (40, 180) mm.
    p_anchor_m = np.array([0.01, 0.0, 0.0])
    bed = p.bed_from_anchor[:3, :3] @ (1000 * p_anchor_m) + p.bed_from_anchor[:3, 3]
    assert np.allclose(bed, [40.0, 180.0, 0.0])
    assert load_profile("generic").name == p.name


def test_partial_profile_takes_generic_values(tmp_path):
    path = _write(tmp_path, {"format": "arapp-printer/1", "name": "Mini", "bed": {"width": 180, "depth": 180, "height": 180},
                             "nozzle_diameter": 0.6, "link": {"baud": 250000}})
    p = load_profile(path)
    assert p.name == "Mini" and p.bed.width == 180.0 and p.nozzle_diameter == 0.6
    assert p.filament_diameter == 1.75 and p.start_gcode.startswith("G28")
    assert p.link.baud == 250000 and p.link.port == "/dev/ttyUSB0"
    assert p.bed_anchor.id == 42


@pytest.mark.parametrize("change, key", [
    ({"colour": "red"}, "colour"),
    ({"nozzle_diameter": "0.4"}, "nozzle_diameter"),
    ({"bed": {"width": 200, "depth": 200, "height": 200, "radius": 3}}, "bed.radius"),
    ({"bed": {"width": 200, "depth": "deep", "height": 200}}, "bed.depth"),
    ({"bed": {"width": 200, "depth": 200}}, "bed.height"),
    ({"link": {"baud": 115200.5}}, "link.baud"),
    ({"link": {"speed": 3}}, "link.speed"),
    ({"start_gcode": ["G28"]}, "start_gcode"),
    ({"bed_anchor": {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 1, "length": -0.04}}, "bed_anchor.length"),
    ({"bed_anchor": {"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 1, "length": 0.04,
                     "bed_from_anchor": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}},
     "bed_anchor.bed_from_anchor"),
])
def test_unknown_key_or_wrong_type_names_the_key(tmp_path, change, key):
    data = {"format": "arapp-printer/1", "name": "X", "bed": {"width": 200, "depth": 200, "height": 200}}
    data.update(change)
    with pytest.raises(ProfileError, match=key.replace(".", r"\.")):
        load_profile(_write(tmp_path, data))


def test_required_keys_and_missing_file(tmp_path):
    with pytest.raises(ProfileError, match="bed"):
        load_profile(_write(tmp_path, {"format": "arapp-printer/1", "name": "X"}))
    with pytest.raises(ProfileError, match="format"):
        load_profile(_write(tmp_path, {"format": "cura/1", "name": "X", "bed": {"width": 1, "depth": 1, "height": 1}}))
    with pytest.raises(ProfileError, match="not found"):
        load_profile(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    with pytest.raises(ProfileError, match="line 1"):
        load_profile(bad)


def test_temperature_limits_come_from_the_profile(tmp_path):
    from arapp.printing.profile import temperature_limit

    generic = load_profile()
    assert (temperature_limit(generic, "hotend"), temperature_limit(generic, "bed")) == (300.0, 120.0)
    path = tmp_path / "hot.json"
    path.write_text(json.dumps({"format": "arapp-printer/1", "name": "hot", "bed": {"width": 200, "depth": 200,
                                "height": 200}, "max_hotend_temperature": 285, "max_bed_temperature": 110}))
    hot = load_profile(path)
    assert (temperature_limit(hot, "hotend"), temperature_limit(hot, "bed")) == (285.0, 110.0)
    with pytest.raises(ValueError, match="heater"):
        temperature_limit(hot, "chamber")


@pytest.mark.parametrize("kwargs, flag", [({"baud": 0}, "--baud"), ({"baud": 115200.5}, "--baud"),
                                          ({"window": 0}, "--window"), ({"window": 64}, "--window"),
                                          ({"timeout": -1}, "--timeout"), ({"timeout": float("nan")}, "--timeout")])
def test_link_values_out_of_range_name_the_flag(kwargs, flag):
    from arapp.printing.profile import check_link_values

    check_link_values(baud=250000, window=4, timeout=10.0)
    with pytest.raises(ValueError, match=flag):
        check_link_values(**kwargs)
