"""The print dialog: the model as placed on screen -> slice (worker thread, progress, cancel) -> preview the
toolpaths on the real printer bed in the AR view (layer slider, build-area warning) -> save the G-code or
send it to a printer (serial port or OctoPrint) with progress, layer, ETA, temperatures, pause/resume/cancel.

The dialog never talks to the live view's engine itself: it emits
`preview_changed(spec | None)` (arapp.gui.toolpaths.preview_spec) and
`progress_reported(Progress)`; the main window forwards the spec to the engine.
During a print the spec's `current` layer follows the link's progress reports.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path

from PySide6.QtCore import QPointF, QStandardPaths, Qt, Signal
from PySide6.QtGui import QColor, QPainter, QPen, QPolygonF
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDialog,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QRadioButton,
    QSlider,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from arapp.gui import printlink
from arapp.gui.tasks import Task, on_ui

OTHER_PROFILE = "Other profile file..."


class TemperatureGraph(QWidget):
    """Hotend and bed temperatures (actual solid, target dashed) over the last few minutes."""

    SERIES = {"hotend": QColor(230, 90, 40), "bed": QColor(60, 130, 230)}

    def __init__(self, span_s: float = 300.0, parent=None):
        super().__init__(parent)
        self.span_s = span_s
        self.samples: deque = deque(maxlen=2000)  # (t, {name: (actual, target)})
        self.setMinimumHeight(110)

    def add(self, temps: dict, t: float | None = None) -> None:
        """temps: {"hotend": (actual, target), "bed": (actual, target)} in degrees C (missing keys allowed,
        a target may be None)."""
        if not temps:
            return
        t = time.monotonic() if t is None else t
        if self.samples and t - self.samples[-1][0] < 0.5 and self.samples[-1][1] == temps:
            return  # the link reports up to 10 times a second; unchanged readings add nothing
        self.samples.append((t, dict(temps)))
        self.update()

    def clear(self) -> None:
        self.samples.clear()
        self.update()

    def paintEvent(self, event):  # noqa: N802
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(250, 250, 252))
        p.setPen(QColor(200, 200, 205))
        p.drawRect(self.rect().adjusted(0, 0, -1, -1))
        if not self.samples:
            p.setPen(QColor(120, 120, 130))
            p.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter, "temperatures appear while printing")
            return
        t_end = self.samples[-1][0]
        # the time axis spans the samples so far, up to span_s (a fresh print fills the width)
        span = max(1.0, min(self.span_s, t_end - self.samples[0][0]))
        values = [v for _, d in self.samples for pair in d.values() for v in pair if v is not None]
        top = max(50.0, max(values) * 1.1 if values else 50.0)
        w, h = self.width() - 40, self.height() - 8

        def xy(t, v):
            return QPointF(36 + w * (1 - (t_end - t) / span), 4 + h * (1 - v / top))

        p.setPen(QColor(120, 120, 130))
        p.drawText(2, 14, f"{top:.0f}")
        p.drawText(2, self.height() - 4, "0 °C")
        for name, colour in self.SERIES.items():
            for k, style in ((0, Qt.PenStyle.SolidLine), (1, Qt.PenStyle.DashLine)):
                pts = [xy(t, d[name][k]) for t, d in self.samples
                       if name in d and d[name][k] is not None and t_end - t <= span]
                if len(pts) >= 2:
                    p.setPen(QPen(colour, 1.6, style))
                    p.drawPolyline(QPolygonF(pts))
        last = self.samples[-1][1]
        text = "   ".join(f"{n} {a:.0f}" + (f"/{tg:.0f}" if tg is not None else "") + " °C"
                           for n, (a, tg) in last.items() if a is not None)
        p.setPen(QColor(40, 40, 50))
        p.drawText(40, 16, text)


KEEP_SLICES = 10


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


class PrintDialog(QDialog):
    """Slice and print the model as displayed. `error(title, message)` reports failures to the window.

    model: the displayed arapp.geometry Model (with edits applied); placement:
    dict with size_mm, offset, rotation_deg as on screen (arapp.placement.placement_from_any).
    """

    error = Signal(str, str)
    sliced = Signal(object)
    solid_ready = Signal(object)
    preview_changed = Signal(object)  # arapp.gui.toolpaths.preview_spec dict, or None: no preview
    progress_reported = Signal(object)  # arapp.printing.link.Progress, on the UI thread
    print_finished = Signal(object)  # the final printlink.PrintEvent

    def __init__(self, model, placement: dict | None, settings=None, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Print")
        self.setModal(False)
        self.resize(560, 640)
        self.model = model
        self.placement = dict(placement or {})
        self.settings = settings
        self.solid = None
        self.result = None
        self.gcode_path: str | None = None  # where the user saved the G-code
        self.job_gcode_path: str | None = None  # the copy the preview and the printer job read
        self.summary = None  # arapp.gui.toolpaths.PreviewSummary of the sliced G-code
        self.sliced_profile: str | None = None  # profile name or path the G-code was sliced for
        self.work_dir = Path(QStandardPaths.writableLocation(QStandardPaths.StandardLocation.AppDataLocation)
                             or Path.home() / ".arapp") / "print-jobs"
        self._slice_task: Task | None = None
        self._job = None
        self.current_layer = -1  # the layer being printed, from the link's reports
        self.last_progress = None
        self.preview_gen = 0
        self.preview_spec: dict | None = None

        from arapp.printing import MATERIALS
        from arapp.printing.profile import shipped_profiles

        lay = QVBoxLayout(self)
        name = getattr(model, "name", "model")
        self.model_label = QLabel(f"<b>{name}</b>, {self.placement.get('size_mm', 50):g} mm as placed on the anchor")
        self.solid_label = QLabel("Preparing the printable solid...")
        lay.addWidget(self.model_label)
        lay.addWidget(self.solid_label)

        box = QGroupBox("Slicing")
        form = QFormLayout(box)
        self.profile = QComboBox()
        self.profile.addItems(shipped_profiles())
        self.profile.addItem(OTHER_PROFILE)
        self.profile.activated.connect(self._profile_activated)
        self._profile_path: str | None = None
        self.material = QComboBox()
        self.material.addItems(list(MATERIALS))
        self.layer_height = QDoubleSpinBox()
        self.layer_height.setRange(0.05, 0.6)
        self.layer_height.setSingleStep(0.05)
        self.layer_height.setDecimals(2)
        self.layer_height.setSuffix(" mm")
        self.infill = QSpinBox()
        self.infill.setRange(0, 100)
        self.infill.setSuffix(" %")
        self.perimeters = QSpinBox()
        self.perimeters.setRange(1, 10)
        form.addRow("Printer", self.profile)
        form.addRow("Material", self.material)
        form.addRow("Layer height", self.layer_height)
        form.addRow("Infill", self.infill)
        form.addRow("Perimeters", self.perimeters)
        row = QHBoxLayout()
        self.slice_button = QPushButton("Slice")
        self.slice_button.clicked.connect(self.start_slice)
        self.cancel_slice_button = QPushButton("Cancel")
        self.cancel_slice_button.setEnabled(False)
        self.cancel_slice_button.clicked.connect(self.cancel_slice)
        self.save_button = QPushButton("Save G-code...")
        self.save_button.setEnabled(False)
        self.save_button.clicked.connect(self.save_gcode)
        for b in (self.slice_button, self.cancel_slice_button, self.save_button):
            row.addWidget(b)
        form.addRow(row)
        self.slice_progress = QProgressBar()
        self.slice_progress.setRange(0, 1000)
        self.slice_progress.setValue(0)
        form.addRow(self.slice_progress)
        self.slice_label = QLabel("")
        self.slice_label.setWordWrap(True)
        form.addRow(self.slice_label)
        lay.addWidget(box)

        prev = QGroupBox("Print preview on the bed (AR view)")
        pf = QVBoxLayout(prev)
        self.preview_check = QCheckBox("Show the toolpaths on the printer bed")
        self.preview_check.setEnabled(False)
        self.preview_check.toggled.connect(self._preview_toggled)
        pf.addWidget(self.preview_check)
        lrow = QHBoxLayout()
        self.layer_slider = QSlider(Qt.Orientation.Horizontal)
        self.layer_slider.setRange(0, 0)
        self.layer_slider.setEnabled(False)
        self.layer_slider.valueChanged.connect(self._layer_changed)
        self.layer_label = QLabel("slice first")
        self.layer_label.setMinimumWidth(170)
        lrow.addWidget(QLabel("Layer"))
        lrow.addWidget(self.layer_slider, 1)
        lrow.addWidget(self.layer_label)
        pf.addLayout(lrow)
        self.preview_warning = QLabel("")
        self.preview_warning.setWordWrap(True)
        self.preview_warning.setStyleSheet("color: #c01010; font-weight: bold")
        self.preview_warning.setVisible(False)
        pf.addWidget(self.preview_warning)
        lay.addWidget(prev)

        send = QGroupBox("Send to printer")
        sf = QFormLayout(send)
        self.use_serial = QRadioButton("USB serial")
        self.use_serial.setChecked(True)
        self.port = QComboBox()
        self.port.setEditable(True)
        self.baud = QComboBox()
        self.baud.setEditable(True)
        self.baud.addItems(["115200", "250000", "57600"])
        ports = QHBoxLayout()
        ports.addWidget(self.port, 1)
        ports.addWidget(self.baud)
        refresh = QPushButton("Refresh")
        refresh.clicked.connect(self.refresh_ports)
        ports.addWidget(refresh)
        sf.addRow(self.use_serial, ports)
        self.use_octoprint = QRadioButton("OctoPrint")
        self.octoprint_url = QLineEdit()
        self.octoprint_url.setPlaceholderText("http://octopi.local")
        self.api_key_file = QLineEdit()
        self.api_key_file.setPlaceholderText("file holding the API key (mode 600)")
        sf.addRow(self.use_octoprint, self.octoprint_url)
        sf.addRow("API key file", self.api_key_file)
        row2 = QHBoxLayout()
        self.send_button = QPushButton("Print")
        self.send_button.setEnabled(False)
        self.send_button.clicked.connect(self.start_print)
        self.pause_button = QPushButton("Pause")
        self.pause_button.setEnabled(False)
        self.pause_button.clicked.connect(self.toggle_pause)
        self.cancel_print_button = QPushButton("Cancel print")
        self.cancel_print_button.setEnabled(False)
        self.cancel_print_button.clicked.connect(self.cancel_print)
        row2.addWidget(self.send_button)
        row2.addWidget(self.pause_button)
        row2.addWidget(self.cancel_print_button)
        sf.addRow(row2)
        self.print_progress = QProgressBar()
        self.print_progress.setRange(0, 1000)
        self.print_progress.setFormat("%p %")
        sf.addRow(self.print_progress)
        stats = QHBoxLayout()
        self.percent_label = QLabel("")
        self.print_layer_label = QLabel("")
        self.eta_label = QLabel("")
        for w in (self.percent_label, self.print_layer_label, self.eta_label):
            stats.addWidget(w, 1)
        sf.addRow(stats)
        self.print_label = QLabel("")
        self.print_label.setWordWrap(True)
        sf.addRow(self.print_label)
        self.temps = TemperatureGraph()
        sf.addRow(self.temps)
        lay.addWidget(send)

        self._restore()
        self.refresh_ports()
        self._start_solid()

    # -- settings ----------------------------------------------------------------------
    def _restore(self) -> None:
        s = self.settings
        get = (lambda k, d: s.value(f"print/{k}", d)) if s is not None else (lambda k, d: d)
        idx = self.profile.findText(str(get("profile", "generic")))
        if idx >= 0:
            self.profile.setCurrentIndex(idx)
        self.material.setCurrentText(str(get("material", "PLA")))
        self.layer_height.setValue(float(get("layer_height", 0.2)))
        self.infill.setValue(int(float(get("infill", 20))))
        self.perimeters.setValue(int(float(get("perimeters", 2))))
        self.octoprint_url.setText(str(get("octoprint_url", "")))
        self.api_key_file.setText(str(get("api_key_file", "")))
        if str(get("link", "serial")) == "octoprint":
            self.use_octoprint.setChecked(True)

    def _save_settings(self) -> None:
        if self.settings is None:
            return
        for k, v in (("profile", self.profile.currentText()), ("material", self.material.currentText()),
                     ("layer_height", self.layer_height.value()), ("infill", self.infill.value()),
                     ("perimeters", self.perimeters.value()), ("octoprint_url", self.octoprint_url.text()),
                     ("api_key_file", self.api_key_file.text()),
                     ("link", "octoprint" if self.use_octoprint.isChecked() else "serial")):
            self.settings.setValue(f"print/{k}", v)

    def _profile_activated(self, index: int) -> None:
        if self.profile.itemText(index) == OTHER_PROFILE:
            path, _ = QFileDialog.getOpenFileName(self, "Printer profile", str(Path.cwd()), "Printer profile (*.json)")
            if path:
                self._profile_path = path
                self.profile.insertItem(0, path)
                self.profile.setCurrentIndex(0)
            else:
                self.profile.setCurrentIndex(0)

    def set_profile_path(self, path: str) -> None:
        """Use the printer profile file at `path` (as 'Other profile file...' does)."""
        path = str(path)
        idx = self.profile.findText(path)
        if idx < 0:
            self.profile.insertItem(0, path)
            idx = 0
        self._profile_path = path
        self.profile.setCurrentIndex(idx)

    def load_profile(self):
        from arapp.printing import load_profile

        name = self.profile.currentText()
        return load_profile(name)

    def slice_settings(self):
        from arapp.printing import SliceSettings

        return SliceSettings(material=self.material.currentText(), layer_height=self.layer_height.value(),
                             first_layer_height=max(self.layer_height.value(), 0.2),
                             infill=float(self.infill.value()), perimeters=self.perimeters.value())

    # -- the printable solid -------------------------------------------------------------
    def model_to_placement_mm(self):
        """4x4 from model units to the anchor's placement frame in millimetres, exactly as displayed."""
        from arapp.placement import placement_from_any

        self.model.placement = placement_from_any(self.placement, self.model.placement)
        return self.model.placement_matrix("mm")

    def _start_solid(self) -> None:
        from arapp.printing import placed_solid

        model, matrix = self.model, self.model_to_placement_mm()
        self._solid_task = Task(placed_solid, model, matrix, done=self._solid_done,
                                failed=lambda e: self._fail("Cannot make a printable solid", e),
                                name="arapp-solid", owner=self).start()

    def _solid_done(self, solid) -> None:
        self.solid = solid
        x, y, z = solid.extents
        self.solid_label.setText(f"Printable solid: {x:.1f} x {y:.1f} x {z:.1f} mm, {len(solid.faces)} triangles"
                                 + (", watertight" if solid.is_watertight else ""))
        self.solid_ready.emit(solid)

    def _fail(self, title: str, exc: BaseException) -> None:
        self.error.emit(title, str(exc) or type(exc).__name__)

    # -- slicing -------------------------------------------------------------------------
    def start_slice(self) -> None:
        from arapp.printing import slice_mesh

        try:
            settings = self.slice_settings()
            profile = self.load_profile()
        except (ValueError, OSError) as exc:
            self._fail("Cannot slice", exc)
            return
        self._save_settings()
        self.result = None
        self.save_button.setEnabled(False)
        self.send_button.setEnabled(False)
        self.slice_button.setEnabled(False)
        self.cancel_slice_button.setEnabled(True)
        self.slice_progress.setValue(0)
        self.slice_label.setText("Slicing...")
        model, matrix = self.model, self.model_to_placement_mm()
        cancel = threading.Event()
        profile_name = self.profile.currentText()
        stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in str(getattr(model, "name", "model")))
        job_gcode = self.work_dir / f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}.gcode"

        def work():
            from arapp.printing import placed_solid

            solid = placed_solid(model, matrix, profile=profile)
            last = [0.0]

            def progress(f):
                now = time.perf_counter()
                if now - last[0] > 0.05 or f >= 1.0:  # at most 20 updates a second
                    last[0] = now
                    on_ui(self._slice_progress, f, self)

            result = slice_mesh(solid, settings, profile, progress=progress, cancel=cancel)
            # The copy the preview (in the pipeline process) and the printer job read; written here, off the UI
            # thread, with the summary the dialog shows (layers, moves outside the build area).
            from arapp.gui.toolpaths import summarize
            from arapp.printing.gcode import parse_gcode

            job_gcode.parent.mkdir(parents=True, exist_ok=True)
            job_gcode.write_text(result.gcode)
            prune_slices(job_gcode.parent)
            summary = summarize(parse_gcode(result.gcode), profile.bed)
            return result, str(job_gcode), summary, profile, profile_name

        self._slice_task = Task(work, done=self._slice_done, failed=self._slice_failed, name="arapp-slice",
                                owner=self)
        self._slice_task.cancel = cancel
        self._slice_task.start()

    def _slice_progress(self, fraction: float) -> None:
        self.slice_progress.setValue(int(1000 * max(0.0, min(1.0, fraction))))

    def cancel_slice(self) -> None:
        if self._slice_task is not None:
            self._slice_task.cancel.set()
            self.slice_label.setText("Cancelling...")

    def _slice_finished(self) -> None:
        self.slice_button.setEnabled(True)
        self.cancel_slice_button.setEnabled(False)

    def _slice_done(self, done) -> None:
        from arapp.printing.gcode import format_duration

        result, self.job_gcode_path, self.summary, profile, self.sliced_profile = done
        self._slice_finished()
        self.result = result
        self.slice_progress.setValue(1000)
        scale = f", scaled by {result.scale:.3f} to fit" if abs(result.scale - 1) > 1e-9 else ""
        self.slice_label.setText(f"{result.layers} layers, about {format_duration(result.print_time_s)}, "
                                 f"{result.filament_mm / 1000:.2f} m of filament ({result.filament_g:.1f} g){scale}")
        self.save_button.setEnabled(True)
        self.send_button.setEnabled(self._job is None)
        self._setup_preview(profile)
        self.sliced.emit(result)

    def _slice_failed(self, exc: BaseException) -> None:
        from arapp.printing import SliceCancelled

        self._slice_finished()
        self.slice_progress.setValue(0)
        if isinstance(exc, SliceCancelled):
            self.slice_label.setText("Slicing cancelled")
            return
        self.slice_label.setText(f"Slicing failed: {exc}")
        self._fail("Slicing failed", exc)

    def save_gcode(self, path: str | None = None) -> str | None:
        if self.result is None:
            return None
        if not path:
            default = str(Path.cwd() / f"{getattr(self.model, 'name', 'model')}.gcode".replace(" ", "_"))
            path, _ = QFileDialog.getSaveFileName(self, "Save G-code", default, "G-code (*.gcode)")
        if not path:
            return None
        try:
            Path(path).write_text(self.result.gcode)
        except OSError as exc:
            self._fail("Cannot save the G-code", exc)
            return None
        self.gcode_path = path
        self.slice_label.setText(self.slice_label.text() + f"\nSaved {path}")
        return path

    # -- the print preview on the bed ------------------------------------------------------
    def _setup_preview(self, profile) -> None:
        """After slicing: the layer slider spans the layers (its last position: all layers), warnings shown."""
        n = self.summary.layers if self.summary is not None else 0
        self.layer_slider.blockSignals(True)
        self.layer_slider.setRange(0, max(0, n))  # 0..n-1: one layer; n: all layers
        self.layer_slider.setValue(n)
        self.layer_slider.blockSignals(False)
        warnings = []
        if self.summary is not None:
            w = self.summary.warning(profile.bed)
            if w:
                warnings.append(w)
        if profile.bed_from_anchor is None:
            warnings.append(f"The printer profile {profile.source} has no bed anchor: the preview cannot be placed "
                            "on the bed (add bed_anchor to the profile, see PRINTER_PROFILE.md).")
        self.preview_warning.setText("\n".join(warnings))
        self.preview_warning.setVisible(bool(warnings))
        can = n > 0 and profile.bed_from_anchor is not None
        self.preview_check.setEnabled(can)
        self.layer_slider.setEnabled(can and self._job is None)
        self._update_layer_label()
        if self.preview_check.isChecked():
            self._emit_preview()

    @property
    def preview_layer(self) -> int | None:
        """The slider's layer (0-based), None for all layers."""
        v = self.layer_slider.value()
        return None if v >= self.layer_slider.maximum() else v

    def _update_layer_label(self) -> None:
        s = self.summary
        if s is None or not s.layers:
            self.layer_label.setText("slice first")
            return
        if self.current_layer >= 0 and self._job is not None:
            k = min(self.current_layer, s.layers - 1)
            self.layer_label.setText(f"printing layer {k + 1} / {s.layers}, z {s.z[k]:.2f} mm")
            return
        k = self.preview_layer
        if k is None:
            self.layer_label.setText(f"all {s.layers} layers")
        else:
            self.layer_label.setText(f"layer {k + 1} / {s.layers}, z {s.z[k]:.2f} mm")

    def _preview_toggled(self, on: bool) -> None:
        if on:
            self._emit_preview()
        else:
            self._set_preview(None)

    def _layer_changed(self, _value: int) -> None:
        self._update_layer_label()
        if self.preview_check.isChecked():
            self._emit_preview()

    def _emit_preview(self) -> None:
        from arapp.gui.toolpaths import preview_spec

        if self.job_gcode_path is None:
            return
        current = self.current_layer if (self._job is not None and self.current_layer >= 0) else None
        self._set_preview(preview_spec(self.job_gcode_path, self.sliced_profile, self.preview_layer, current))

    def _set_preview(self, spec: dict | None) -> None:
        self.preview_gen += 1
        if spec is not None:
            spec["gen"] = self.preview_gen
        self.preview_spec = spec
        self.preview_changed.emit(spec)

    def preview_shown(self, info: dict) -> None:
        """The live view drew the preview `info` (arapp.gui.toolpaths); called by the main window."""
        if info.get("outside") and not self.preview_warning.isVisible():
            self.preview_warning.setText("Toolpaths leave the build area (drawn red on the bed).")
            self.preview_warning.setVisible(True)

    # -- printing --------------------------------------------------------------------------
    def refresh_ports(self) -> None:
        current = self.port.currentText()
        self.port.clear()
        self.port.addItems(printlink.serial_ports())
        if current:
            self.port.setCurrentText(current)

    def target(self):
        """The printer chosen in the dialog (printlink.SerialTarget or OctoPrintTarget)."""
        if self.use_octoprint.isChecked():
            return printlink.OctoPrintTarget(self.octoprint_url.text().strip(), self.api_key_file.text().strip())
        text = self.baud.currentText()
        try:
            baud = int(text)
        except ValueError:
            raise ValueError(f"baud rate must be a whole number, got {text!r}") from None
        return printlink.SerialTarget(self.port.currentText().strip(), baud)

    def start_print(self) -> None:
        if self.result is None or self._job is not None:
            return
        self._save_settings()
        gcode = self.result.gcode
        job_path = None
        if self.job_gcode_path is not None:
            job_path = str(Path(self.job_gcode_path).with_suffix(".printjob.json"))
        try:
            target = self.target()
            profile = self.load_profile()
            self._job = printlink.start_job(target, gcode, profile, self._print_event, job_path=job_path,
                                            gcode_path=self.job_gcode_path or "")
        except (ValueError, OSError, RuntimeError) as exc:
            self._fail("Printer error", exc)
            return
        self.current_layer = -1
        self.last_progress = None
        self.temps.clear()
        self.print_progress.setValue(0)
        self.percent_label.setText("0.0 %")
        self.print_layer_label.setText("")
        self.eta_label.setText("")
        self.send_button.setEnabled(False)
        self.slice_button.setEnabled(False)
        self.pause_button.setEnabled(True)
        self.pause_button.setText("Pause")
        self.cancel_print_button.setEnabled(True)
        self._slider_before_print = self.layer_slider.value()
        self.layer_slider.setEnabled(False)
        self.print_label.setText("Connecting...")
        if self.preview_check.isEnabled() and not self.preview_check.isChecked():
            self.preview_check.setChecked(True)  # show the print's progress on the bed

    def _print_event(self, event: printlink.PrintEvent) -> None:
        """Called from the link's thread; forwarded to the UI thread."""
        on_ui(self._show_print_event, event, self)

    def _show_print_event(self, ev: printlink.PrintEvent) -> None:
        pr = ev.progress
        if pr is not None:
            self.last_progress = pr
            self.print_progress.setValue(int(round(10 * max(0.0, min(100.0, pr.percent)))))
            self.percent_label.setText(f"{pr.percent:.1f} %")
            self.print_layer_label.setText(printlink.layer_text(pr))
            self.eta_label.setText(f"ETA {printlink.format_duration_s(pr.eta_s)}" if pr.eta_s is not None else "")
            self.temps.add(printlink.temperatures(pr))
            if pr.layer != self.current_layer:
                # the highlight follows the printer's acknowledged lines, as the link reports them
                self.current_layer = pr.layer
                if pr.layer >= 0:
                    self.layer_slider.blockSignals(True)  # the slider shows the printed layer (disabled meanwhile)
                    self.layer_slider.setValue(min(pr.layer, self.layer_slider.maximum()))
                    self.layer_slider.blockSignals(False)
                self._update_layer_label()
                if self.preview_check.isChecked() and pr.layer >= 0 and self._job is not None:
                    self._emit_preview()
            self.progress_reported.emit(pr)
        if ev.text:
            self.print_label.setText(ev.text)
        if ev.error:
            message = ev.error
            if ev.job_path and str(ev.job_path) not in message:
                message += f"\n\nThe job state is saved in {ev.job_path}; resume with: arapp print --resume {ev.job_path}"
            self._fail(ev.error_title or "Printer error", RuntimeError(message))
        if ev.finished:
            self._job = None
            self.send_button.setEnabled(self.result is not None)
            self.slice_button.setEnabled(True)
            self.pause_button.setEnabled(False)
            self.pause_button.setText("Pause")
            self.cancel_print_button.setEnabled(False)
            self.layer_slider.setEnabled(self.preview_check.isEnabled())
            self.layer_slider.blockSignals(True)
            self.layer_slider.setValue(getattr(self, "_slider_before_print", self.layer_slider.maximum()))
            self.layer_slider.blockSignals(False)
            if self.preview_check.isChecked():
                self._emit_preview()  # back to the slider's layer
            self._update_layer_label()
            self.print_finished.emit(ev)

    def toggle_pause(self) -> None:
        job = self._job
        if job is None:
            return
        if job.paused:
            job.resume()
            self.pause_button.setText("Pause")
            self.print_label.setText("Resuming...")
        else:
            job.pause()
            self.pause_button.setText("Resume")
            self.print_label.setText("Pausing after the lines in flight (heaters stay on)...")

    def cancel_print(self) -> None:
        if self._job is not None:
            self._job.cancel()
            self.pause_button.setEnabled(False)
            self.print_label.setText("Cancelling (heaters off, nozzle lifted)...")

    @property
    def printing(self) -> bool:
        return self._job is not None

    def done(self, r: int) -> None:  # noqa: D401 - Qt's name
        if self._slice_task is not None and self._slice_task.running:
            self._slice_task.cancel.set()
        self._save_settings()
        if self._job is None and self.preview_check.isChecked():
            self.preview_check.setChecked(False)  # closing the dialog ends the preview (not a running print's)
        super().done(r)
