"""A sliced layer's extrusions: the data the slicer (arapp.printing.slicer) makes and the G-code writer
(arapp.printing.gcode) writes, in their own module so neither package imports the other's inside. Millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Feature kinds, in G-code `;TYPE:` names.
KIND_TYPES = {
    "skirt": "SKIRT",
    "external_perimeter": "EXTERNAL_PERIMETER",
    "perimeter": "PERIMETER",
    "solid_infill": "SOLID_INFILL",
    "sparse_infill": "SPARSE_INFILL",
}


@dataclass
class ToolPath:
    """One continuous extrusion: `points` (N, 2) in mm at the layer's z; closed loops repeat the first point."""

    kind: str
    points: np.ndarray
    width: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


@dataclass
class LayerToolpaths:
    """The extrusions of one layer in print order; `z` is the layer's top (nozzle height), `height` its thickness."""

    index: int
    z: float
    height: float
    paths: list[ToolPath] = field(default_factory=list)
