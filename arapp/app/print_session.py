"""One print of the model as shown, without widgets: printable solid -> slice -> preview on the bed -> print.

`PrintSession` holds what the print dialog shows and does: the placed
solid, the slice result and its G-code (a copy under `work_dir` that the
preview and the printer job read), the print preview request, and the
running `PrintJob` with its last progress. Slow work goes through the
session's runner (arapp.app.runner); print events come from the link's
thread and are posted to the runner's thread. Sizes in millimetres.

Events: solid_ready(solid), slice_progress(fraction), sliced(result),
slice_failed(exception, cancelled), preview_changed(spec | None),
preview_drawn(info) (the live view shows the preview), print_event(PrintEvent), error(title, message),
saved_job_changed(SavedJob | None) (a stopped print that can be resumed, arapp.app.saved_job).

A print that stopped with its state saved is never started over silently:
`start_print` refuses while `saved_job` is set unless told `start_over`
(the user chose to), and `resume_print` continues it by the CLI's rules.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from arapp.engine.events import Events
from arapp.printing.printers import resolve_profile
from arapp.app.printlink import PrintEvent, start_job
from arapp.app.runner import ImmediateRunner
from arapp.app.saved_job import SavedJob, find_saved_job, load_saved_job, stop_text
from arapp.engine.toolpaths import bed_from_placement_mm, preview_spec, summarize
from arapp.exchange import write_atomic
from arapp.geometry.placement import Placement
from arapp.printing import SliceCancelled, placed_solid, slice_mesh
from arapp.printing.export import drop_on_bed
from arapp.printing.gcode import parse_gcode
from arapp.printing.link import JobState
from arapp.printing.prusa import slice_with_prusa

KEEP_SLICES = 10
# The slicers a print can use: name -> slice(mesh_mm, settings, profile, progress=, cancel=) -> SliceResult.
# Adding one is one function with that signature and one row here (the print dialog lists the names).
SLICERS = {"built-in": slice_mesh, "PrusaSlicer": slice_with_prusa}


def prune_slices(folder: Path, keep: int = KEEP_SLICES) -> None:
    """Delete all but the newest `keep` sliced G-code files in `folder` that no print job refers to (a file
    with a .printjob.json beside it may be needed to resume a print, so it stays)."""
    loose = [p for p in folder.glob("*.gcode") if not p.with_suffix(".printjob.json").exists()]
    loose.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    for p in loose[keep:]:
        try:
            p.unlink()
        except OSError:
            pass  # in use or already gone: harmless, tried again next time


def default_work_dir() -> Path:
    return Path.home() / ".arapp" / "print-jobs"


def slice_job(model, placement: Placement, settings, profile, profile_name: str, job_gcode: Path, progress,
              cancel, slicer: str = "built-in"):
    """Worker thread: the placed solid sliced by `slicer` (a SLICERS name); the G-code written to
    `job_gcode` (the copy the preview and the printer job read) with its summary. Returns (result, gcode
    path, summary, profile, name, bed_from_placement: the 4x4 (mm) the slicer moved the placed part by)."""
    matrix = placement.matrix(model.bounds(), "mm")
    here = placed_solid(model, placement, profile=profile, center=False)  # x, y as placed; lowest point at z = 0
    solid = drop_on_bed(here, profile)  # centred on the bed, as placed_solid does by default
    result = SLICERS[slicer](solid, settings, profile, progress=progress, cancel=cancel)
    v = np.asarray(model.mesh().vertices, float) @ np.asarray(matrix, float)[:3, :3].T + np.asarray(matrix, float)[:3, 3]
    sliced = result.mesh if getattr(result, "mesh", None) is not None and abs(result.scale - 1) < 1e-9 else solid
    bed_from_placement = bed_from_placement_mm(here.bounds, sliced.bounds, float(v[:, 2].min()))
    # renamed into place: the preview and a resume check read it while a later slice may be writing
    write_atomic(job_gcode, result.gcode.encode("utf-8"))
    prune_slices(job_gcode.parent)
    summary = summarize(parse_gcode(result.gcode), profile.bed)
    return result, str(job_gcode), summary, profile, profile_name, bed_from_placement


class PrintSession:
    """Slice and print `model` (an arapp.geometry Model with edits applied) at `placement` (as shown)."""

    def __init__(self, model, placement: Placement | None, runner=None, work_dir=None):
        self.model = model
        self.placement = Placement.from_any(placement, getattr(model, "placement", None))
        self.run = runner or ImmediateRunner()
        self.work_dir = Path(work_dir) if work_dir is not None else default_work_dir()
        self.events = Events("solid_ready", "slice_progress", "sliced", "slice_failed", "preview_changed",
                             "preview_drawn", "print_event", "error", "saved_job_changed")
        self.solid = None
        self.result = None  # arapp.printing SliceResult
        self.gcode_path: str | None = None  # where the user saved the G-code
        self.job_gcode_path: str | None = None
        self.summary = None  # arapp.engine.toolpaths.PreviewSummary of the sliced G-code
        self.profile = None  # the PrinterProfile sliced for
        self.sliced_profile: str | None = None  # its name or path
        self.bed_from_placement = None  # 4x4 (mm): the slicer's move of the placed part onto the bed
        self.job = None  # arapp.app.printlink.PrintJob while printing
        self.current_layer = -1  # the layer being printed, from the link's reports
        self.last_progress = None
        self.preview_on = False
        self.preview_layer: int | None = None  # None: all layers
        self.preview_gen = 0
        self.preview_spec: dict | None = None
        self._slice_task = None
        self.saved_job: SavedJob | None = None  # a stopped print that can be resumed
        self._job_profile = None  # the PrinterProfile the running job prints for

    def fail(self, title: str, exc: BaseException) -> None:
        self.events.error.emit(title, str(exc) or type(exc).__name__)

    # -- the printable solid -------------------------------------------------------------
    def make_solid(self) -> None:
        self.model.placement = self.placement
        self.run.run(placed_solid, self.model, self.placement, done=self._solid_done,
                     failed=lambda e: self.fail("Cannot make a printable solid", e), name="arapp-solid")

    def _solid_done(self, solid) -> None:
        self.solid = solid
        self.events.solid_ready.emit(solid)

    # -- slicing -------------------------------------------------------------------------
    @property
    def slicing(self) -> bool:
        return self._slice_task is not None and self._slice_task.running

    def slice(self, settings, profile_name: str, slicer: str = "built-in") -> bool:
        """Slice with `settings` (arapp.printing.SliceSettings) for the printer profile `profile_name` (a
        shipped name or a file) with `slicer` (a SLICERS name); False (reported) when the profile cannot be
        read or the slicer is unknown."""
        try:
            if slicer not in SLICERS:
                raise ValueError(f"unknown slicer {slicer!r}; the slicers are {', '.join(SLICERS)}")
            profile = resolve_profile(profile_name)
        except (ValueError, OSError) as exc:
            self.fail("Cannot slice", exc)
            return False
        self.result = None
        stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in str(getattr(self.model, "name", "model")))
        job_gcode = self.work_dir / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}.gcode"
        cancel = threading.Event()
        last = [0.0]

        def progress(f):
            now = time.perf_counter()
            if now - last[0] > 0.05 or f >= 1.0:  # at most 20 updates a second
                last[0] = now
                self.run.post(self.events.slice_progress.emit, f)

        self.model.placement = self.placement
        self._slice_task = self.run.run(slice_job, self.model, self.placement, settings, profile,
                                        str(profile_name), job_gcode, progress, cancel, slicer,
                                        done=self._slice_done,
                                        failed=self._slice_failed, name="arapp-slice")
        if self._slice_task is not None:
            self._slice_task.cancel = cancel
        return True

    def cancel_slice(self) -> None:
        if self._slice_task is not None:
            self._slice_task.cancel.set()

    def _slice_done(self, done) -> None:
        (self.result, self.job_gcode_path, self.summary, self.profile, self.sliced_profile,
         self.bed_from_placement) = done
        self.events.sliced.emit(self.result)
        if self.preview_on:
            self.emit_preview()

    def _slice_failed(self, exc: BaseException) -> None:
        cancelled = isinstance(exc, SliceCancelled)
        self.events.slice_failed.emit(exc, cancelled)
        if not cancelled:
            self.fail("Slicing failed", exc)

    def save_gcode(self, path: str) -> str | None:
        """Write the sliced G-code to `path`; None (reported) when it cannot be written or nothing is sliced."""
        if self.result is None or not path:
            return None
        try:
            Path(path).write_text(self.result.gcode)
        except OSError as exc:
            self.fail("Cannot save the G-code", exc)
            return None
        self.gcode_path = str(path)
        return self.gcode_path

    # -- the print preview on the bed ------------------------------------------------------
    @property
    def preview_possible(self) -> bool:
        """Sliced: the toolpaths can be shown, on the bed marker or where the model is placed."""
        return (self.summary is not None and self.summary.layers > 0 and self.profile is not None
                and (self.bed_from_placement is not None or self.profile.bed_from_anchor is not None))

    def set_preview(self, on: bool, layer: int | None = None) -> None:
        """Show (or hide) the toolpaths on the bed, up to `layer` (0-based; None: all layers)."""
        self.preview_on, self.preview_layer = bool(on), layer
        if on:
            self.emit_preview()
        else:
            self._set_preview(None)

    def emit_preview(self) -> None:
        if self.job_gcode_path is None:
            return
        current = self.current_layer if (self.job is not None and self.current_layer >= 0) else None
        self._set_preview(preview_spec(self.job_gcode_path, self.sliced_profile, self.preview_layer, current,
                                       bed_from_placement=self.bed_from_placement))

    def _set_preview(self, spec: dict | None) -> None:
        self.preview_gen += 1
        if spec is not None:
            spec["gen"] = self.preview_gen
        self.preview_spec = spec
        self.events.preview_changed.emit(spec)

    def preview_shown(self, info: dict) -> None:
        """The live view drew the preview `info` (arapp.engine.toolpaths); the session tells us."""
        self.events.preview_drawn.emit(info)

    # -- printing --------------------------------------------------------------------------
    @property
    def printing(self) -> bool:
        return self.job is not None

    def _set_saved_job(self, saved: SavedJob | None) -> None:
        self.saved_job = saved
        self.events.saved_job_changed.emit(saved)

    def look_for_saved_job(self, profile_name: str | None = None) -> SavedJob | None:
        """Offer the newest resumable job in `work_dir` (a print that stopped in an earlier run of the app)."""
        if self.job is not None:
            return self.saved_job
        try:
            profile = resolve_profile(profile_name) if profile_name else None
        except (ValueError, OSError):
            profile = None
        saved = find_saved_job(self.work_dir, profile)
        if saved is not None or self.saved_job is not None:
            self._set_saved_job(saved)
        return saved

    def start_print(self, target, profile_name: str, start_over: bool = False) -> bool:
        """Send the sliced G-code to `target` (arapp.app.printlink SerialTarget or OctoPrintTarget); False
        (reported) when the target or profile cannot work, or when a stopped print could be resumed and
        `start_over` is not set (the user must choose: Resume, or start the job again)."""
        if self.result is None or self.job is not None:
            return False
        if self.saved_job is not None and not start_over:
            self.events.error.emit("A stopped print can be resumed",
                                   f"{self.saved_job.executed_text()}\n\nPress Resume to continue it, or choose to "
                                   "start over (clear the bed first).")
            return False
        job_path = None
        if self.job_gcode_path is not None:
            job_path = str(Path(self.job_gcode_path).with_suffix(".printjob.json"))
        try:
            profile = resolve_profile(profile_name)
            job = start_job(target, self.result.gcode, profile,
                            lambda ev: self.run.post(self.handle_event, ev), job_path=job_path,
                            gcode_path=self.job_gcode_path or "")
        except (ValueError, OSError, RuntimeError) as exc:
            self.fail("Printer error", exc)
            return False
        if self.saved_job is not None:
            self._discard_saved_job(profile, job_path)
        self.job, self._job_profile = job, profile
        self.current_layer = -1
        self.last_progress = None
        return True

    def _discard_saved_job(self, profile, new_job_path: str | None) -> None:
        """The user started over: the stopped job's file says so (unless the new job writes that same file),
        and it is no longer offered."""
        saved = self.saved_job
        if saved.job_path != new_job_path:
            try:
                state = JobState.load(saved.job_path, profile)
                state.status, state.message = "cancelled", "started over from the GUI"
                state.save(saved.job_path)
            except (ValueError, OSError):
                pass  # unreadable now: find_saved_job will not offer it either
        self._set_saved_job(None)

    def resume_print(self, target, profile_name: str | None = None, halt_confirmed: bool = False) -> bool:
        """Continue `saved_job` on `target` (serial) as `arapp print --resume` does: the job file and its G-code
        checked again now, the printer brought back by job.resume_commands (homes X and Y only), then the
        lines not yet executed. A halted job needs `halt_confirmed` (the user read why it halted). False
        (reported) when it cannot."""
        saved = self.saved_job
        if saved is None or self.job is not None:
            return False
        if saved.halted and not halt_confirmed:
            self.events.error.emit("Resume needs your confirmation", saved.check_text())
            return False
        try:
            profile = resolve_profile(profile_name or self.sliced_profile)
            saved = load_saved_job(saved.job_path, profile)  # the file may have changed since it was offered
            gcode = Path(saved.gcode_path).read_text(encoding="utf-8", errors="replace")
            job = start_job(target, gcode, profile, lambda ev: self.run.post(self.handle_event, ev),
                            job_path=saved.job_path, gcode_path=saved.gcode_path, resume=saved)
        except (ValueError, OSError, RuntimeError) as exc:
            self.fail("Cannot resume the print", exc)
            return False
        if self.job_gcode_path != saved.gcode_path:
            # the preview and its highlight follow the G-code being printed (an earlier slice)
            self.job_gcode_path = saved.gcode_path
            self.summary = summarize(parse_gcode(gcode), profile.bed)
            self.profile, self.sliced_profile = profile, str(profile_name or self.sliced_profile)
        self.job, self._job_profile = job, profile
        self._set_saved_job(None)
        self.current_layer = saved.state.layer
        self.last_progress = None
        return True

    def handle_event(self, ev: PrintEvent) -> None:
        """A report of the job (on the runner's thread): progress, the printed layer, errors, the end."""
        pr = ev.progress
        layer_changed = False
        if pr is not None:
            self.last_progress = pr
            layer_changed = pr.layer != self.current_layer
            self.current_layer = pr.layer
        saved, why_not = None, ""
        if ev.finished and ev.error and ev.job_path:
            try:
                saved = load_saved_job(ev.job_path, self._job_profile)
            except (ValueError, OSError) as exc:
                # stopped before the first move, its G-code changed or is gone: not resumable, and why
                saved, why_not = None, str(exc)
        if ev.error:
            if ev.finished and ev.job_state is not None:
                title, message = stop_text(ev.job_state, saved, ev.error, why_not)
            else:
                title, message = ev.error_title or "Printer error", ev.error
            self.events.error.emit(title, message)
        if ev.finished:
            self.job = None
            self._set_saved_job(saved)
        self.events.print_event.emit(ev)
        # the preview's highlight follows the printer's acknowledged lines, as the link reports them
        if self.preview_on and ((layer_changed and pr.layer >= 0 and self.job is not None) or ev.finished):
            self.emit_preview()

    def toggle_pause(self) -> str:
        """Pause or resume the running print; returns what it did ("paused", "resumed" or "")."""
        job = self.job
        if job is None:
            return ""
        if job.paused:
            job.resume()
            return "resumed"
        job.pause()
        return "paused"

    def cancel_print(self) -> None:
        if self.job is not None:
            self.job.cancel()
