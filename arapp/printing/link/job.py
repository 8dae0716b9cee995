"""A print job's program and state: what runs, how far it got, how to resume it.

`Program` is the G-code prepared for streaming: the commands (comments and
blank lines removed) with their source line index and layer (`;LAYER:n`
comments, or PrusaSlicer's `;LAYER_CHANGE`). `JobState` is what a host knows
about the printer after the last executed command: source line, layer,
position (bed frame, mm), positioning modes, heater targets and readings, fan.
It is saved as JSON (`arapp-printjob/1`) so a print whose link dropped can be
resumed (`resume_commands`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..profile import load_profile
from .protocol import clean_command

JOB_FORMAT = "arapp-printjob/1"

_LAYER = re.compile(r";\s*LAYER\s*:\s*(-?\d+)", re.IGNORECASE)
_LAYER_CHANGE = re.compile(r";\s*LAYER_CHANGE\b", re.IGNORECASE)
_WORD = re.compile(r"([A-Z])\s*(-?\d*\.?\d+)")
_HEATING = {"M104", "M109", "M140", "M190"}


class JobFileError(ValueError):
    """A job file that cannot be read or does not match its G-code."""


# Job status values after which a job cannot continue.
NOT_RESUMABLE = frozenset({"cancelled", "done"})
STATUSES = frozenset({"new", "printing", "cancelling", "cancelled", "done", "halted", "reset", "link_lost",
                      "failed"})
# Slicers put purge lines just outside the bed (PrusaSlicer's at Y-3): positions up to this far
# outside it (mm) are accepted.
BED_MARGIN_MM = 5.0
DEFAULT_MAX_HOTEND_C = 300.0
DEFAULT_MAX_BED_C = 120.0


@dataclass
class Command:
    """One command to stream: source line index (0-based), text, layer (-1: before the first)."""

    index: int
    text: str
    layer: int


@dataclass
class Program:
    """G-code prepared for streaming."""

    commands: list[Command]
    source_lines: int
    layer_count: int
    sha256: str

    @classmethod
    def from_lines(cls, lines) -> "Program":
        """Prepare raw G-code lines (with or without newlines)."""
        commands: list[Command] = []
        layer = -1
        layers_seen = set()
        digest = hashlib.sha256()
        count = 0
        for index, raw in enumerate(lines):
            count += 1
            raw = raw.rstrip("\r\n")
            digest.update(raw.encode("utf-8", errors="replace") + b"\n")
            m = _LAYER.search(raw)
            if m and not raw.lstrip().startswith(("G", "M", "T")):
                layer = int(m.group(1))
                layers_seen.add(layer)
            elif _LAYER_CHANGE.search(raw):
                layer += 1
                layers_seen.add(layer)
            text = clean_command(raw)
            if not text:
                continue
            if "*" in text:
                raise ValueError(
                    f"G-code line {index + 1} contains '*', which the serial protocol "
                    f"reserves for the checksum: {raw!r}"
                )
            commands.append(Command(index, text, layer))
        layer_count = (max(layers_seen) + 1) if layers_seen else 0
        return cls(commands, count, layer_count, digest.hexdigest())

    @classmethod
    def from_file(cls, path) -> "Program":
        with open(path, encoding="utf-8", errors="replace") as f:
            return cls.from_lines(f)

    def position_of(self, source_index: int) -> int:
        """Index into `commands` of the first command at or after a source line."""
        lo, hi = 0, len(self.commands)
        while lo < hi:
            mid = (lo + hi) // 2
            if self.commands[mid].index < source_index:
                lo = mid + 1
            else:
                hi = mid
        return lo


@dataclass
class JobState:
    """The printer's state after the last executed command of a job.

    `next_line` is the 0-based source line to continue from (every command
    before it was acknowledged by the printer as executed). Position in the
    bed frame, millimetres; `e` in the extruder's current mode; `f` in mm/min.
    Temperatures in degrees C: targets as commanded, readings as last reported.
    """

    gcode: str = ""
    gcode_sha256: str = ""
    source_lines: int = 0
    next_line: int = 0
    commands_done: int = 0
    commands_total: int = 0
    layer: int = -1
    layer_count: int = 0
    x: float | None = None
    y: float | None = None
    z: float | None = None
    e: float = 0.0
    f: float | None = None
    absolute_xyz: bool = True
    absolute_e: bool = True
    hotend_target: float = 0.0
    bed_target: float = 0.0
    hotend: float | None = None
    bed: float | None = None
    fan: int = 0
    status: str = "new"
    message: str = ""
    port: str = ""
    baud: int = 0
    updated: float = field(default_factory=time.time)

    # -- tracking -------------------------------------------------------------
    def apply(self, command: Command) -> None:
        """Update the state for a command the printer has executed."""
        self.next_line = command.index + 1
        self.commands_done += 1
        self.layer = command.layer
        words = command.text.split(None, 1)
        code = words[0].upper()
        args = dict((k, float(v)) for k, v in _WORD.findall(words[1].upper())) if len(words) > 1 else {}
        if code in ("G0", "G1", "G2", "G3"):
            for axis in ("X", "Y", "Z"):
                if axis in args:
                    current = getattr(self, axis.lower())
                    value = args[axis]
                    if not self.absolute_xyz and current is not None:
                        value += current
                    setattr(self, axis.lower(), value)
            if "E" in args:
                self.e = args["E"] if self.absolute_e else self.e + args["E"]
            if "F" in args:
                self.f = args["F"]
        elif code == "G92":
            for axis in ("X", "Y", "Z"):
                if axis in args:
                    setattr(self, axis.lower(), args[axis])
            if "E" in args:
                self.e = args["E"]
        elif code == "G28":
            axes = [a for a in ("X", "Y", "Z") if a in words[-1].upper()] if len(words) > 1 else []
            for axis in axes or ["X", "Y", "Z"]:
                setattr(self, axis.lower(), 0.0)
        elif code == "G90":
            self.absolute_xyz = True
            self.absolute_e = True
        elif code == "G91":
            self.absolute_xyz = False
            self.absolute_e = False
        elif code == "M82":
            self.absolute_e = True
        elif code == "M83":
            self.absolute_e = False
        elif code in ("M104", "M109") and "S" in args:
            self.hotend_target = args["S"]
        elif code in ("M140", "M190") and "S" in args:
            self.bed_target = args["S"]
        elif code == "M106":
            self.fan = int(args.get("S", 255))
        elif code == "M107":
            self.fan = 0

    def read_temperatures(self, temps: dict) -> None:
        """Take heater readings from a reply ({"T": (actual, target), "B": ...})."""
        hot = temps.get("T", temps.get("T0"))
        if hot is not None:
            self.hotend = hot[0]
        if "B" in temps:
            self.bed = temps["B"][0]

    # -- files ----------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"format": JOB_FORMAT, **asdict(self)}

    def save(self, path) -> None:
        """Write atomically (a crash mid-write leaves the previous file)."""
        path = Path(path)
        self.updated = time.time()
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=2) + "\n", encoding="utf-8")
        os.replace(tmp, path)

    @classmethod
    def load(cls, path, profile=None) -> "JobState":
        """Read and check a job file (see `check_job_fields`); JobFileError names the file and field."""
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise JobFileError(f"cannot read print job {path}: {exc}") from exc
        if not isinstance(data, dict) or data.get("format") != JOB_FORMAT:
            raise JobFileError(f"{path} is not an {JOB_FORMAT} job file (key 'format')")
        data.pop("format")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise JobFileError(f"{path}: unknown key(s) {', '.join(unknown)}")
        check_job_fields(data, path, profile)
        return cls(**data)

    def check_program(self, program: Program, path) -> None:
        """Refuse to resume a job whose G-code file changed since it was saved."""
        if self.gcode_sha256 and program.sha256 != self.gcode_sha256:
            raise JobFileError(
                f"the G-code {path} changed since the job was saved (sha256 differs); "
                "resume with the original file"
            )


def job_schema(profile) -> dict:
    """Each job-file field -> (kind, low, high, unit). Kinds: str, sha, status, bool, int (whole
    number), num (finite number), opt (finite number or null). Positions within the profile's bed
    (mm; x and y up to `BED_MARGIN_MM` outside it), heater targets up to its maxima (degrees C)."""
    bed = profile.bed
    hot = float(getattr(profile, "max_hotend_temperature", DEFAULT_MAX_HOTEND_C))
    cold = float(getattr(profile, "max_bed_temperature", DEFAULT_MAX_BED_C))
    on_bed = " mm (on the printer's bed)"
    return {
        "gcode": ("str", None, None, ""), "message": ("str", None, None, ""), "port": ("str", None, None, ""),
        "gcode_sha256": ("sha", None, None, ""), "status": ("status", None, None, ""),
        "source_lines": ("int", 0, None, ""), "next_line": ("int", 0, None, ""),
        "commands_done": ("int", 0, None, ""), "commands_total": ("int", 0, None, ""),
        "layer": ("int", -1, None, ""), "layer_count": ("int", 0, None, ""), "baud": ("int", 0, None, ""),
        "fan": ("int", 0, 255, ""),
        "x": ("opt", -BED_MARGIN_MM, bed.width + BED_MARGIN_MM, on_bed),
        "y": ("opt", -BED_MARGIN_MM, bed.depth + BED_MARGIN_MM, on_bed),
        "z": ("opt", 0.0, bed.height, on_bed),
        "e": ("num", None, None, ""), "f": ("opt", None, None, ""), "updated": ("num", None, None, ""),
        "hotend": ("opt", None, None, ""), "bed": ("opt", None, None, ""),
        "hotend_target": ("num", 0.0, hot, " C (the printer profile's maximum)"),
        "bed_target": ("num", 0.0, cold, " C (the printer profile's maximum)"),
        "absolute_xyz": ("bool", None, None, ""), "absolute_e": ("bool", None, None, ""),
    }


_KIND_TEXT = {
    "str": "must be a string", "sha": "must be the G-code's sha256 (64 hex digits)",
    "status": f"must be one of {', '.join(sorted(STATUSES))}", "bool": "must be true or false",
    "int": "must be a whole number", "num": "must be a finite number", "opt": "must be a finite number or null",
}


def _kind_ok(kind: str, value) -> bool:
    if kind == "str":
        return isinstance(value, str)
    if kind == "sha":
        return isinstance(value, str) and re.fullmatch(r"[0-9a-f]{64}", value) is not None
    if kind == "status":
        return isinstance(value, str) and value in STATUSES
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "opt" and value is None:
        return True
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def check_job_fields(data: dict, path, profile=None) -> None:
    """Refuse a job file field of the wrong type or out of range (`job_schema`): JobFileError, one
    line naming the file and the field. The G-code's sha256 is required; `profile` None: the
    generic printer's."""
    if profile is None:
        profile = load_profile(None)  # the generic printer, as every command assumes without --printer

    def bad(key, why):
        return JobFileError(f"{path}: field '{key}' {why} (got {data.get(key)!r}); fix or delete the job file")

    if "gcode_sha256" not in data:
        raise bad("gcode_sha256", _KIND_TEXT["sha"])
    for key, (kind, low, high, unit) in job_schema(profile).items():
        if key not in data:
            continue
        value = data[key]
        if not _kind_ok(kind, value):
            raise bad(key, _KIND_TEXT[kind])
        if value is None or low is None:
            continue
        if high is None and value < low:
            raise bad(key, f"must be >= {low:g}")
        if high is not None and not low <= value <= high:
            raise bad(key, f"must be {low:g} to {high:g}{unit}")
    if data.get("f") is not None and data["f"] <= 0:
        raise bad("f", "must be a positive feed rate (mm/min)")
    if data.get("next_line", 0) > data.get("source_lines", 0):
        raise bad("next_line", "must not be past the G-code's last line (source_lines)")
    if data.get("commands_done", 0) > data.get("commands_total", 0):
        raise bad("commands_done", "must not exceed commands_total")


