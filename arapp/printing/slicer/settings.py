"""Slicing settings: layers, walls, infill, skirt, speeds, retraction, temperatures (mm, mm/s, °C, %)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ..materials import Material, get_material

INFILL_PATTERNS = ("zigzag", "grid")

# Printer-independent ranges: (low, high, unit). Past them no printer makes a part (a 1e9 mm z-hop, a
# 1e-4 mm layer that takes hours to slice); check_for(profile) narrows the nozzle- and printer-bound ones.
RANGES: dict[str, tuple[float, float, str]] = {
    "layer_height": (0.01, 2.0, " mm"),
    "first_layer_height": (0.01, 2.0, " mm"),
    "line_width": (0.05, 5.0, " mm"),
    "perimeters": (0, 50, ""),
    "top_layers": (0, 200, ""),
    "bottom_layers": (0, 200, ""),
    "infill": (0.0, 100.0, " %"),
    "infill_angle": (-360.0, 360.0, " degrees"),
    "infill_overlap": (0.0, 1.0, " of a line width"),
    "skirts": (0, 20, ""),
    "skirt_distance": (0.0, 100.0, " mm"),
    "retract_length": (0.0, 20.0, " mm"),
    "retract_speed": (0.0, 200.0, " mm/s"),
    "retract_min_travel": (0.0, 100.0, " mm"),
    "z_hop": (0.0, 10.0, " mm"),
    "perimeter_speed": (0.0, 1000.0, " mm/s"),
    "external_perimeter_speed": (0.0, 1000.0, " mm/s"),
    "infill_speed": (0.0, 1000.0, " mm/s"),
    "solid_infill_speed": (0.0, 1000.0, " mm/s"),
    "first_layer_speed": (0.0, 1000.0, " mm/s"),
    "travel_speed": (0.0, 1000.0, " mm/s"),
    "acceleration": (0.0, 100000.0, " mm/s²"),
    "hotend_temperature": (0.0, 500.0, " °C"),
    "bed_temperature": (0.0, 200.0, " °C"),
    "fan": (0, 100, " %"),
    "resolution": (0.0, 1.0, " mm"),
    "contour_tolerance": (0.0, 0.1, " mm"),
}
POSITIVE = {"layer_height", "first_layer_height", "line_width", "retract_speed", "perimeter_speed",
            "external_perimeter_speed", "infill_speed", "solid_infill_speed", "first_layer_speed", "travel_speed",
            "acceleration", "resolution", "contour_tolerance"}
WHOLE = {"perimeters", "top_layers", "bottom_layers", "skirts", "fan"}
# Command-line flags of `arapp slice` / `arapp print` for the settings they set, named in errors.
FLAGS = {"layer_height": "--layer-height", "first_layer_height": "--first-layer-height", "infill": "--infill",
         "perimeters": "--perimeters", "z_hop": "--z-hop", "retract_length": "--retract"}
LAYER_FACTORS = (0.1, 0.8)        # layer height as a fraction of the nozzle diameter (PrusaSlicer stops at 0.75-0.8)
LINE_WIDTH_FACTORS = (0.5, 2.5)   # line width as a multiple of the nozzle diameter
MAX_Z_HOP_MM = 10.0
EPS_MM = 1e-9                     # 0.8 x 0.4 is 0.32000000000000006 in floating point: still 0.32
NOZZLE_RULES = {name: f" ({LAYER_FACTORS[0]:g} to {LAYER_FACTORS[1]:g} x the nozzle diameter on a given printer)"
                for name in ("layer_height", "first_layer_height")}
MIN_HOTEND = 150.0                # °C; below it no filament melts (and Marlin refuses to extrude below 170)
DEFAULT_MAX_HOTEND = 300.0        # °C, for a profile that names no max_hotend_temperature
DEFAULT_MAX_BED = 120.0           # °C, likewise max_bed_temperature


class SettingsError(ValueError):
    """A slicing setting out of range; the message names the setting, its flag, the range and the printer."""


def layer_range(nozzle_diameter: float) -> tuple[float, float]:
    """(lowest, highest) layer height in mm that a nozzle of this diameter (mm) prints."""
    return (round(LAYER_FACTORS[0] * nozzle_diameter, 4), round(LAYER_FACTORS[1] * nozzle_diameter, 4))


def _within(value, lo: float, hi: float, open_low: bool = False) -> bool:
    """lo <= value <= hi (lo < value with open_low); False for NaN and non-numbers."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return False
    return (lo < v if open_low else lo <= v) and v <= hi


def _num(x) -> str:
    try:
        return format(float(x), ".6g")
    except (TypeError, ValueError):
        return repr(x)


def _label(name: str) -> str:
    flag = FLAGS.get(name)
    return f"slice setting {name}" + (f" ({flag})" if flag else "")


