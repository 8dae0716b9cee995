"""A print that stopped with its state saved, as the app offers to resume it (no Qt).

The rules are the CLI's (`arapp print --resume`, arapp.commands.print_): the
job file is read and checked against the printer profile
(`JobState.load`), a cancelled or finished job is refused and a halted one
only once the user has read why it halted (`check_resumable`), the G-code
must be the one the job ran (`check_program`: its sha256), and the printer
is brought back by `resume_commands` (heat, take the saved Z, lift, home X
and Y only, move back above the saved point, lower). `SavedJob` holds all
of it and says in plain words what was executed and what Resume will do;
`stop_text` says what happened when a print stopped. Sizes in mm, heats in
degrees C.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from arapp.printing.link import JobFileError, JobState, Program, resume_commands
from arapp.printing.link.job import check_resumable

@dataclass
class SavedJob:
    """A resumable job: its file, G-code, saved state and prepared program."""

    job_path: str
    gcode_path: str
    state: JobState
    program: Program
    bed_height: float | None = None

    @property
    def halted(self) -> bool:
        return self.state.status == "halted"

    @property
    def percent(self) -> float:
        total = max(1, self.state.commands_total or len(self.program.commands))
        return 100.0 * self.state.commands_done / total

    def preamble(self) -> list[str]:
        """The G-code that brings the printer back (job.resume_commands, capped by the bed height)."""
        return resume_commands(self.state, bed_height=self.bed_height)

    def executed_text(self) -> str:
        """What the printer executed: commands, percent, layer, the nozzle's height."""
        s = self.state
        layer = f", layer {s.layer + 1} of {s.layer_count}" if s.layer >= 0 and s.layer_count else ""
        return (f"The printer executed {s.commands_done:,} of {s.commands_total:,} commands "
                f"({self.percent:.1f} %){layer}; the nozzle stopped at z {s.z:.2f} mm "
                f"above x {s.x:.1f}, y {s.y:.1f} mm.")

    def plan_text(self) -> str:
        """What Resume does, step by step, in plain words."""
        s = self.state
        heat = []
        if s.bed_target > 0:
            heat.append(f"the bed to {s.bed_target:g} °C")
        if s.hotend_target > 0:
            heat.append(f"the nozzle to {s.hotend_target:g} °C")
        # the first Z move of the preamble is the lift (resume_commands' order)
        lift = next(c for c in self.preamble() if c.startswith("G1 Z")).split()[1][1:]
        steps = ([f"heat {' and '.join(heat)} and wait"] if heat else [])
        steps += [f"take z {s.z:.2f} mm as the nozzle's height (Z is not homed: that would drive the nozzle "
                  "into the part)",
                  f"lift the nozzle to z {float(lift):.2f} mm",
                  "home X and Y only",
                  f"move back above x {s.x:.1f}, y {s.y:.1f} and lower to z {s.z:.2f} mm",
                  f"continue with line {s.next_line + 1:,} of {s.source_lines:,}; nothing already executed "
                  "runs again"]
        return "Resume will:\n" + "\n".join(f"  {i + 1}. {t}" for i, t in enumerate(steps))

    def check_text(self) -> str:
        """What the user must make sure of before resuming."""
        text = ("Before resuming: the part must still be on the bed where it was, and nothing may have moved the "
                "print head up or down since it stopped.")
        if self.halted:
            text = (f"The printer halted itself: {self.state.message or 'it gave no reason'}. Fix the cause first "
                    "(a halt is a safety stop, e.g. a heater or its sensor failing). ") + text
        return text


def load_saved_job(job_path, profile=None) -> SavedJob:
    """The job at `job_path` checked as `arapp print --resume` checks it (halts are allowed here: the GUI asks
    the user to confirm having read the halt's reason). Raises JobFileError (a ValueError; one line) when it
    cannot be resumed, FileNotFoundError when its G-code is gone."""
    state = JobState.load(job_path, profile)
    check_resumable(state, job_path, after_halt=True)
    if not state.port:
        # as `arapp print --resume`: serial jobs only (an OctoPrint job is OctoPrint's to continue)
        raise JobFileError(f"{job_path}: this job ran through OctoPrint; it can be resumed over USB serial only")
    gcode = Path(state.gcode)
    if not gcode.is_file():
        raise FileNotFoundError(f"{job_path}: its G-code {gcode} is gone; the print cannot be resumed")
    program = Program.from_file(gcode)
    state.check_program(program, gcode)
    bed_height = getattr(getattr(profile, "bed", None), "height", None)
    job = SavedJob(str(job_path), str(gcode), state, program, bed_height)
    job.preamble()  # refuses a job without a known nozzle position (JobFileError)
    return job


def find_saved_job(folder, profile=None) -> SavedJob | None:
    """The newest resumable job in `folder` (the print jobs folder), or None."""
    folder = Path(folder)
    if not folder.is_dir():
        return None
    paths = sorted(folder.glob("*.printjob.json"), key=lambda p: p.stat().st_mtime, reverse=True)
    for path in paths:
        try:
            return load_saved_job(path, profile)
        except (ValueError, OSError):
            continue  # finished, cancelled, for another printer, or its G-code changed: not offered
    return None


_WHY = {
    "link_lost": ("The connection to the printer was lost",
                  "The printer was switched off, reset, or its USB cable came loose."),
    "reset": ("The printer restarted during the print",
              "Its firmware reset (a power dip, or a reset over USB); it lost its position and heat."),
    "halted": ("The printer halted itself", "It stopped for safety and turned its heaters off."),
    "failed": ("The print stopped on an error", ""),
}


def stop_text(state: JobState | None, resumable: SavedJob | None, detail: str, why_not: str = "") -> tuple[str, str]:
    """(title, message) in plain words for a print that stopped with `state` (the link's job state);
    `resumable` when it can be resumed, else `why_not` (why its saved job cannot be); `detail`: the
    link's own wording, kept last."""
    status = getattr(state, "status", "failed")
    title, why = _WHY.get(status, _WHY["failed"])
    where = ""
    if state is not None and state.commands_total:
        pct = 100.0 * state.commands_done / state.commands_total
        layer = f", layer {state.layer + 1} of {state.layer_count}" if state.layer >= 0 and state.layer_count else ""
        where = f" at {pct:.1f} %{layer}"
    lines = [f"{title}{where}. {why}".strip()]
    if resumable is not None:
        lines.append("The print's progress is saved. Leave the part on the bed; when the printer is back, press "
                     "Resume in the Print panel (it homes X and Y only and continues where the print stopped). "
                     "Print would start the whole job again.")
    elif state is not None and state.commands_done:
        because = f" ({why_not})" if why_not else ""
        lines.append(f"This print cannot be resumed{because}; clear the bed before printing again.")
    if detail:
        lines.append(f"Details: {_without_cli_hint(detail)}")
    return title, "\n\n".join(lines)


def _without_cli_hint(message: str) -> str:
    """The link's message without the CLI's '(job state saved to ...; resume with --resume ...)'."""
    cut = message.find(" (job state saved to ")
    return message[:cut] if cut >= 0 else message

