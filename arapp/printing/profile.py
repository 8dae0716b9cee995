"""Printer profiles (`arapp-printer/1`, docs/printer-profile.md): bed size, nozzle, filament, G-code, link, bed anchor.

Lengths are millimetres except the bed anchor's own marker sizes (metres, as in
docs/recording-format.md). `bed_from_anchor` maps the anchor frame, taken in
millimetres, to the bed frame (the printer's G-code coordinates).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arapp.exchange.files import DocumentFormat, register_document
from arapp.exchange.jsonfile import read_json
from tracking.errors import SessionError
from tracking.recording.schema import parse_anchor, parse_rigid

FORMAT = "arapp-printer/1"
PROFILES_DIR = Path(__file__).with_name("profiles")
GENERIC_PATH = PROFILES_DIR / "generic.json"


class ProfileError(ValueError):
    """A printer profile that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class BedSize:
    """Build volume in millimetres: x (width), y (depth), z (height)."""

    width: float
    depth: float
    height: float


@dataclass(frozen=True)
class LinkSettings:
    """How the printer is reached by default: `kind` "serial" (port, baud) or a server ("octoprint",
    "moonraker") at `url`, its API key in `api_key_file` (mode 600; "" where the server needs none)."""

    port: str
    baud: int
    kind: str = "serial"
    url: str = ""
    api_key_file: str = ""


@dataclass
class PrinterProfile:
    """A parsed, checked printer profile."""

    name: str
    bed: BedSize
    nozzle_diameter: float
    filament_diameter: float
    flavor: str
    start_gcode: str
    end_gcode: str
    link: LinkSettings
    bed_anchor: object | None          # tracking.recording.schema.AnchorSpec, or None
    bed_from_anchor: np.ndarray | None  # 4x4, anchor frame (mm) -> bed frame (mm)
    source: str = "<generic>"
    max_hotend_temperature: float = 300.0  # °C; slicing settings and jobs above it are refused
    max_bed_temperature: float = 120.0     # °C
    raw: dict = field(default_factory=dict, repr=False)

    @property
    def bed_center(self) -> tuple[float, float]:
        """Centre of the bed in bed coordinates (mm)."""
        return (self.bed.width / 2.0, self.bed.depth / 2.0)

    @property
    def filament_area(self) -> float:
        """Filament cross-section in mm²."""
        return math.pi * (self.filament_diameter / 2.0) ** 2

    def to_dict(self) -> dict:
        """The profile as its JSON object (defaults filled in)."""
        return copy.deepcopy(self.raw)


# Types of the top-level keys; nested blocks are checked below.
_TOP = {
    "format": str, "name": str, "bed": dict, "nozzle_diameter": float, "filament_diameter": float,
    "flavor": str, "start_gcode": str, "end_gcode": str, "link": dict, "bed_anchor": dict,
    "max_hotend_temperature": float, "max_bed_temperature": float,
}
# Ranges of the numbers (what real FFF printers have); a value outside is a typo (mm for cm, a missing dot).
_RANGES = {
    "nozzle_diameter": (0.1, 2.0, "mm"), "filament_diameter": (1.0, 3.5, "mm"),
    "max_hotend_temperature": (150.0, 500.0, "°C"), "max_bed_temperature": (0.0, 200.0, "°C"),
    "bed.width": (10.0, 2000.0, "mm"), "bed.depth": (10.0, 2000.0, "mm"), "bed.height": (1.0, 2000.0, "mm"),
}
DEFAULT_MAX_HOTEND = 300.0
DEFAULT_MAX_BED = 120.0
_BED = {"width": float, "depth": float, "height": float}
_LINK = {"port": str, "baud": int, "kind": str, "url": str, "api_key_file": str}
LINK_KINDS = ("serial", "octoprint", "moonraker")
_LINK_REQUIRED = ("port", "baud")
_FLAVORS = ("marlin",)


def _check(value, typ, where: str, src: str):
    if typ is float:
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
            raise ProfileError(f"{src}: {where}: must be a number, got {value!r}")
        return float(value)
    if typ is int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise ProfileError(f"{src}: {where}: must be an integer, got {value!r}")
        return value
    if not isinstance(value, typ):
        raise ProfileError(f"{src}: {where}: must be a {'object' if typ is dict else typ.__name__}, got {value!r}")
    return value