@dataclass
class SliceSettings:
    """What the built-in slicer does; PrusaSlicer gets the equivalent settings (arapp.printing.prusa).

    `None` temperatures and fan take the material's defaults; a `None` line
    width is 1.125 x the profile's nozzle diameter (PrusaSlicer's automatic width).
    """

    material: str = "PLA"
    layer_height: float = 0.2
    first_layer_height: float = 0.2
    line_width: float | None = None
    perimeters: int = 2
    top_layers: int = 3
    bottom_layers: int = 3
    infill: float = 20.0                 # sparse infill density, percent
    infill_pattern: str = "zigzag"
    infill_angle: float = 45.0           # degrees; alternates +/- 90 degrees per layer
    infill_overlap: float = 0.15         # fraction of a line width the infill reaches into the inner wall
    skirts: int = 1
    skirt_distance: float = 6.0
    retract_length: float = 1.0
    retract_speed: float = 35.0
    retract_min_travel: float = 2.0
    z_hop: float = 0.0
    perimeter_speed: float = 45.0
    external_perimeter_speed: float = 35.0
    infill_speed: float = 80.0
    solid_infill_speed: float = 50.0
    first_layer_speed: float = 20.0
    travel_speed: float = 150.0
    acceleration: float = 1000.0         # mm/s², for the time estimate only
    hotend_temperature: float | None = None
    bed_temperature: float | None = None
    fan: int | None = None               # percent, from the second layer on
    scale_to_fit: bool = False
    center: bool = True                  # centre the model on the bed
    resolution: float = 0.0125           # mm; contours are simplified to this
    contour_tolerance: float = 1e-4      # mm; vertices this close to a plane lie on it

    def __post_init__(self):
        self.check()

    def check(self) -> None:
        """Raise SettingsError naming the setting (and its command-line flag) when a value is out of the
        range any printer could use (RANGES); `check_for(profile)` adds the limits of one printer."""
        get_material(self.material)
        for name, (lo, hi, unit) in RANGES.items():
            value = getattr(self, name)
            if value is None:
                continue
            if name in WHOLE and (isinstance(value, bool) or int(value) != value):
                raise SettingsError(f"{_label(name)} must be a whole number, got {value!r}")
            if not _within(value, lo, hi, open_low=name in POSITIVE):
                span = (f"above {_num(lo)} and at most {_num(hi)}{unit}" if name in POSITIVE
                        else f"{_num(lo)} to {_num(hi)}{unit}")
                rule = NOZZLE_RULES.get(name, "")
                raise SettingsError(f"{_label(name)} must be {span}{rule}, got {_num(value)}")
        if self.infill_pattern not in INFILL_PATTERNS:
            raise SettingsError(f"infill pattern must be one of {', '.join(INFILL_PATTERNS)}, got {self.infill_pattern!r}")

    def check_for(self, profile) -> "SliceSettings":
        """Raise SettingsError when a value does not suit `profile` (a PrinterProfile): layer heights
        and line width against its nozzle, z-hop against its build height, temperatures against its
        maximums. Returns self, so `settings.check_for(profile)` can be passed on."""
        self.check()
        nozzle = float(profile.nozzle_diameter)
        where = f"the {_num(nozzle)} mm nozzle of '{profile.name}'"
        lo, hi = layer_range(nozzle)
        for name in ("layer_height", "first_layer_height"):
            value = getattr(self, name)
            if not _within(value, lo - EPS_MM, hi + EPS_MM):
                raise SettingsError(f"{_label(name)} is {_num(value)} mm, but {where} prints layers from "
                                    f"{_num(lo)} to {_num(hi)} mm; choose one in that range")
        w_lo, w_hi = LINE_WIDTH_FACTORS[0] * nozzle, LINE_WIDTH_FACTORS[1] * nozzle
        if self.line_width is not None and not _within(self.line_width, w_lo - EPS_MM, w_hi + EPS_MM):
            raise SettingsError(f"{_label('line_width')} is {_num(self.line_width)} mm, but {where} lays lines "
                                f"from {_num(w_lo)} to {_num(w_hi)} mm wide; choose one in that range")
        hop_max = min(MAX_Z_HOP_MM, float(profile.bed.height))
        if self.z_hop > hop_max:
            raise SettingsError(f"{_label('z_hop')} is {_num(self.z_hop)} mm; '{profile.name}' lifts the nozzle "
                                f"at most {_num(hop_max)} mm on travel")
        t_max = float(getattr(profile, "max_hotend_temperature", DEFAULT_MAX_HOTEND))
        if not _within(self.hotend(), MIN_HOTEND, t_max):
            raise SettingsError(f"hotend temperature {_num(self.hotend())} °C is outside {_num(MIN_HOTEND)}..{_num(t_max)} °C, "
                                f"what '{profile.name}' allows (max_hotend_temperature in its profile)")
        b_max = float(getattr(profile, "max_bed_temperature", DEFAULT_MAX_BED))
        if not _within(self.bed(), 0.0, b_max):
            raise SettingsError(f"bed temperature {_num(self.bed())} °C is outside 0..{_num(b_max)} °C, "
                                f"what '{profile.name}' allows (max_bed_temperature in its profile)")
        return self

    @property
    def material_info(self) -> Material:
        return get_material(self.material)

    def width(self, nozzle_diameter: float) -> float:
        """Extrusion line width in mm."""
        return self.line_width if self.line_width is not None else round(1.125 * nozzle_diameter, 4)

    def hotend(self) -> float:
        return self.hotend_temperature if self.hotend_temperature is not None else self.material_info.hotend

    def bed(self) -> float:
        return self.bed_temperature if self.bed_temperature is not None else self.material_info.bed

    def fan_percent(self) -> int:
        return self.fan if self.fan is not None else self.material_info.fan

    def speeds(self) -> dict:
        """Feature speeds in mm/s after the material's speed factor (TPU prints slowly)."""
        f = self.material_info.speed_factor
        return {
            "external_perimeter": self.external_perimeter_speed * f,
            "perimeter": self.perimeter_speed * f,
            "solid_infill": self.solid_infill_speed * f,
            "sparse_infill": self.infill_speed * f,
            "skirt": self.first_layer_speed * f,
            "first_layer": self.first_layer_speed * f,
            "travel": self.travel_speed,
        }

    def replace(self, **changes) -> "SliceSettings":
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}
