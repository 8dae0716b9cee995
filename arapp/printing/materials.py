"""Filament materials: temperatures (docs/domain.md §4), fan, density and speed factor.

Hotend ranges and bed needs are docs/domain.md's table; the default hotend and bed
temperatures are points inside those ranges. Densities (g/cm³) are the usual
datasheet values, used for the filament mass in the G-code header.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """One filament: temperatures in °C, fan in percent, density in g/cm³."""

    name: str
    hotend_range: tuple[float, float]
    hotend: float          # default hotend temperature, inside hotend_range
    bed: float             # default bed temperature; 0 means bed heater off
    fan: int               # part-cooling fan after the first layer, 0..100 %
    density: float         # g/cm³
    speed_factor: float    # print speeds are multiplied by this (TPU prints slowly)
    note: str = ""


MATERIALS: dict[str, Material] = {
    "PLA": Material("PLA", (180.0, 230.0), 205.0, 60.0, 100, 1.24, 1.0, "bed optional"),
    "ABS": Material("ABS", (210.0, 250.0), 240.0, 100.0, 0, 1.04, 1.0, "heated bed, enclosure; warps"),
    "PETG": Material("PETG", (220.0, 250.0), 235.0, 70.0, 50, 1.27, 1.0, "bed not required"),
    "NYLON": Material("NYLON", (240.0, 260.0), 250.0, 80.0, 0, 1.14, 1.0, "bed 70-100 °C; dry filament"),
    "TPU": Material("TPU", (210.0, 230.0), 220.0, 45.0, 50, 1.21, 0.5, "bed 30-60 °C; print slowly"),
}


def get_material(name: str) -> Material:
    """The material called `name` (case-insensitive), or a ValueError listing the known ones."""
    key = str(name).strip().upper()
    if key not in MATERIALS:
        raise ValueError(f"unknown material {name!r}; use one of {', '.join(MATERIALS)}")
    return MATERIALS[key]