def _read_json(path: Path) -> dict:
    return read_json(path, "printer profile", ProfileError)


def _in_range(value: float, key: str, source: str) -> float:
    lo, hi, unit = _RANGES[key]
    if not lo <= value <= hi:
        raise ProfileError(f"{source}: {key}: must be {lo:g} to {hi:g} {unit}, got {value:g}")
    return value


def parse_profile(data: dict, source: str = "<profile>", defaults: dict | None = None) -> PrinterProfile:
    """A `PrinterProfile` from a profile's JSON object; missing values take `defaults` (the generic printer's).

    Raises ProfileError naming the key for an unknown key, a wrong type or a bad value.
    """
    _check_top(data, source)
    merged = copy.deepcopy(defaults or {})
    merged.update(copy.deepcopy(data))
    dims = _parse_bed(merged["bed"], source)
    link_block = _parse_link(data, defaults, source)
    kind = link_block.get("kind", "serial")
    merged["link"] = link_block

    if merged.get("flavor") not in _FLAVORS:
        raise ProfileError(f"{source}: flavor: {merged.get('flavor')!r} is not supported; use one of {', '.join(_FLAVORS)}")

    anchor, bed_from_anchor = None, None
    if merged.get("bed_anchor") is not None:
        anchor, bed_from_anchor = _parse_bed_anchor(merged["bed_anchor"], source)

    return PrinterProfile(
        name=merged["name"],
        bed=BedSize(**dims),
        nozzle_diameter=float(merged["nozzle_diameter"]),
        filament_diameter=float(merged["filament_diameter"]),
        flavor=merged["flavor"],
        start_gcode=merged["start_gcode"],
        end_gcode=merged["end_gcode"],
        link=LinkSettings(port=link_block["port"], baud=int(link_block["baud"]), kind=kind,
                          url=str(link_block.get("url", "")).strip(),
                          api_key_file=str(link_block.get("api_key_file", ""))),
        bed_anchor=anchor,
        bed_from_anchor=bed_from_anchor,
        source=source,
        raw=merged,
        max_hotend_temperature=float(merged.get("max_hotend_temperature", DEFAULT_MAX_HOTEND)),
        max_bed_temperature=float(merged.get("max_bed_temperature", DEFAULT_MAX_BED)),
    )


def _check_top(data, source: str) -> None:
    """The profile's top-level keys: known, the required ones present, types, signs and ranges right."""
    if not isinstance(data, dict):
        raise ProfileError(f"{source}: a printer profile must be a JSON object")
    for key in data:
        if key not in _TOP:
            raise ProfileError(f"{source}: {key}: unknown key; known keys are {', '.join(_TOP)}")
    for key in ("format", "name", "bed"):
        if key not in data:
            raise ProfileError(f"{source}: {key}: missing (a printer profile needs format, name and bed)")
    for key, typ in _TOP.items():
        if key in data:
            data_value = _check(data[key], typ, key, source)
            if typ is float and data_value <= 0:
                raise ProfileError(f"{source}: {key}: must be positive (millimetres), got {data_value}")
            if key in _RANGES:
                _in_range(data_value, key, source)
    if data["format"] != FORMAT:
        raise ProfileError(f"{source}: format: must be {FORMAT!r}, got {data['format']!r}")


def _parse_bed(bed: dict, source: str) -> dict:
    """{"width", "depth", "height"} in mm from the (merged) bed block, each checked."""
    for key in bed:
        if key not in _BED:
            raise ProfileError(f"{source}: bed.{key}: unknown key; the bed has width, depth and height (mm)")
    dims = {}
    for key in _BED:
        if key not in bed:
            raise ProfileError(f"{source}: bed.{key}: missing (the bed needs width, depth and height in mm)")
        dims[key] = _check(bed[key], float, f"bed.{key}", source)
        if dims[key] <= 0:
            raise ProfileError(f"{source}: bed.{key}: must be positive (millimetres), got {dims[key]}")
        _in_range(dims[key], f"bed.{key}", source)
    return dims


