"""Printing: printer profiles, materials, export of the placed model, slicing and G-code.

The public names below are imported lazily, so `import arapp.printing` (for the
printer links) stays light.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "load_profile": ".profile", "PrinterProfile": ".profile", "ProfileError": ".profile",
    "MATERIALS": ".materials", "Material": ".materials", "get_material": ".materials",
    "placed_solid": ".export", "write_stl": ".export", "write_3mf": ".export", "load_mesh": ".export",
    "ModelDoesNotFitError": ".export",
    "slice_mesh": ".slicer", "SliceSettings": ".slicer", "SliceResult": ".slicer", "SliceCancelled": ".slicer",
    "parse_gcode": ".gcode", "read_stats": ".gcode",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
