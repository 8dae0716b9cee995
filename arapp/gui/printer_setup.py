"""Printer set-up: the printer (a preset or a profile file), how it is reached (a serial port or an
OctoPrint server), a Test connection button, and the choices remembered for next time.

Nothing is chosen for the user: the port list shows what serial.tools.list_ports
finds, with descriptions, and starts on "Choose a port". The OctoPrint API key
is pasted once; Save keeps it in the user's config folder with mode 600
(arapp.printing.connection_check) and the field then says it is stored. The
choices (`printer` in arapp.user_config's state) are what `saved_choice()`
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

from arapp import user_config
from arapp.gui.tasks import Task
from arapp.printing import connection_check as cc
from arapp.printing.link.octoprint import ApiKeyError
from arapp.printing.presets import PRESETS, preset_profile
from arapp.printing.profile import ProfileError, load_profile

STATE_KEY = "printer"
BAUDS = (115200, 250000, 230400, 57600, 500000, 1000000)


def saved_choice() -> dict:
    """The remembered printer set-up: {"profile": "preset:KEY" or a file path, "link": "serial" or
    "octoprint", "port", "baud", "url"} ({} when never saved)."""
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

        self.profile = QComboBox()
        for key, data in PRESETS.items():
            self.profile.addItem(data["name"], f"preset:{key}")
        self.profile.addItem("Profile file...", "file")
        self.profile.activated.connect(self._profile_activated)
        self.profile_info = QLabel("")
        self.profile_info.setWordWrap(True)
        form.addRow("Printer", self.profile)
        self.bed_anchor_button = QPushButton("Bed marker...")
        self.bed_anchor_button.setToolTip("Which marker lies on the bed and where (saved in the printer profile)")
        self.bed_anchor_button.clicked.connect(self.edit_bed_anchor)
        irow = QHBoxLayout()
        irow.addWidget(self.profile_info, 1)
        irow.addWidget(self.bed_anchor_button)
        form.addRow("", irow)

        self.serial_radio = QRadioButton("USB / serial")
        self.octo_radio = QRadioButton("OctoPrint")
        group = QButtonGroup(self)
        group.addButton(self.serial_radio)
        group.addButton(self.octo_radio)
        self.serial_radio.setChecked(True)
        row = QHBoxLayout()
        row.addWidget(self.serial_radio)
        row.addWidget(self.octo_radio)
        row.addStretch(1)
        form.addRow("Connection", row)

        self.serial_box = QWidget()
        sf = QFormLayout(self.serial_box)
        sf.setContentsMargins(0, 0, 0, 0)
        self.port = QComboBox()
        self.refresh_button = QPushButton("Refresh")
        self.refresh_button.clicked.connect(self.refresh_ports)
        prow = QHBoxLayout()
        prow.addWidget(self.port, 1)
        prow.addWidget(self.refresh_button)
        sf.addRow("Port", prow)
        self.baud = QComboBox()
        for b in BAUDS:
            self.baud.addItem(str(b), b)
        sf.addRow("Baud", self.baud)
        form.addRow(self.serial_box)

        self.octo_box = QWidget()
        of = QFormLayout(self.octo_box)
        of.setContentsMargins(0, 0, 0, 0)
        self.url = QLineEdit()
        self.url.setPlaceholderText("http://octopi.local")
        self.url.editingFinished.connect(self._url_changed)
        self.key = QLineEdit()
        self.key.setEchoMode(QLineEdit.EchoMode.Password)
        self.key.setPlaceholderText("paste the API key (OctoPrint: Settings > API)")
        of.addRow("Address", self.url)
        of.addRow("API key", self.key)
        form.addRow(self.octo_box)

        self.test_button = QPushButton("Test connection")
        self.test_button.clicked.connect(self.test_connection)
        self.result = QLabel("")
        self.result.setWordWrap(True)
        trow = QHBoxLayout()
        trow.addWidget(self.test_button)
        trow.addWidget(self.result, 1)

        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Save | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.save)
        buttons.rejected.connect(self.reject)
        self.save_button = buttons.button(QDialogButtonBox.StandardButton.Save)
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addLayout(trow)
        lay.addWidget(buttons)

        self.serial_radio.toggled.connect(self._link_changed)
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
        from arapp.gui.bed_anchor_dialog import BedAnchorDialog

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

    def _link_changed(self, *_args) -> None:
        serial = self.serial_radio.isChecked()
        self.serial_box.setVisible(serial)
        self.octo_box.setVisible(not serial)
        self.result.setText("")

    def _url_changed(self) -> None:
        url = self.url.text().strip()
        if url and not self.key.text() and cc.stored_octoprint_key(url):
            self.key.setPlaceholderText("stored (paste a new key to replace it)")

    def _octoprint_key(self) -> str:
        return self.key.text().strip() or (cc.stored_octoprint_key(self.url.text()) or "")

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
                "link": "serial" if self.serial_radio.isChecked() else "octoprint",
                "port": self.port.currentData() or "", "baud": int(self.baud.currentData()),
                "url": self.url.text().strip()}

    def save(self) -> None:
        """Remember the choice; with OctoPrint and a pasted key, store the key (mode 600)."""
        choice = self.choice()
        if choice["link"] == "octoprint" and self.key.text().strip():
            try:
                cc.store_octoprint_key(choice["url"], self.key.text())
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
        if c.get("port"):
            self.set_port(c["port"])
        i = self.baud.findData(c.get("baud"))
        if i >= 0:
            self.baud.setCurrentIndex(i)
        self.url.setText(c.get("url", ""))
        self._url_changed()
