"""Slicing settings: layers, walls, infill, skirt, speeds, retraction, temperatures (mm, mm/s, °C, %)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ..materials import Material, get_material

INFILL_PATTERNS = ("zigzag", "grid")


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
        """Raise ValueError naming the setting when a value is out of range."""
        get_material(self.material)
        positive = ("layer_height", "first_layer_height", "perimeter_speed", "external_perimeter_speed",
                    "infill_speed", "solid_infill_speed", "first_layer_speed", "travel_speed", "acceleration",
                    "retract_speed")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"slice setting {name} must be positive, got {getattr(self, name)}")
        if self.line_width is not None and not self.line_width > 0:
            raise ValueError(f"slice setting line_width must be positive (mm), got {self.line_width}")
        if not 0 <= self.infill <= 100:
            raise ValueError(f"infill density must be between 0 and 100 percent, got {self.infill}")
        if self.infill_pattern not in INFILL_PATTERNS:
            raise ValueError(f"infill pattern must be one of {', '.join(INFILL_PATTERNS)}, got {self.infill_pattern!r}")
        for name in ("perimeters", "top_layers", "bottom_layers", "skirts"):
            if int(getattr(self, name)) != getattr(self, name) or getattr(self, name) < 0:
                raise ValueError(f"slice setting {name} must be a whole number >= 0, got {getattr(self, name)}")
        for name in ("retract_length", "retract_min_travel", "z_hop", "skirt_distance"):
            if getattr(self, name) < 0:
                raise ValueError(f"slice setting {name} must not be negative, got {getattr(self, name)}")
        if self.fan is not None and not 0 <= self.fan <= 100:
            raise ValueError(f"fan must be between 0 and 100 percent, got {self.fan}")

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
