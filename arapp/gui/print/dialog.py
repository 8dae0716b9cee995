"""The print dialog: widgets bound to an `arapp.app.print_session.PrintSession` (the model as placed on
screen -> slice -> preview the toolpaths on the real printer bed in the AR view -> save the G-code or send
it to a printer, serial port or OctoPrint, with progress, layer, ETA, temperatures, pause/resume/cancel).

The print session emits the preview requests; the app session forwards them
to the live view's engine. During a print the preview's `current` layer
follows the link's progress reports.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QStandardPaths, QTimer, Signal
from PySide6.QtWidgets import QDialog, QFileDialog, QHBoxLayout, QLabel, QMessageBox, QPushButton, QVBoxLayout

from arapp.store import user_config

from arapp.app import printlink
from arapp.app.bed_fit import size_text
from arapp.app.print_session import PrintSession, prune_slices
from arapp.gui.print.dialog_parts import BedFitPart, BedPreviewPart
from arapp.gui.print.setup_prefill import prefill, remember_printer, with_setup_key
from arapp.gui.print.widgets import (OTHER_PROFILE, preview_box, restore_settings, send_box, settings_values, slicing_box)
from arapp.gui.print.temperature_graph import TemperatureGraph
from arapp.printing import SliceSettings

__all__ = ["PrintDialog", "TemperatureGraph", "prune_slices"]


def _session_attr(name: str) -> property:
    """The print session's attribute `name`, read and written through the dialog."""
    return property(lambda self: getattr(self.session, name), lambda self, v: setattr(self.session, name, v))


