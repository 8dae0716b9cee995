"""The G-code parser (arapp.printing.gcode.parse_gcode, read_stats, feature_kind) on hand-written files.

Every expected layer, move and number below is worked out by hand from
Marlin's G-code semantics (G90/G91, M82/M83, G92, G28) and the slicers'
comment conventions: a golden oracle, not the slicer's own output.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from arapp.printing.gcode import feature_kind, parse_gcode, read_stats

PRUSA = """\
G28 ; home
G1 Z5 F5000
G1 X1 Y1 E2 ; purge before the first layer: dropped
;LAYER_CHANGE
;Z:0.2
;TYPE:Skirt/Brim
G1 Z0.2
G1 X10 Y0 E1.0
;TYPE:External perimeter
G1 X10 Y10 E2.0
G1 E1.2 ; retraction: not a move
G0 X0 Y10
;TYPE:Gap fill
G01 X0 Y0 E2.5
;LAYER_CHANGE
;Z:0.4
G00 Z0.4
;TYPE:Overhang perimeter
G1 X5 Y0 E3.5
"""


def moves(layer):
    return [(m.kind, m.start, m.end, round(m.e, 6)) for m in layer.moves]


def test_prusa_layer_change_z_types_and_travel():
    layers = parse_gcode(PRUSA)
    assert [(l.index, l.z) for l in layers] == [(0, 0.2), (1, 0.4)]
    assert moves(layers[0]) == [
        ("travel", (1.0, 1.0, 5.0), (1.0, 1.0, 0.2), 0.0),
        ("travel", (1.0, 1.0, 0.2), (10.0, 0.0, 0.2), 0.0),  # E 2 -> 1: the filament went back
        ("perimeter", (10.0, 0.0, 0.2), (10.0, 10.0, 0.2), 1.0),
        ("travel", (10.0, 10.0, 0.2), (0.0, 10.0, 0.2), 0.0),
        ("infill", (0.0, 10.0, 0.2), (0.0, 0.0, 0.2), 1.3),
    ]
    assert moves(layers[1]) == [
        ("travel", (0.0, 0.0, 0.2), (0.0, 0.0, 0.4), 0.0),
        ("perimeter", (0.0, 0.0, 0.4), (5.0, 0.0, 0.4), 1.0),
    ]
    assert layers[0].filament_mm == pytest.approx(2.3)
    seg = layers[0].segments()
    assert seg.shape == (2, 2, 3) and seg.dtype == float
    assert np.allclose(seg[0], [[10, 0, 0.2], [10, 10, 0.2]])
    assert layers[0].segments(kinds=("infill",)).tolist() == [[[0, 10, 0.2], [0, 0, 0.2]]]
    assert layers[0].segments(kinds=("travel",), extruding=False).shape == (3, 2, 3)
    assert layers[0].segments(kinds=("travel",)).shape == (0, 2, 3)
    assert parse_gcode("").__len__() == 0 and layers[1].segments(kinds=("skirt",)).shape == (0, 2, 3)


def test_cura_layers_relative_modes_g92_and_homing():
    text = """\
;LAYER:0
;TYPE:WALL-OUTER
G1 X10 Y10 Z0.3 E1
G91
M83
G1 X5 E0.5
G1 Y-2 Z0.1 E0.25
G90
G92 X0 Y0 E0
G1 X1 E0.1
;LAYER:1
;TYPE:SKIN
M82
G1 Y3 E1.1
G28 X
G1 Y4 E1.2
G28
G1 X2 E1.4
G92
G1 X3 E0.2
;TYPE:SUPPORT
G1 X4 E0.3
"""
    layers = parse_gcode(text)
    assert [l.z for l in layers] == [0.3, 0.4]
    assert moves(layers[0]) == [
        ("perimeter", (0.0, 0.0, 0.0), (10.0, 10.0, 0.3), 1.0),
        ("perimeter", (10.0, 10.0, 0.3), (15.0, 10.0, 0.3), 0.5),
        ("perimeter", (15.0, 10.0, 0.3), (15.0, 8.0, 0.4), 0.25),
        ("perimeter", (0.0, 0.0, 0.4), (1.0, 0.0, 0.4), 0.1),
    ]
    assert moves(layers[1]) == [
        ("infill", (1.0, 0.0, 0.4), (1.0, 3.0, 0.4), 1.0),
        ("infill", (0.0, 3.0, 0.4), (0.0, 4.0, 0.4), 0.1),
        ("infill", (0.0, 0.0, 0.0), (2.0, 0.0, 0.0), 0.2),
        ("infill", (0.0, 0.0, 0.0), (3.0, 0.0, 0.0), 0.2),
        ("other", (3.0, 0.0, 0.0), (4.0, 0.0, 0.0), 0.1),
    ]


def test_without_layer_comments_a_new_layer_starts_where_extrusion_starts_at_a_new_z():
    text = """\
G1 Z0.2 X1 Y1 ; travel before any layer: dropped
G1 X2 Y1 E1
G1 X3 Y1 E2
G1 Z0.4
G1 X3 Y2 E2 ; no extrusion: travel
G1 X4 Y2 E3
G1 Z0.4 E3.5 ; extruding without an x/y move is not a layer start
"""
    layers = parse_gcode(text)
    assert [(l.index, l.z, len(l.moves)) for l in layers] == [(0, 0.2, 4), (1, 0.4, 1)]
    assert moves(layers[1])[0] == ("other", (3.0, 2.0, 0.4), (4.0, 2.0, 0.4), 1.0)
    assert moves(layers[0])[-1][0] == "travel"


def test_z_comment_before_or_after_the_layer_start_and_a_bad_one():
    text = ";Z:0.3\n;LAYER_CHANGE\nG1 X1 E1\n;LAYER_CHANGE\n;Z:zero\n;Z:0.6\nG1 X2 E2\n;LAYER_CHANGE\nG1 Z0.9 X3 E3\n"
    assert [l.z for l in parse_gcode(text)] == [0.3, 0.6, 0.9]
    lower = ";layer:0\nG1 X1 E1\n"
    assert parse_gcode(lower) and parse_gcode(lower)[0].z == 0.0  # no marker: a layer where extrusion starts


@pytest.mark.parametrize("name, kind", [
    ("Skirt/Brim", "skirt"), ("BRIM", "skirt"), ("skirt", "skirt"),
    ("External perimeter", "perimeter"), ("WALL-INNER", "perimeter"), ("Overhang", "perimeter"),
    ("Solid infill", "infill"), ("FILL", "infill"), ("SKIN", "infill"), ("Gap", "infill"),
    ("SUPPORT", "other"), ("Custom", "other"), ("  wall-outer  ", "perimeter"),
])
def test_feature_kind(name, kind):
    assert feature_kind(name) == kind


def test_read_stats():
    ours = "; filament used [mm] = 1234.5\n; filament used [g] = 3.7\n; estimated printing time (s) = 600\n"
    assert read_stats(ours) == {"filament_mm": 1234.5, "filament_g": 3.7, "print_time_s": 600.0}
    prusa = "; total filament used [g] = 12.5\n; estimated printing time (normal mode) = 1d 2h 3m 4s\n"
    assert read_stats(prusa) == {"filament_g": 12.5, "print_time_s": 86400 + 7200 + 180 + 4}
    assert read_stats("G28\n") == {}
    assert math.isclose(read_stats("; estimated printing time (normal mode) = 45s\n")["print_time_s"], 45.0)
