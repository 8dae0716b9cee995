"""The print dialog's widget groups, built onto the dialog (its slots and attributes), and its settings.

Each `*_box(dialog)` makes one QGroupBox and sets its widgets as attributes of
the dialog, so the dialog (arapp/gui/print/dialog.py) keeps to binding them to
the print session.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit, QProgressBar,
    QPushButton, QRadioButton, QSlider, QSpinBox, QVBoxLayout,
)

from arapp.app.print_session import SLICERS
from arapp.gui.print.temperature_graph import TemperatureGraph
from arapp.printing import MATERIALS
from arapp.printing.printers import printer_choices

OTHER_PROFILE = "Other profile file..."


def _button(text: str, slot, enabled: bool = True) -> QPushButton:
    b = QPushButton(text)
    b.clicked.connect(slot)
    b.setEnabled(enabled)
    return b


def _spin(box, lo, hi, suffix="", step=None, decimals=None):
    box.setRange(lo, hi)
    if step is not None:
        box.setSingleStep(step)
    if decimals is not None:
        box.setDecimals(decimals)
    if suffix:
        box.setSuffix(suffix)
    return box


def slicing_box(dlg) -> QGroupBox:
    """The Slicing group: printer profile, material, layer height, infill, perimeters, Slice/Cancel/Save,
    progress; its widgets become attributes of the dialog `dlg`."""
    box = QGroupBox("Slicing")
    form = QFormLayout(box)
    dlg.profile = QComboBox()
    for label, key in printer_choices():
        dlg.profile.addItem(label, key)
    dlg.profile.addItem(OTHER_PROFILE, OTHER_PROFILE)
    dlg.profile.activated.connect(dlg.profile_activated)
    dlg.material = QComboBox()
    dlg.material.addItems(list(MATERIALS))
    dlg.layer_height = _spin(QDoubleSpinBox(), 0.05, 0.6, " mm", step=0.05, decimals=2)
    dlg.infill = _spin(QSpinBox(), 0, 100, " %")
    dlg.perimeters = _spin(QSpinBox(), 1, 10)
    dlg.slicer = QComboBox()
    dlg.slicer.addItems(list(SLICERS))
    for label, w in (("Printer", dlg.profile), ("Material", dlg.material), ("Layer height", dlg.layer_height),
                     ("Infill", dlg.infill), ("Perimeters", dlg.perimeters), ("Slicer", dlg.slicer)):
        form.addRow(label, w)
    row = QHBoxLayout()
    dlg.slice_button = _button("Slice", dlg.start_slice)
    dlg.cancel_slice_button = _button("Cancel", dlg.cancel_slice, False)
    dlg.save_button = _button("Save G-code...", dlg.save_gcode, False)
    for b in (dlg.slice_button, dlg.cancel_slice_button, dlg.save_button):
        row.addWidget(b)
    form.addRow(row)
    dlg.slice_progress = QProgressBar()
    dlg.slice_progress.setRange(0, 1000)
    dlg.slice_progress.setValue(0)
    form.addRow(dlg.slice_progress)
    dlg.slice_label = QLabel("")
    dlg.slice_label.setWordWrap(True)
    form.addRow(dlg.slice_label)
    return box

def preview_box(dlg) -> QGroupBox:
    """The bed preview group: show toggle, layer slider and label, build-area warning."""
    prev = QGroupBox("Print preview on the bed (AR view)")
    pf = QVBoxLayout(prev)
    dlg.preview_check = QCheckBox("Show the toolpaths on the printer bed")
    dlg.preview_check.setEnabled(False)
    dlg.preview_check.toggled.connect(dlg.preview_toggled)
    pf.addWidget(dlg.preview_check)
    dlg.ghost_note = QLabel("While the toolpaths stand on the bed, the model on its marker is drawn see-through.")
    dlg.ghost_note.setWordWrap(True)
    dlg.ghost_note.setStyleSheet("color: #555")
    dlg.ghost_note.setVisible(False)
    dlg.preview_check.toggled.connect(dlg.ghost_note.setVisible)
    pf.addWidget(dlg.ghost_note)
    dlg.placement_note = QLabel("")  # where the toolpaths stand: on the bed marker, or where the model is
    dlg.placement_note.setWordWrap(True)
    dlg.placement_note.setVisible(False)
    pf.addWidget(dlg.placement_note)
    lrow = QHBoxLayout()
    dlg.layer_slider = QSlider(Qt.Orientation.Horizontal)
    dlg.layer_slider.setRange(0, 0)
    dlg.layer_slider.setEnabled(False)
    dlg.layer_slider.valueChanged.connect(dlg.layer_changed)
    dlg.layer_label = QLabel("slice first")
    dlg.layer_label.setMinimumWidth(170)
    lrow.addWidget(QLabel("Layer"))
    lrow.addWidget(dlg.layer_slider, 1)
    lrow.addWidget(dlg.layer_label)
    pf.addLayout(lrow)
    dlg.preview_warning = QLabel("")
    dlg.preview_warning.setWordWrap(True)
    dlg.preview_warning.setStyleSheet("color: #c01010; font-weight: bold")
    dlg.preview_warning.setVisible(False)
    pf.addWidget(dlg.preview_warning)
    return prev

def send_box(dlg) -> QGroupBox:
    """The printer group: serial port and baud, or an OctoPrint or Moonraker URL and key file, Print/Pause/Cancel, progress,
    layer, ETA, the printer's message and the temperature graph."""
    send = QGroupBox("Send to printer")
    sf = QFormLayout(send)
    dlg.use_serial = QRadioButton("USB serial")
    dlg.use_serial.setChecked(True)
    dlg.port = QComboBox()
    dlg.port.setEditable(True)
    dlg.baud = QComboBox()
    dlg.baud.setEditable(True)
    dlg.baud.addItems(["115200", "250000", "57600"])
    ports = QHBoxLayout()
    ports.addWidget(dlg.port, 1)
    ports.addWidget(dlg.baud)
    ports.addWidget(_button("Refresh", dlg.refresh_ports))
    sf.addRow(dlg.use_serial, ports)
    dlg.use_octoprint = QRadioButton("OctoPrint")
    dlg.octoprint_url = QLineEdit()
    dlg.octoprint_url.setPlaceholderText("http://octopi.local")
    dlg.api_key_file = QLineEdit()
    dlg.api_key_file.setPlaceholderText("file holding the API key (mode 600)")
    sf.addRow(dlg.use_octoprint, dlg.octoprint_url)
    dlg.use_moonraker = QRadioButton("Klipper (Moonraker)")
    dlg.moonraker_url = QLineEdit()
    dlg.moonraker_url.setPlaceholderText("http://mainsailos.local:7125")
    sf.addRow(dlg.use_moonraker, dlg.moonraker_url)
    # one key field for both servers: Moonraker's is optional (none for its trusted clients)
    sf.addRow("API key file", dlg.api_key_file)
    row2 = QHBoxLayout()
    dlg.send_button = _button("Print", dlg.start_print, False)
    dlg.pause_button = _button("Pause", dlg.toggle_pause, False)
    dlg.cancel_print_button = _button("Cancel print", dlg.cancel_print, False)
    for b in (dlg.send_button, dlg.pause_button, dlg.cancel_print_button):
        row2.addWidget(b)
    sf.addRow(row2)
    dlg.saved_job_label = QLabel("")
    dlg.saved_job_label.setWordWrap(True)
    dlg.saved_job_label.setStyleSheet("color: #a05000; font-weight: bold")
    dlg.resume_button = _button("Resume the stopped print...", dlg.resume_print)
    for w in (dlg.saved_job_label, dlg.resume_button):
        w.setVisible(False)
        sf.addRow(w)
    dlg.print_progress = QProgressBar()
    dlg.print_progress.setRange(0, 1000)
    dlg.print_progress.setFormat("0.0 %")
    sf.addRow(dlg.print_progress)
    stats = QHBoxLayout()
    dlg.percent_label, dlg.print_layer_label, dlg.eta_label = QLabel(""), QLabel(""), QLabel("")
    for w in (dlg.print_layer_label, dlg.eta_label):
        stats.addWidget(w, 1)
    dlg.percent_label.setVisible(False)  # the bar shows the percent; one figure, not two that round apart
    sf.addRow(stats)
    dlg.print_label = QLabel("")
    dlg.print_label.setWordWrap(True)
    sf.addRow(dlg.print_label)
    dlg.temps = TemperatureGraph()
    sf.addRow(dlg.temps)
    return send