def _parse_link(data: dict, defaults: dict | None, source: str) -> dict:
    """The link block: the defaults' with the profile's keys over it, checked (keys, types, kind, url)."""
    link_block = dict((defaults or {}).get("link", {}))
    link_block.update(data.get("link", {}))
    for key in data.get("link", {}):
        if key not in _LINK:
            raise ProfileError(f"{source}: link.{key}: unknown key; the link has {', '.join(_LINK)}")
    for key, typ in _LINK.items():
        if key not in link_block:
            if key in _LINK_REQUIRED:
                raise ProfileError(f"{source}: link.{key}: missing")
            continue
        _check(link_block[key], typ, f"link.{key}", source)
    if link_block["baud"] <= 0:
        raise ProfileError(f"{source}: link.baud: must be positive, got {link_block['baud']}")
    kind = link_block.get("kind", "serial")
    if kind not in LINK_KINDS:
        raise ProfileError(f"{source}: link.kind: {kind!r} is not a link kind; use one of {', '.join(LINK_KINDS)}")
    if kind != "serial" and not str(link_block.get("url", "")).strip():
        raise ProfileError(f"{source}: link.url: missing (a {kind} link needs the server's address, "
                           "e.g. http://mainsailos.local)")
    return link_block


def _parse_bed_anchor(block: dict, source: str):
    """The bed anchor as an AnchorSpec plus its 4x4 `bed_from_anchor` (mm)."""
    block = dict(block)
    bed_from_anchor = np.eye(4)
    if "bed_from_anchor" in block:
        try:
            bed_from_anchor = parse_rigid(block.pop("bed_from_anchor"), "bed_anchor.bed_from_anchor")
        except SessionError as exc:
            raise ProfileError(f"{source}: {exc}") from None
    try:
        anchor = parse_anchor(block, "bed_anchor")
    except SessionError as exc:
        raise ProfileError(f"{source}: {exc}") from None
    return anchor, bed_from_anchor


LINK_LIMITS = {
    "baud": (1200, 4_000_000, "baud (the serial rate; Marlin uses 115200 or 250000)"),
    "window": (1, 8, "lines in flight (Marlin's command buffer holds 4 by default)"),
    "timeout": (0.5, 600.0, "seconds without an answer"),
}


def check_link_values(baud=None, window=None, timeout=None) -> None:
    """Raise ValueError naming the flag (--baud, --window, --timeout) when a serial-link value is out of
    LINK_LIMITS or not a number; None values are not checked (the profile's or the default apply)."""
    for name, value in (("baud", baud), ("window", window), ("timeout", timeout)):
        if value is None:
            continue
        lo, hi, what = LINK_LIMITS[name]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if name in ("baud", "window"):
            ok = ok and float(value) == int(value)
        if not (ok and lo <= value <= hi):
            raise ValueError(f"--{name} must be {lo:g} to {hi:g} {what}, got {value!r}")


def temperature_limit(profile: "PrinterProfile", heater: str) -> float:
    """The highest target (°C) `profile` allows for `heater` ("hotend" or "bed"); jobs and settings above
    it are refused (max_hotend_temperature / max_bed_temperature in the profile, else 300 / 120 °C)."""
    if heater == "hotend":
        return float(profile.max_hotend_temperature)
    if heater == "bed":
        return float(profile.max_bed_temperature)
    raise ValueError(f"heater must be 'hotend' or 'bed', got {heater!r}")


def shipped_profiles() -> list[str]:
    """Names of the profiles shipped with arapp (usable as `--printer NAME`)."""
    return sorted(p.stem for p in PROFILES_DIR.glob("*.json"))


def load_profile(path: str | Path | None = None) -> PrinterProfile:
    """Load a printer profile from a JSON file, or a shipped one by name; None gives the generic printer.

    Values the file omits take the generic 250 x 210 x 210 mm Marlin printer's.
    """
    generic = _read_json(GENERIC_PATH)
    if path is None:
        return parse_profile(generic, str(GENERIC_PATH))
    p = Path(path)
    if not p.exists() and p.suffix == "" and (PROFILES_DIR / f"{p.name}.json").exists():
        p = PROFILES_DIR / f"{p.name}.json"
    if not p.exists():
        raise ProfileError(
            f"printer profile {str(path)!r} not found: give a JSON file (shared format {FORMAT}) "
            f"or a shipped profile name ({', '.join(shipped_profiles())})"
        )
    return parse_profile(_read_json(p), str(p), defaults=generic)


register_document("printer", DocumentFormat("printer profile", (".json",), load_profile, ProfileError,
                                            "docs/printer-profile.md"))
