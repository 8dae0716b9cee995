"""NURBS geometry: curves, surfaces, constructions, tessellation, printable solids, models.

Public API: `NurbsSurface`, `NurbsCurve`, `load_model` (and `Model`, the
constructions in `construct`, and the errors, all `ValueError` subclasses).
"""

from .curve import NurbsCurve
from .errors import DenominatorError, DomainError, GeometryError, ModelError
from .surface import NurbsSurface

__all__ = [
    "NurbsCurve",
    "NurbsSurface",
    "load_model",
    "Model",
    "GeometryError",
    "DenominatorError",
    "DomainError",
    "ModelError",
]


def __getattr__(name):
    # The model module pulls in trimesh; load it on first use.
    if name in ("load_model", "Model"):
        from . import model

        return getattr(model, name)
    raise AttributeError(name)