def check_resumable(state: JobState, path, *, after_halt: bool = False) -> None:
    """Refuse to resume a cancelled or finished job; a halted one only with `after_halt`
    (the user has read why the printer halted)."""
    if state.status in NOT_RESUMABLE:
        raise JobFileError(f"{path}: this job is {state.status} and cannot be resumed; start the print again")
    if state.status == "halted" and not after_halt:
        raise JobFileError(
            f"{path}: the printer halted during this job ({state.message or 'no message'}); "
            "fix the cause, then resume with --after-halt"
        )


def new_state(program: Program, gcode_path: str = "") -> JobState:
    """The state before the first command of `program`."""
    return JobState(
        gcode=str(gcode_path),
        gcode_sha256=program.sha256,
        source_lines=program.source_lines,
        commands_total=len(program.commands),
        layer_count=program.layer_count,
    )


def resume_commands(state: JobState, *, z_lift: float = 2.0, bed_height: float | None = None) -> list[str]:
    """G-code that brings the printer back to `state` before the job continues.

    Heats the bed and hotend to their saved targets (waiting), takes the saved
    Z as the current Z (the printer may have lost its position; the nozzle has
    not moved since the link dropped), lifts it by `z_lift` mm, homes X and Y
    (never Z: that would drive the nozzle into the part), moves back above the
    saved point, lowers to Z, restores the extruder position, feed rate, fan and
    positioning modes.
    """
    if state.z is None or state.x is None or state.y is None:
        raise JobFileError(
            "the job has no known nozzle position (it stopped before the first move); start it again instead"
        )
    lift = z_lift if bed_height is None else max(0.0, min(z_lift, bed_height - state.z))
    out = []
    if state.bed_target > 0:
        out.append(f"M190 S{state.bed_target:g}")
    if state.hotend_target > 0:
        out.append(f"M109 S{state.hotend_target:g}")
    out += [
        "G90",
        f"G92 Z{state.z:.3f}",
        f"G1 Z{state.z + lift:.3f} F600",
        "G28 X Y",
        f"G1 X{state.x:.3f} Y{state.y:.3f} F3000",
        f"G1 Z{state.z:.3f} F600",
        "M82" if state.absolute_e else "M83",
        f"G92 E{state.e:.5f}",
    ]
    if state.fan:
        out.append(f"M106 S{state.fan}")
    if state.f:
        out.append(f"G1 F{state.f:g}")
    if not state.absolute_xyz:
        out.append("G91")
    return out


def cancel_commands(state: JobState, *, z_lift: float = 10.0, bed_height: float | None = None) -> list[str]:
    """G-code for a cancelled print: heaters off, fan off, nozzle up, motors off.

    Heats nothing. The lift is relative, `z_lift` mm, less where the bed
    height (mm) would be exceeded.
    """
    lift = z_lift
    if bed_height is not None and state.z is not None:
        lift = max(0.0, min(z_lift, bed_height - state.z))
    out = ["M104 S0", "M140 S0", "M107"]
    if lift > 0:
        out += ["G91", f"G1 Z{lift:g} F600", "G90"]
    out.append("M84")
    return out


def is_heating(command: str) -> bool:
    """True for a command that sets a non-zero heater target."""
    words = command.split()
    if not words or words[0].upper() not in _HEATING:
        return False
    args = dict((k, float(v)) for k, v in _WORD.findall(" ".join(words[1:]).upper()))
    return args.get("S", args.get("R", 0.0)) > 0
