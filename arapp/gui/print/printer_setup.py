"""Printer set-up: the printer (a preset or a profile file), how it is reached (a serial port, an
OctoPrint server or a Klipper printer's Moonraker), a Test connection button, and the choices remembered
for next time.

Nothing is chosen for the user: the port list shows what serial.tools.list_ports
finds, with descriptions, and starts on "Choose a port". The OctoPrint (or
Moonraker) API key is pasted once; Save keeps it in the user's config folder with mode 600
(arapp.printing.connection_check) and the field then says it is stored. The
choices (`printer` in arapp.store.user_config's state) are what `saved_choice()`
returns; the print dialog reads them from there.
Tests run in a worker thread (a printer that is off takes seconds to be
given up on); the dialog stays live meanwhile.
"""

from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QButtonGroup,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QRadioButton,
    QVBoxLayout,
    QWidget,
)

from arapp.store import user_config
from arapp.gui.print.bed_anchor_dialog import BedAnchorDialog
from arapp.gui.tasks import Task
from arapp.printing import connection_check as cc
from arapp.printing.link.webapi import ApiKeyError
from arapp.printing.presets import PRESETS, preset_profile
from arapp.printing.profile import ProfileError, load_profile

STATE_KEY = "printer"
BAUDS = (115200, 250000, 230400, 57600, 500000, 1000000)


def saved_choice() -> dict:
    """The remembered printer set-up: {"profile": "preset:KEY" or a file path, "link": "serial",
    "octoprint" or "moonraker", "port", "baud", "url"} ({} when never saved)."""
    value = user_config.recall(STATE_KEY, {})
    return value if isinstance(value, dict) else {}


def profile_summary(profile) -> str:
    b = profile.bed
    anchor = "bed marker set up" if profile.bed_anchor is not None else "no bed marker (Bed marker...)"
    return (f"build volume {b.width:g} x {b.depth:g} x {b.height:g} mm, nozzle {profile.nozzle_diameter:g} mm, "
            f"filament {profile.filament_diameter:g} mm; {anchor}")