class PrintDialog(BedFitPart, BedPreviewPart, QDialog):
    """Slice and print the model as displayed, through `session` (a PrintSession). `error(title, message)`
    repeats the session's failures; `progress_reported(Progress)` and `print_finished(PrintEvent)` come on
    the UI thread."""

    error = Signal(str, str)
    sliced = Signal(object)
    solid_ready = Signal(object)
    progress_reported = Signal(object)  # arapp.printing.link.Progress
    print_finished = Signal(object)  # the final printlink.PrintEvent
    placement_requested = Signal(object)  # arapp.geometry.placement.Placement: "scale to fit" resized the part

    def __init__(self, session: PrintSession, settings=None, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Print")
        self.setModal(False)
        self.resize(560, 640)
        self.session = ps = session
        self.settings = settings
        ps.work_dir = user_config.jobs_dir(
            Path(QStandardPaths.writableLocation(QStandardPaths.StandardLocation.AppDataLocation)
                 or Path.home() / ".arapp") / "print-jobs")
        self.ask = self._ask  # (title, text, choices) -> the choice pressed, or "" (tests answer for the user)
        self._profile_path: str | None = None
        self._slider_before_print = 0
        lay = QVBoxLayout(self)
        name = getattr(ps.model, "name", "model")
        self.model_label = QLabel(f"<b>{name}</b>, placed {ps.placement.size_mm:g} mm at its largest")
        self.solid_label = QLabel("Preparing the printable solid...")
        for label in (self.model_label, self.solid_label):
            label.setWordWrap(True)  # the dialog lives in a side panel: long lines wrap, not widen it
            lay.addWidget(label)
        fit_row = QHBoxLayout()
        self.fit_label = QLabel("")
        self.fit_label.setWordWrap(True)
        self.fit_label.setStyleSheet("color: #b33")
        self.fit_button = QPushButton("Scale to fit")
        self.fit_button.clicked.connect(self.scale_to_fit)
        fit_row.addWidget(self.fit_label, 1)
        fit_row.addWidget(self.fit_button)
        lay.addLayout(fit_row)
        self._fit = None
        self._show_fit(None)
        for box in (slicing_box(self), preview_box(self), send_box(self)):
            lay.addWidget(box)
        ev = ps.events
        ev.solid_ready.connect(self._solid_done)
        ev.slice_progress.connect(self._slice_progress)
        ev.sliced.connect(self._slice_done)
        ev.slice_failed.connect(self._slice_failed)
        ev.preview_drawn.connect(self.preview_shown)
        ev.print_event.connect(self._show_print_event)
        ev.error.connect(self.error.emit)
        ev.saved_job_changed.connect(self._show_saved_job)
        restore_settings(self, settings)
        self.profile.currentIndexChanged.connect(self.check_fit)
        self.refresh_ports()
        self.print_label.setText(prefill(self))  # the saved Printer set-up: its port or server, not asked again
        ps.look_for_saved_job(self.profile_key())  # a print that stopped in an earlier run
        ps.make_solid()

    # -- the session's state, as the window and tests read it --------------------------------
    model = _session_attr("model")
    placement = _session_attr("placement")
    solid = _session_attr("solid")
    result = _session_attr("result")  # settable: a test may print other G-code than was sliced
    summary = _session_attr("summary")
    job_gcode_path = _session_attr("job_gcode_path")
    gcode_path = _session_attr("gcode_path")
    current_layer = _session_attr("current_layer")
    last_progress = _session_attr("last_progress")
    preview_spec = _session_attr("preview_spec")
    printing = _session_attr("printing")
    work_dir = _session_attr("work_dir")

    # -- settings ----------------------------------------------------------------------
    def _save_settings(self) -> None:
        if self.settings is not None:
            for k, v in settings_values(self).items():
                self.settings.setValue(f"print/{k}", v)

    def profile_key(self) -> str:
        """The printer chosen (an arapp.printing.printers key: "preset:KEY", a shipped name or a profile file)."""
        data = self.profile.currentData()
        return str(data) if data else self.profile.currentText()

    def profile_activated(self, index: int) -> None:
        """The user chose a printer: it becomes the one printer choice (Printer set-up's too)."""
        if self.profile.itemData(index) == OTHER_PROFILE:
            path, _ = QFileDialog.getOpenFileName(self, "Printer profile", str(Path.cwd()), "Printer profile (*.json)")
            if path:
                self.set_profile_path(path)
            else:
                self.profile.setCurrentIndex(0)
        remember_printer(self.profile_key())

    def set_profile_path(self, path: str) -> None:
        """Use the printer profile file at `path` (as 'Other profile file...' does)."""
        path = str(path)
        idx = self.profile.findData(path)
        if idx < 0:
            self.profile.insertItem(0, path, path)
            idx = 0
        self._profile_path = path
        self.profile.setCurrentIndex(idx)

    def slice_settings(self) -> SliceSettings:
        return SliceSettings(material=self.material.currentText(), layer_height=self.layer_height.value(),
                             first_layer_height=max(self.layer_height.value(), 0.2),
                             infill=float(self.infill.value()), perimeters=self.perimeters.value())

    # -- solid and slicing ---------------------------------------------------------------
    def _solid_done(self, solid) -> None:
        self.solid_label.setText(f"Printable solid: {size_text(solid.extents)} (width x depth x height), "
                                 f"{len(solid.faces)} triangles" + (", watertight" if solid.is_watertight else ""))
        self.check_fit()
        self.solid_ready.emit(solid)

    def start_slice(self) -> None:
        try:
            settings = self.slice_settings()
        except ValueError as exc:
            self.session.fail("Cannot slice", exc)
            return
        self._save_settings()
        for b, on in ((self.save_button, False), (self.send_button, False), (self.slice_button, False),
                      (self.cancel_slice_button, True)):
            b.setEnabled(on)
        self.slice_progress.setValue(0)
        self.slice_label.setText("Slicing...")
        if not self.session.slice(settings, self.profile_key(), self.slicer.currentText()):
            self._slice_finished()

    def _slice_progress(self, fraction: float) -> None:
        self.slice_progress.setValue(int(1000 * max(0.0, min(1.0, fraction))))

    def cancel_slice(self) -> None:
        self.session.cancel_slice()
        self.slice_label.setText("Cancelling...")

    def _slice_finished(self) -> None:
        self.slice_button.setEnabled(True)
        self.cancel_slice_button.setEnabled(False)

    def _slice_done(self, result) -> None:
        self._slice_finished()
        self.slice_progress.setValue(1000)
        scale = f", scaled by {result.scale:.3f} to fit" if abs(result.scale - 1) > 1e-9 else ""
        self.slice_label.setText(f"{result.layers} layers, about {printlink.format_duration_s(result.print_time_s)}, "
                                 f"{result.filament_mm / 1000:.2f} m of filament ({result.filament_g:.1f} g){scale}")
        self.save_button.setEnabled(True)
        self.send_button.setEnabled(not self.session.printing)
        self._setup_preview()
        self.sliced.emit(result)

    def _slice_failed(self, exc: BaseException, cancelled: bool) -> None:
        self._slice_finished()
        self.slice_progress.setValue(0)
        self.slice_label.setText("Slicing cancelled" if cancelled else f"Slicing failed: {exc}")

    def save_gcode(self, path: str | None = None) -> str | None:
        if self.session.result is None:
            return None
        if not path:
            default = str(Path.cwd() / f"{getattr(self.model, 'name', 'model')}.gcode".replace(" ", "_"))
            path, _ = QFileDialog.getSaveFileName(self, "Save G-code", default, "G-code (*.gcode)")
        saved = self.session.save_gcode(path) if path else None
        if saved:
            self.slice_label.setText(self.slice_label.text() + f"\nSaved {saved}")
        return saved

    # -- printing --------------------------------------------------------------------------
    def refresh_ports(self) -> None:
        current = self.port.currentText()
        self.port.clear()
        self.port.addItems(printlink.serial_ports())
        if current:
            self.port.setCurrentText(current)

    def target(self):
        """The printer chosen in the dialog (printlink.SerialTarget, OctoPrintTarget or MoonrakerTarget)."""
        if self.use_moonraker.isChecked():
            return with_setup_key(printlink.MoonrakerTarget(self.moonraker_url.text().strip(),
                                                            self.api_key_file.text().strip()))
        if self.use_octoprint.isChecked():
            return with_setup_key(printlink.OctoPrintTarget(self.octoprint_url.text().strip(),
                                                            self.api_key_file.text().strip()))
        text = self.baud.currentText()
        try:
            baud = int(text)
        except ValueError:
            raise ValueError(f"baud rate must be a whole number, got {text!r}") from None
        return printlink.SerialTarget(self.port.currentText().strip(), baud)

    def _ask(self, title: str, text: str, choices: list[str]) -> str:
        """A modal question with `choices` (the first is the default) and Cancel; the choice, "" for Cancel."""
        box = QMessageBox(QMessageBox.Icon.Question, title, text, QMessageBox.StandardButton.Cancel, self)
        buttons = {box.addButton(c, QMessageBox.ButtonRole.AcceptRole): c for c in choices}
        box.setDefaultButton(next(iter(buttons)))
        box.exec()
        return buttons.get(box.clickedButton(), "")

    def _show_saved_job(self, saved) -> None:
        """A stopped print that can be resumed: say what ran, offer Resume."""
        self.saved_job_label.setVisible(saved is not None)
        self.resume_button.setVisible(saved is not None)
        self.resume_button.setEnabled(saved is not None and not self.session.printing)
        if saved is not None:
            self.saved_job_label.setText(f"A print stopped before it finished. {saved.executed_text()} "
                                         "Resume continues it; Print would start it over.")
            scroll = getattr(self, "scroll_area", None)  # in the side panel (print_panel): bring it into sight
            if scroll is not None:
                QTimer.singleShot(0, self, lambda: scroll.ensureWidgetVisible(self.resume_button, 20, 60))

    def _target_or_report(self):
        try:
            return self.target()
        except ValueError as exc:
            self.session.fail("Printer error", exc)
            return None

    def start_print(self) -> None:
        ps = self.session
        if ps.result is None or ps.printing:
            return
        self._save_settings()
        start_over = False
        if ps.saved_job is not None:
            # never start a job over silently: the half-made part may still be on the bed
            choice = self.ask("A stopped print can be resumed",
                              f"{ps.saved_job.executed_text()}\n\nResume it where it stopped, or start the "
                              "whole print over? Start over only with the bed cleared.",
                              ["Resume...", "Start over"])
            if choice == "Resume...":
                self.resume_print()
                return
            if choice != "Start over":
                return
            start_over = True
        target = self._target_or_report()
        if target is None or not ps.start_print(target, self.profile_key(), start_over=start_over):
            return
        self._printing_started()

    def resume_print(self) -> None:
        """Resume the stopped print after the user confirmed what it does (arapp.app.saved_job's plain words)."""
        ps = self.session
        saved = ps.saved_job
        if saved is None or ps.printing:
            return
        target = self._target_or_report()
        if target is None:
            return
        text = f"{saved.executed_text()}\n\n{saved.plan_text()}\n\n{saved.check_text()}"
        if self.ask("Resume the print?", text, ["Resume"]) != "Resume":
            return
        if not ps.resume_print(target, ps.sliced_profile or self.profile_key(), halt_confirmed=True):
            return
        self._printing_started()
        self.print_label.setText(f"Resuming at line {saved.state.next_line + 1:,}: heating, homing X and Y...")

    def _printing_started(self) -> None:
        self.resume_button.setEnabled(False)
        self.temps.clear()
        self.print_progress.setValue(0)
        self.print_progress.setFormat("0.0 %")
        self.percent_label.setText("0.0 %")
        self.print_layer_label.setText("")
        self.eta_label.setText("")
        for b, on in ((self.send_button, False), (self.slice_button, False), (self.pause_button, True),
                      (self.cancel_print_button, True)):
            b.setEnabled(on)
        self.pause_button.setText("Pause")
        self._slider_before_print = self.layer_slider.value()
        self.layer_slider.setEnabled(False)
        self.print_label.setText("Connecting...")
        if self.preview_check.isEnabled() and not self.preview_check.isChecked():
            self.preview_check.setChecked(True)  # show the print's progress on the bed

    def _show_print_event(self, ev: printlink.PrintEvent) -> None:
        pr = ev.progress
        if pr is not None:
            self.print_progress.setValue(int(round(10 * max(0.0, min(100.0, pr.percent)))))
            self.percent_label.setText(f"{pr.percent:.1f} %")
            self.print_progress.setFormat(self.percent_label.text())  # one figure: the bar says it
            self.print_layer_label.setText(printlink.layer_text(pr))
            self.eta_label.setText(f"{printlink.format_duration_s(pr.eta_s)} left" if pr.eta_s is not None else "")
            self.temps.add(printlink.temperatures(pr))
            if pr.layer >= 0:
                self._set_slider(pr.layer)  # the slider shows the printed layer (disabled meanwhile)
            self._update_layer_label()
            self.progress_reported.emit(pr)
        if ev.text:
            self.print_label.setText(ev.text)
        if ev.finished:
            self._print_done(ev)

    def _print_done(self, ev) -> None:
        self.send_button.setEnabled(self.session.result is not None)
        self.resume_button.setEnabled(self.session.saved_job is not None)
        self.slice_button.setEnabled(True)
        self.pause_button.setEnabled(False)
        self.pause_button.setText("Pause")
        self.cancel_print_button.setEnabled(False)
        self.layer_slider.setEnabled(self.preview_check.isEnabled())
        self._set_slider(self._slider_before_print)
        self.session.preview_layer = self.preview_layer  # the preview goes back to the slider's layer
        self._update_layer_label()
        self.print_finished.emit(ev)

    def toggle_pause(self) -> None:
        did = self.session.toggle_pause()
        if did == "resumed":
            self.pause_button.setText("Pause")
            self.print_label.setText("Resuming...")
        elif did == "paused":
            self.pause_button.setText("Resume")
            self.print_label.setText("Pausing after the lines in flight (heaters stay on)...")

    def cancel_print(self) -> None:
        if self.session.printing:
            self.session.cancel_print()
            self.pause_button.setEnabled(False)
            self.print_label.setText("Cancelling (heaters off, nozzle lifted)...")

    def done(self, r: int) -> None:  # noqa: D401 - Qt's name
        if self.session.slicing:
            self.session.cancel_slice()
        self._save_settings()
        if not self.session.printing and self.preview_check.isChecked():
            self.preview_check.setChecked(False)  # closing the dialog ends the preview (not a running print's)
        super().done(r)
