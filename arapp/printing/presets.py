"""Printer presets for common Marlin printers, in the printer-profile format (`arapp-printer/1`).

A preset is a profile without a bed anchor (that depends on where the user
lays the marker) and without a port (that depends on the computer); the
user picks the port in the printer set-up and sets up the bed anchor with
`arapp printer bed-anchor`. Build volumes and start G-code from the makers'
published specifications (mm): Prusa i3 MK3S/MK3S+ 250 x 210 x 210;
Creality Ender-3 / Ender-3 Pro / Ender-3 V2 220 x 220 x 250; Ender-3 S1
220 x 220 x 270; Ender-3 Max 300 x 300 x 340.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

from arapp.printing.profile import FORMAT, GENERIC_PATH, PrinterProfile, ProfileError, parse_profile

_PRUSA_START = ("M862.3 P \"MK3S\" ; printer model check\nG28 W ; home all without mesh bed level\n"
                "G80 ; mesh bed leveling\nG1 Y-3.0 F1000.0 ; go outside the print area\n"
                "G92 E0.0\nG1 X60.0 E9.0 F1000.0 ; intro line\nG1 X100.0 E12.5 F1000.0 ; intro line\nG92 E0.0")
_PRUSA_END = "M104 S0\nM140 S0\nM107\nG1 Z+10 F720\nG1 X0 Y200 F3600\nM84"
_ENDER_START = ("G28 ; home all axes\nG92 E0\nG1 Z2.0 F3000\nG1 X0.1 Y20 Z0.3 F5000.0\n"
                "G1 X0.1 Y200.0 Z0.3 F1500.0 E15 ; purge line\nG1 X0.4 Y200.0 Z0.3 F5000.0\n"
                "G1 X0.4 Y20 Z0.3 F1500.0 E30 ; purge line\nG92 E0\nG1 Z2.0 F3000")
_ENDER_END = "G91\nG1 E-2 F2700\nG1 Z10 F2400\nG90\nG1 X0 Y200 F3000\nM106 S0\nM104 S0\nM140 S0\nM84 X Y E"


def _preset(name: str, w: float, d: float, h: float, start: str, end: str, max_hotend: float = 260.0,
            max_bed: float = 100.0) -> dict:
    return {"format": FORMAT, "name": name, "bed": {"width": w, "depth": d, "height": h},
            "nozzle_diameter": 0.4, "filament_diameter": 1.75, "flavor": "marlin",
            "start_gcode": start, "end_gcode": end, "link": {"port": "", "baud": 115200},
            "max_hotend_temperature": max_hotend, "max_bed_temperature": max_bed}


PRESETS: dict[str, dict] = {
    "prusa_mk3s": _preset("Prusa i3 MK3S", 250.0, 210.0, 210.0, _PRUSA_START, _PRUSA_END, 300.0, 120.0),
    "ender3": _preset("Creality Ender-3 / Pro / V2", 220.0, 220.0, 250.0, _ENDER_START, _ENDER_END),
    "ender3_s1": _preset("Creality Ender-3 S1", 220.0, 220.0, 270.0, _ENDER_START, _ENDER_END),
    "ender3_max": _preset("Creality Ender-3 Max", 300.0, 300.0, 340.0, _ENDER_START, _ENDER_END),
    "generic_220": _preset("Generic Marlin 220x220", 220.0, 220.0, 250.0, "G28\nG1 Z5 F5000",
                           "M104 S0\nM140 S0\nG28 X0\nM84"),
}


def preset_names() -> list[str]:
    return list(PRESETS)


def preset_data(key: str) -> dict:
    """A copy of preset `key`'s profile JSON object."""
    if key not in PRESETS:
        raise ProfileError(f"no printer preset {key!r}; presets: {', '.join(PRESETS)}")
    return copy.deepcopy(PRESETS[key])


def preset_profile(key: str) -> PrinterProfile:
    """Preset `key` parsed and checked as a printer profile (no bed anchor)."""
    generic = json.loads(GENERIC_PATH.read_text())
    generic.pop("bed_anchor", None)
    return parse_profile(preset_data(key), f"preset {key}", defaults=generic)


def write_preset(key: str, path: str | Path, port: str = "", baud: int | None = None) -> Path:
    """Write preset `key` as a profile file the user can edit (with the chosen port and baud)."""
    data = preset_data(key)
    data["link"]["port"] = port
    if baud is not None:
        data["link"]["baud"] = int(baud)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path