class PrinterSetupDialog(QDialog):
    """Choose the printer and its connection; `saved(dict)` fires with the choice when Save is pressed."""

    saved = Signal(dict)
    tested = Signal(object)  # connection_check.CheckResult

    def __init__(self, parent=None, ports: list[tuple[str, str]] | None = None):
        super().__init__(parent)
        self.setWindowTitle("Printer set-up")
        self._ports_given = ports
        self._test_task: Task | None = None
        self.last_result: cc.CheckResult | None = None
        form = QFormLayout()
        self._add_printer_row(form)
        self._add_bed_marker_row(form)
        self._add_link_choice_row(form)
        self._add_serial_section(form)
        self._add_octoprint_section(form)
        test_row = self._test_row()
        buttons = self._button_box()
        self._lay_out(form, test_row, buttons)
        self._connect_signals(buttons)
        self._start_from_saved_choice()

    # -- building the dialog (top to bottom) -------------------------------------------------------
    def _add_printer_row(self, form: QFormLayout) -> None:
        """The Printer row: the presets, then "Profile file..." to pick a profile JSON."""
        self.profile = QComboBox()
        for key, data in PRESETS.items():
            self.profile.addItem(data["name"], f"preset:{key}")
        self.profile.addItem("Profile file...", "file")
        form.addRow("Printer", self.profile)

    def _add_bed_marker_row(self, form: QFormLayout) -> None:
        """The chosen profile's summary and the Bed marker... button beside it."""
        self.profile_info = QLabel("")
        self.profile_info.setWordWrap(True)
        self.bed_anchor_button = QPushButton("Bed marker...")
        self.bed_anchor_button.setToolTip("Which marker lies on the bed and where (saved in the printer profile)")
        # the summary on a row of its own: a word-wrapped label beside a button in one row was given one
        # line's height and cut its second line off
        form.addRow("", self.profile_info)
        row = QHBoxLayout()
        row.addWidget(self.bed_anchor_button)
        row.addStretch(1)
        form.addRow("", row)

    def _add_link_choice_row(self, form: QFormLayout) -> None:
        """The Connection row: USB / serial (checked at first), OctoPrint or Klipper (Moonraker), one of them."""
        self.serial_radio = QRadioButton("USB / serial")
        self.octo_radio = QRadioButton("OctoPrint")
        self.moonraker_radio = QRadioButton("Klipper (Moonraker)")
        group = QButtonGroup(self)
        group.addButton(self.serial_radio)
        group.addButton(self.octo_radio)
        group.addButton(self.moonraker_radio)
        self.serial_radio.setChecked(True)
        row = QHBoxLayout()
        row.addWidget(self.serial_radio)
        row.addWidget(self.octo_radio)
        row.addWidget(self.moonraker_radio)
        row.addStretch(1)
        form.addRow("Connection", row)

    def _add_serial_section(self, form: QFormLayout) -> None:
        """The serial fields (shown with USB / serial): the port with Refresh, and the baud rate."""
        self.serial_box = QWidget()
        fields = QFormLayout(self.serial_box)
        fields.setContentsMargins(0, 0, 0, 0)
        fields.addRow("Port", self._port_row())
        self.baud = QComboBox()
        for b in BAUDS:
            self.baud.addItem(str(b), b)
        fields.addRow("Baud", self.baud)
        form.addRow(self.serial_box)

    def _port_row(self) -> QHBoxLayout:
        """The port list (filled by refresh_ports) and its Refresh button."""
        self.port = QComboBox()
        self.refresh_button = QPushButton("Refresh")
        row = QHBoxLayout()
        row.addWidget(self.port, 1)
        row.addWidget(self.refresh_button)
        return row

    def _add_octoprint_section(self, form: QFormLayout) -> None:
        """The server fields (shown with OctoPrint or Moonraker): the address and its API key (hidden text)."""
        self.octo_box = QWidget()
        fields = QFormLayout(self.octo_box)
        fields.setContentsMargins(0, 0, 0, 0)
        self.url = QLineEdit()
        self.url.setPlaceholderText("http://octopi.local")
        self.key = QLineEdit()
        self.key.setEchoMode(QLineEdit.EchoMode.Password)
        self.key.setPlaceholderText("paste the API key (OctoPrint: Settings > API)")
        fields.addRow("Address", self.url)
        fields.addRow("API key", self.key)
        form.addRow(self.octo_box)

    def _test_row(self) -> QHBoxLayout:
        """Test connection and, beside it, the test's result."""
        self.test_button = QPushButton("Test connection")
        self.result = QLabel("")
        self.result.setWordWrap(True)
        row = QHBoxLayout()
        row.addWidget(self.test_button)
        row.addWidget(self.result, 1)
        return row

    def _button_box(self) -> QDialogButtonBox:
        """Save and Cancel; Save is kept as `save_button`."""
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        self.save_button = buttons.button(QDialogButtonBox.StandardButton.Save)
        return buttons

    def _lay_out(self, form: QFormLayout, test_row: QHBoxLayout, buttons: QDialogButtonBox) -> None:
        """The form, then the test row, then Save / Cancel, top to bottom."""
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addLayout(test_row)
        lay.addWidget(buttons)

    def _connect_signals(self, buttons: QDialogButtonBox) -> None:
        """Widgets to handlers; made after the radios' first setChecked so that it does not count as a change."""
        self.profile.activated.connect(self._profile_activated)
        self.bed_anchor_button.clicked.connect(self.edit_bed_anchor)
        self.refresh_button.clicked.connect(self.refresh_ports)
        self.url.editingFinished.connect(self._url_changed)
        self.test_button.clicked.connect(self.test_connection)
        buttons.accepted.connect(self.save)
        buttons.rejected.connect(self.reject)
        self.serial_radio.toggled.connect(self._link_changed)
        self.moonraker_radio.toggled.connect(self._link_changed)

    def _start_from_saved_choice(self) -> None:
        """List the ports, restore the remembered choice, and show the fields and summary that go with it."""
        self.refresh_ports()
        self._restore()
        self._link_changed()
        self._show_profile()

    # -- profile -------------------------------------------------------------------------------
    def _profile_activated(self, _index: int) -> None:
        if self.profile.currentData() == "file":
            path, _ = QFileDialog.getOpenFileName(self, "A printer profile", "", "Printer profiles (*.json)")
            if path:
                self.set_profile_file(path)
            else:
                self.profile.setCurrentIndex(0)
        self._show_profile()

    def edit_bed_anchor(self) -> None:
        """The bed marker dialog for the printer chosen; a preset becomes a profile file in the config folder."""
        choice = self.profile.currentData()
        if not isinstance(choice, str) or choice == "file":
            return
        dlg = BedAnchorDialog(choice, self)
        dlg.accepted.connect(lambda: self.set_profile_file(str(dlg.saved_path)))
        self.bed_anchor_dialog = dlg
        dlg.open()

    def set_profile_file(self, path: str) -> None:
        i = self.profile.findData(path)
        if i < 0:
            self.profile.insertItem(self.profile.count() - 1, path.rsplit("/", 1)[-1], path)
            i = self.profile.findData(path)
        self.profile.setCurrentIndex(i)
        self._show_profile()

    def current_profile(self):
        data = self.profile.currentData()
        if isinstance(data, str) and data.startswith("preset:"):
            return preset_profile(data[len("preset:"):])
        return load_profile(data)

    def _show_profile(self) -> None:
        try:
            self.profile_info.setText(profile_summary(self.current_profile()))
        except (ProfileError, OSError) as exc:
            self.profile_info.setText(str(exc))

    # -- connection ------------------------------------------------------------------------------
    def refresh_ports(self) -> None:
        current = self.port.currentData()
        self.port.clear()
        self.port.addItem("Choose a port", "")
        for dev, desc in (cc.list_ports() if self._ports_given is None else self._ports_given):
            self.port.addItem(f"{dev} - {desc}", dev)
        i = self.port.findData(current) if current else -1
        self.port.setCurrentIndex(max(0, i))

    def set_port(self, device: str) -> None:
        """Select `device`, adding it when the list does not show it (a pty, a port that is unplugged now)."""
        if self.port.findData(device) < 0:
            self.port.addItem(f"{device} - not found now", device)
        self.port.setCurrentIndex(self.port.findData(device))

    def link_kind(self) -> str:
        """"serial", "octoprint" or "moonraker": the Connection chosen."""
        if self.serial_radio.isChecked():
            return "serial"
        return "moonraker" if self.moonraker_radio.isChecked() else "octoprint"

    def _link_changed(self, *_args) -> None:
        kind = self.link_kind()
        self.serial_box.setVisible(kind == "serial")
        self.octo_box.setVisible(kind != "serial")
        if kind == "moonraker":
            self.url.setPlaceholderText("http://mainsailos.local")
            self.key.setPlaceholderText("Moonraker's API key (none needed from its trusted_clients)")
        else:
            self.url.setPlaceholderText("http://octopi.local")
            self.key.setPlaceholderText("paste the API key (OctoPrint: Settings > API)")
        self.result.setText("")
        self._url_changed()

    def _url_changed(self) -> None:
        url = self.url.text().strip()
        kind = self.link_kind()
        if url and kind != "serial" and not self.key.text() and cc.stored_key(kind, url):
            self.key.setPlaceholderText("stored (paste a new key to replace it)")

    def _server_key(self) -> str:
        return self.key.text().strip() or (cc.stored_key(self.link_kind(), self.url.text()) or "")

    def _octoprint_key(self) -> str:
        return self._server_key()

    @property
    def testing(self) -> bool:
        """A Test is running (its result has not been shown yet)."""
        return not self.test_button.isEnabled()

    def test_connection(self) -> None:
        if self.testing:
            return
        self.test_button.setEnabled(False)
        if self.serial_radio.isChecked():
            port, baud = self.port.currentData(), self.baud.currentData()
            self.result.setText(f"Asking the printer on {port} (M115)..." if port else "")
            fn, args = cc.check_serial, (port, baud)
        elif self.moonraker_radio.isChecked():
            self.result.setText("Asking Moonraker...")
            fn, args = cc.check_moonraker, (self.url.text(), self._server_key())
        else:
            self.result.setText("Asking OctoPrint...")
            fn, args = cc.check_octoprint, (self.url.text(), self._octoprint_key())
        self._test_task = Task(fn, *args, done=self._tested, failed=self._test_failed, name="arapp-printer-test",
                               owner=self).start()

    def _tested(self, res: cc.CheckResult) -> None:
        self.test_button.setEnabled(True)
        self.last_result = res
        self.result.setText(("OK: " if res.ok else "Failed: ") + res.summary)
        self.tested.emit(res)

    def _test_failed(self, exc: BaseException) -> None:
        self._tested(cc.CheckResult(False, str(exc), {}))

    # -- saving -----------------------------------------------------------------------------------
    def choice(self) -> dict:
        return {"profile": self.profile.currentData(),
                "link": self.link_kind(),
                "port": self.port.currentData() or "", "baud": int(self.baud.currentData()),
                "url": self.url.text().strip()}

    def save(self) -> None:
        """Remember the choice; with OctoPrint or Moonraker and a pasted key, store the key (mode 600)."""
        choice = self.choice()
        if choice["link"] in ("octoprint", "moonraker") and self.key.text().strip():
            try:
                cc.store_key(choice["link"], choice["url"], self.key.text())
            except ApiKeyError as exc:
                self.result.setText(f"Failed: {exc}")
                return
            self.key.clear()
        user_config.remember(STATE_KEY, choice)
        self.saved.emit(choice)
        self.accept()

    def _restore(self) -> None:
        c = saved_choice()
        if not c:
            return
        profile = c.get("profile")
        if isinstance(profile, str) and profile.startswith("preset:") and self.profile.findData(profile) >= 0:
            self.profile.setCurrentIndex(self.profile.findData(profile))
        elif isinstance(profile, str) and profile and profile != "file":
            self.set_profile_file(profile)
        if c.get("link") == "octoprint":
            self.octo_radio.setChecked(True)
        elif c.get("link") == "moonraker":
            self.moonraker_radio.setChecked(True)
        if c.get("port"):
            self.set_port(c["port"])
        i = self.baud.findData(c.get("baud"))
        if i >= 0:
            self.baud.setCurrentIndex(i)
        self.url.setText(c.get("url", ""))
        self._url_changed()
