"""Words for a user who sees no model: what the tracker looks for, and how to show it (no Qt here).

`looking_for(anchors)` names the printed anchors ("ArUco id 40, DICT_4X4_50,
50 mm"); `lost_hint(anchors, camera)` adds where to hold them: the distance
range in which the pattern fits in the picture and its markers are still
large enough to read. Anchor lengths are metres (tracking.recording.schema.AnchorSpec);
the distances are rounded to centimetres for display.
"""

from __future__ import annotations


# A marker whose side spans fewer pixels than this is not read reliably (a 4x4 ArUco marker has 6 cells
# across with its border: ~4 px per cell; blur and perspective need the margin).
MIN_MARKER_PX = 25.0
# The whole pattern should fit within this fraction of the picture's shorter side.
FILL_FRACTION = 0.8


def anchor_phrase(spec) -> str:
    """One anchor as a user would check it against the printed sheet; lengths in mm (the kind's words)."""
    return spec.anchor_kind.describe(spec)


def looking_for(anchors) -> str:
    """'Looking for ArUco id 40, DICT_4X4_50, 50 mm' (several anchors joined with 'or')."""
    if not anchors:
        return "No anchor is set up (Tracking > Anchors...)"
    return "Looking for " + " or ".join(anchor_phrase(a) for a in anchors)


def _smallest_and_extent(spec) -> tuple[float, float]:
    """(side of the smallest marker that must be read, side of the whole pattern), metres."""
    return spec.anchor_kind.extent(spec)


def distance_range_m(spec, camera) -> tuple[float, float]:
    """(nearest, farthest) camera distance in metres at which `spec` fits in `camera`'s picture (within
    FILL_FRACTION of its shorter side) and its markers span at least MIN_MARKER_PX pixels, seen face-on."""
    small, extent = _smallest_and_extent(spec)
    f = min(camera.fx, camera.fy)
    near = f * extent / (FILL_FRACTION * min(camera.width, camera.height))
    far = f * small / MIN_MARKER_PX
    return near, far


def _cm(m: float) -> str:
    return f"{m:.1f} m" if m >= 1.0 else f"{max(1, round(m * 100))} cm"


def lost_hint(anchors, camera=None, estimated: bool = False) -> str:
    """Two lines for the view when nothing is tracked: what is looked for, and how to show it."""
    first = looking_for(anchors)
    if not anchors:
        return first
    how = "Hold the printed sheet flat, in good light and without glare"
    if camera is not None:
        near, far = distance_range_m(anchors[0], camera)
        if far > near:
            how += f", {_cm(near)} to {_cm(far)} from the camera"
        else:
            how += ", closer to the camera: its markers are too small for this picture"
    how += ". No sheet? Print one: Marker sheets... in the Tracking panel."
    if estimated:
        how += " The camera is uncalibrated: sizes are approximate."
    return f"{first}.\n{how}"


AMBIGUOUS_HINT = ("The marker is seen head-on: its tilt is uncertain. Tilt the camera a little (or move it sideways) "
                  "over the desk around the marker until this goes.")


def ambiguous_hint() -> str:
    """The line for the view while the pose rests on a lone marker seen nearly head-on whose two possible tilts
    the desk around it has not yet told apart (`TrackResult.ambiguous`, issue 25.4)."""
    return AMBIGUOUS_HINT
