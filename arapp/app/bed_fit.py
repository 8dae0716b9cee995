"""Does the part fit the printer, before slicing: its real size against the bed, and the size that fits. No Qt.

The printable solid's extents (mm, x y z as it stands on the bed) are compared
with the profile's build volume less the room its skirt takes (the rule the
slicer applies, arapp.printing.slicer.skirt_margin), so a part too big is
caught in the print dialog with a "scale to fit" offer instead of failing
after slicing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arapp.printing.slicer import skirt_margin


@dataclass(frozen=True)
class BedFit:
    """fits: whether the part fits; scale: the factor that makes it fit (1.0 when it does, < 1 else);
    text: one sentence for the user ('' when it fits)."""

    fits: bool
    scale: float
    text: str


def size_text(extents) -> str:
    """'32.0 x 32.0 x 50.7 mm': a solid's real size, width x depth x height."""
    x, y, z = (float(v) for v in extents)
    return f"{x:.1f} x {y:.1f} x {z:.1f} mm"


def bed_fit(extents, profile, settings=None) -> BedFit:
    """Whether a solid of `extents` (mm) fits the bed of `profile` (arapp.printing PrinterProfile) with the
    skirt of `settings` (SliceSettings; none: no skirt)."""
    bed = profile.bed
    margin = skirt_margin(settings, settings.width(profile.nozzle_diameter)) if settings is not None else 0.0
    room = np.array([bed.width - 2 * margin, bed.depth - 2 * margin, bed.height], float)
    ext = np.asarray(extents, float)
    if np.all(ext <= room + 1e-9):
        return BedFit(True, 1.0, "")
    scale = float(np.min(room / np.maximum(ext, 1e-12))) * 0.999 if np.all(room > 0) else 0.0
    skirt = f", {margin:.0f} mm kept free around it for the skirt" if margin > 0 else ""
    return BedFit(False, scale, f"The part ({size_text(ext)}) is larger than the bed of {profile.name} "
                                f"({bed.width:g} x {bed.depth:g} x {bed.height:g} mm{skirt}).")
