"""The print dialog: the model as placed on screen -> slice (worker thread, progress, cancel) -> save G-code
or send it to a printer (serial port or OctoPrint) with progress, temperatures and cancel."""

from __future__ import annotations

import threading
import time
from collections import deque
from pathlib import Path

from PySide6.QtCore import QPointF, Qt, Signal
from PySide6.QtGui import QColor, QPainter, QPen, QPolygonF
from PySide6.QtWidgets import (
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
        """temps: {"hotend": (actual, target), "bed": (actual, target)} in degrees C (missing keys allowed)."""
        self.samples.append((time.monotonic() if t is None else t, dict(temps)))
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
        values = [v for _, d in self.samples for pair in d.values() for v in pair if v is not None]
        top = max(50.0, max(values) * 1.1 if values else 50.0)
        w, h = self.width() - 40, self.height() - 8

        def xy(t, v):
            return QPointF(36 + w * (1 - (t_end - t) / self.span_s), 4 + h * (1 - v / top))

        p.setPen(QColor(120, 120, 130))
        p.drawText(2, 14, f"{top:.0f}")
        p.drawText(2, self.height() - 4, "0 °C")
        for name, colour in self.SERIES.items():
            for k, style in ((0, Qt.PenStyle.SolidLine), (1, Qt.PenStyle.DashLine)):
                pts = [xy(t, d[name][k]) for t, d in self.samples
                       if name in d and d[name][k] is not None and t_end - t <= self.span_s]
                if len(pts) >= 2:
                    p.setPen(QPen(colour, 1.6, style))
                    p.drawPolyline(QPolygonF(pts))
        last = self.samples[-1][1]
        text = "   ".join(f"{n} {a:.0f}/{tg:.0f} °C" for n, (a, tg) in last.items() if a is not None and tg is not None)
        p.setPen(QColor(40, 40, 50))
        p.drawText(40, 16, text)


class PrintDialog(QDialog):
    """Slice and print the model as displayed. `error(title, message)` reports failures to the window.

    model: the displayed arapp.geometry Model (with edits applied); placement:
    dict with size_mm, offset, rotation_deg as on screen (arapp.placement.placement_from_any).
    """

    error = Signal(str, str)
    sliced = Signal(object)
    solid_ready = Signal(object)

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
        self.gcode_path: str | None = None
        self._slice_task: Task | None = None
        self._job = None

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
        self.cancel_print_button = QPushButton("Cancel print")
        self.cancel_print_button.setEnabled(False)
        self.cancel_print_button.clicked.connect(self.cancel_print)
        row2.addWidget(self.send_button)
        row2.addWidget(self.cancel_print_button)
        sf.addRow(row2)
        self.print_progress = QProgressBar()
        self.print_progress.setRange(0, 1000)
        sf.addRow(self.print_progress)
        self.print_label = QLabel("")
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

        def work():
            from arapp.printing import placed_solid

            solid = placed_solid(model, matrix, profile=profile)
            last = [0.0]

            def progress(f):
                now = time.perf_counter()
                if now - last[0] > 0.05 or f >= 1.0:  # at most 20 updates a second
                    last[0] = now
                    on_ui(self._slice_progress, f, self)

            return slice_mesh(solid, settings, profile, progress=progress, cancel=cancel)

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

    def _slice_done(self, result) -> None:
        from arapp.printing.gcode import format_duration

        self._slice_finished()
        self.result = result
        self.slice_progress.setValue(1000)
        scale = f", scaled by {result.scale:.3f} to fit" if abs(result.scale - 1) > 1e-9 else ""
        self.slice_label.setText(f"{result.layers} layers, about {format_duration(result.print_time_s)}, "
                                 f"{result.filament_mm / 1000:.2f} m of filament ({result.filament_g:.1f} g){scale}")
        self.save_button.setEnabled(True)
        self.send_button.setEnabled(True)
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

    # -- printing --------------------------------------------------------------------------
    def refresh_ports(self) -> None:
        current = self.port.currentText()
        self.port.clear()
        self.port.addItems(printlink.serial_ports())
        if current:
            self.port.setCurrentText(current)

    def start_print(self) -> None:
        if self.result is None:
            return
        self._save_settings()
        if self.use_octoprint.isChecked():
            target = printlink.OctoPrintTarget(self.octoprint_url.text().strip(), self.api_key_file.text().strip())
        else:
            try:
                baud = int(self.baud.currentText())
            except ValueError:
                text = self.baud.currentText()
                self._fail("Cannot print", ValueError(f"baud rate must be a whole number, got {text!r}"))
                return
            target = printlink.SerialTarget(self.port.currentText().strip(), baud)
        try:
            profile = self.load_profile()
            self._job = printlink.start_job(target, self.result.gcode, profile, self._print_event)
        except (ValueError, OSError, RuntimeError) as exc:
            self._fail("Printer error", exc)
            return
        self.send_button.setEnabled(False)
        self.cancel_print_button.setEnabled(True)
        self.print_label.setText("Connecting...")

    def _print_event(self, event: printlink.PrintEvent) -> None:
        """Called from the link's thread; forwarded to the UI thread."""
        on_ui(self._show_print_event, event, self)

    def _show_print_event(self, ev) -> None:
        if ev.fraction is not None:
            self.print_progress.setValue(int(1000 * ev.fraction))
        if ev.temperatures:
            self.temps.add(ev.temperatures)
        if ev.text:
            self.print_label.setText(ev.text)
        if ev.finished:
            self.send_button.setEnabled(True)
            self.cancel_print_button.setEnabled(False)
            self._job = None
            if ev.error:
                self._fail("Printer error", RuntimeError(ev.error))

    def cancel_print(self) -> None:
        if self._job is not None:
            self._job.cancel()
            self.print_label.setText("Cancelling (heaters off, nozzle lifted)...")

    def done(self, r: int) -> None:  # noqa: D401 - Qt's name
        if self._slice_task is not None and self._slice_task.running:
            self._slice_task.cancel.set()
        self._save_settings()
        super().done(r)
