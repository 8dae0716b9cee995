"""Errors raised by the geometry package; all are `ValueError` subclasses.

Each carries `field` (where the problem is, e.g. ``surfaces[0].knots_u``) and
`problem` (what is wrong and how to fix it), and prints as ``field: problem``.
"""

from __future__ import annotations


class GeometryError(ValueError):
    """Invalid geometric input: bad knots, shapes, weights or parameters."""

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}" if field else problem)

    def within(self, prefix: str) -> "GeometryError":
        """The same error with `prefix` put in front of the field name."""
        field = f"{prefix}.{self.field}" if self.field else prefix
        return type(self)(field, self.problem)


class DenominatorError(GeometryError):
    """The rational denominator sum(w N N) vanishes inside the domain."""


class DomainError(GeometryError):
    """A parameter lies outside the valid domain [t_p, t_(n+1)]."""


class ModelError(GeometryError):
    """A model file is unreadable or invalid."""


def fmt(x: float) -> str:
    """A number written short: 1.0 -> '1', 0.5 -> '0.5'."""
    return format(float(x), ".15g")