def settings_values(dlg) -> dict:
    """The dialog's choices as stored under print/ in the settings."""
    return {"profile": dlg.profile_key(), "material": dlg.material.currentText(),
            "layer_height": dlg.layer_height.value(), "infill": dlg.infill.value(),
            "perimeters": dlg.perimeters.value(), "slicer": dlg.slicer.currentText(), "octoprint_url": dlg.octoprint_url.text(),
            "api_key_file": dlg.api_key_file.text(),
            "moonraker_url": dlg.moonraker_url.text(), "link": link_kind(dlg)}


def link_kind(dlg) -> str:
    """Which printer link the dialog's radio buttons choose: "serial", "octoprint" or "moonraker"."""
    if dlg.use_octoprint.isChecked():
        return "octoprint"
    return "moonraker" if dlg.use_moonraker.isChecked() else "serial"


def restore_settings(dlg, settings) -> None:
    """Set the dialog's widgets from the stored choices (defaults without settings)."""
    get = (lambda k, d: settings.value(f"print/{k}", d)) if settings is not None else (lambda k, d: d)
    key = str(get("profile", "generic"))
    idx = dlg.profile.findData(key)
    if idx < 0 and Path(key).is_file():
        dlg.set_profile_path(key)
    elif idx >= 0:
        dlg.profile.setCurrentIndex(idx)
    dlg.material.setCurrentText(str(get("material", "PLA")))
    dlg.layer_height.setValue(float(get("layer_height", 0.2)))
    dlg.infill.setValue(int(float(get("infill", 20))))
    dlg.perimeters.setValue(int(float(get("perimeters", 2))))
    dlg.slicer.setCurrentText(str(get("slicer", "built-in")))
    dlg.octoprint_url.setText(str(get("octoprint_url", "")))
    dlg.api_key_file.setText(str(get("api_key_file", "")))
    dlg.moonraker_url.setText(str(get("moonraker_url", "")))
    link = str(get("link", "serial"))
    if link == "octoprint":
        dlg.use_octoprint.setChecked(True)
    elif link == "moonraker":
        dlg.use_moonraker.setChecked(True)
