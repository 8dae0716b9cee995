"""The bed anchor set up in the GUI: which marker lies on the printer's bed and where, saved into the
printer profile by the same functions `arapp printer bed-anchor` uses (arapp.printing.bed_anchor).

Either the marker centre's bed X, Y (mm) and its turn about z (degrees), or the bed X/Y the printer
reports (M114) with the nozzle on the marker's bottom-left and bottom-right corners as printed. Lengths
are typed in millimetres; the profile keeps the marker side in metres, as every anchor does. A preset
has no file: the first bed anchor writes it to `<config>/printers/<preset>.json` and the set-up then
uses that file.
"""

from __future__ import annotations

import math
from pathlib import Path

from PySide6.QtWidgets import (
    QButtonGroup,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QRadioButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from arapp.store import user_config
from arapp.printing.bed_anchor import bed_from_anchor_measured, bed_from_anchor_touched, save_bed_anchor
from arapp.printing.presets import write_preset
from arapp.printing.profile import ProfileError, load_profile
from tracking.anchors.defaults import DEFAULT_DICTIONARY
from tracking.anchors.kinds.base import aruco_dictionary_names

DEFAULT = {"dictionary": DEFAULT_DICTIONARY, "id": 42, "length_mm": 40.0}  # as the CLI's defaults


def profile_file_for(profile_choice: str) -> Path:
    """The profile file a bed anchor is saved into: the chosen file, or a preset written out once to the
    user's config folder (kept when it exists: an earlier anchor or the user's edits stay)."""
    if profile_choice.startswith("preset:"):
        key = profile_choice[len("preset:"):]
        path = user_config.config_dir() / "printers" / f"{key}.json"
        if not path.exists():
            write_preset(key, path)
        return path
    return Path(profile_choice)


def _mm(lo: float, hi: float, value: float = 0.0, decimals: int = 1) -> QDoubleSpinBox:
    box = QDoubleSpinBox()
    box.setRange(lo, hi)
    box.setDecimals(decimals)
    box.setValue(value)
    box.setSuffix(" mm")
    return box


class BedAnchorDialog(QDialog):
    """Enter the bed marker for the profile `profile_choice` ("preset:KEY" or a profile file path);
    after Save, `saved_path` is the profile file written."""

    def __init__(self, profile_choice: str, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Bed marker")
        self.profile_choice = profile_choice
        self.saved_path: Path | None = None
        form = QFormLayout()
        self._add_marker_rows(form)
        self._add_where_rows(form)
        self._add_centre_rows(form)
        self._add_touch_rows(form)
        self.message = QLabel("")
        self.message.setWordWrap(True)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.save)
        buttons.rejected.connect(self.reject)
        self.save_button = buttons.button(QDialogButtonBox.StandardButton.Save)
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.message)
        lay.addWidget(buttons)
        self.centre_radio.toggled.connect(self._how_changed)
        self._prefill()
        self._how_changed()

    def _add_marker_rows(self, form) -> None:
        """Which marker: dictionary, id and printed side."""
        self.dictionary = QComboBox()
        for name in aruco_dictionary_names():
            self.dictionary.addItem(name)
        self.marker_id = QSpinBox()
        self.marker_id.setRange(0, 4999)
        self.length = _mm(1.0, 1000.0, DEFAULT["length_mm"])
        form.addRow("Dictionary", self.dictionary)
        form.addRow("Marker id", self.marker_id)
        form.addRow("Marker side", self.length)

    def _add_where_rows(self, form) -> None:
        """How its place is given: centre coordinates, or two corners touched with the nozzle."""
        self.centre_radio = QRadioButton("Marker centre on the bed")
        self.touch_radio = QRadioButton("Nozzle touched two corners")
        group = QButtonGroup(self)
        group.addButton(self.centre_radio)
        group.addButton(self.touch_radio)
        self.centre_radio.setChecked(True)
        row = QHBoxLayout()
        row.addWidget(self.centre_radio)
        row.addWidget(self.touch_radio)
        form.addRow("Where", row)

    def _add_centre_rows(self, form) -> None:
        """The marker's centre on the bed (mm) and its turn about z (degrees)."""
        self.centre_box = QWidget()
        cf = QFormLayout(self.centre_box)
        cf.setContentsMargins(0, 0, 0, 0)
        self.cx, self.cy = _mm(-1000, 1000), _mm(-1000, 1000)
        self.rotation = QDoubleSpinBox()
        self.rotation.setRange(-360.0, 360.0)
        self.rotation.setSuffix(" deg")
        crow = QHBoxLayout()
        crow.addWidget(self.cx)
        crow.addWidget(self.cy)
        cf.addRow("Centre X, Y", crow)
        cf.addRow("Turn about z", self.rotation)
        form.addRow(self.centre_box)

    def _add_touch_rows(self, form) -> None:
        """The nozzle's X, Y (mm) on the marker's bottom-left and bottom-right corners."""
        self.touch_box = QWidget()
        tf = QFormLayout(self.touch_box)
        tf.setContentsMargins(0, 0, 0, 0)
        self.x1, self.y1, self.x2, self.y2 = (_mm(-1000, 1000, decimals=2) for _ in range(4))
        for label, a, b in (("Bottom-left X, Y", self.x1, self.y1), ("Bottom-right X, Y", self.x2, self.y2)):
            r = QHBoxLayout()
            r.addWidget(a)
            r.addWidget(b)
            tf.addRow(label, r)
        hint = QLabel("Jog the nozzle onto each corner of the marker as printed and read X/Y from the printer "
                      "(M114).")
        hint.setWordWrap(True)
        tf.addRow(hint)
        form.addRow(self.touch_box)

    def _how_changed(self, *_args) -> None:
        self.centre_box.setVisible(self.centre_radio.isChecked())
        self.touch_box.setVisible(self.touch_radio.isChecked())

    def _profile(self):
        """The profile as it is now (None for a preset not written yet: the defaults apply)."""
        if self.profile_choice.startswith("preset:"):
            path = user_config.config_dir() / "printers" / f"{self.profile_choice[len('preset:'):]}.json"
            return load_profile(path) if path.exists() else None
        return load_profile(self.profile_choice)

    def _prefill(self) -> None:
        """The profile's bed anchor when it has one, else the CLI's defaults and the bed's middle."""
        self.dictionary.setCurrentText(DEFAULT["dictionary"])
        self.marker_id.setValue(DEFAULT["id"])
        try:
            profile = self._profile()
        except (ProfileError, OSError) as exc:
            self.message.setText(str(exc))
            return
        if profile is None:
            return
        self.cx.setValue(profile.bed.width / 2)
        self.cy.setValue(profile.bed.depth / 2)
        a, T = profile.bed_anchor, profile.bed_from_anchor
        if a is None or T is None:
            return
        self.dictionary.setCurrentText(a.dictionary)
        self.marker_id.setValue(int(a.id))
        self.length.setValue(1000.0 * float(a.length))
        self.cx.setValue(float(T[0, 3]))
        self.cy.setValue(float(T[1, 3]))
        self.rotation.setValue(math.degrees(math.atan2(T[1, 0], T[0, 0])))

    def bed_from_anchor(self):
        """4x4 bed_from_anchor (mm) of the fields; ValueError when the touched corners do not fit the side."""
        side_m = self.length.value() / 1000.0
        if self.touch_radio.isChecked():
            return bed_from_anchor_touched((self.x1.value(), self.y1.value()), (self.x2.value(), self.y2.value()),
                                           side_m)
        return bed_from_anchor_measured((self.cx.value(), self.cy.value()), self.rotation.value())

    def save(self) -> None:
        """Write the bed anchor into the profile (one line in the dialog when it cannot be)."""
        try:
            T = self.bed_from_anchor()
            path = profile_file_for(self.profile_choice)
            profile = load_profile(path)
            x, y = float(T[0, 3]), float(T[1, 3])
            if not (0 <= x <= profile.bed.width and 0 <= y <= profile.bed.depth):
                raise ValueError(f"the marker centre would be at bed ({x:.1f}, {y:.1f}) mm, off the "
                                 f"{profile.bed.width:g} x {profile.bed.depth:g} mm bed; check the coordinates")
            anchor = {"kind": "aruco", "dictionary": self.dictionary.currentText(), "id": self.marker_id.value(),
                      "length": self.length.value() / 1000.0}
            self.saved_path = save_bed_anchor(path, anchor, T)
        except (ValueError, ProfileError, OSError) as exc:
            self.message.setText(f"Not saved: {exc}")
            return
        self.message.setText(f"Saved in {self.saved_path}: marker centre at bed ({x:.1f}, {y:.1f}) mm")
        self.accept()
