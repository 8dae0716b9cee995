"""The real PrusaLink (`prusalink` 0.8.1 from the package index, the Raspberry-Pi PrusaLink for the MK3S)
talking over a pseudo-terminal to the project's Marlin emulator answering as Prusa firmware
(tests/prusa_firmware.py), for the PrusaLink link's tests: started once per test session in a temporary
folder, from its own environment (`.venv-prusalink`, made by `make test`: its pins cannot share arapp's).

PrusaLink's local service is set up as its wizard would leave it (prusa_printer_settings.ini): user
`maker`, the digest of its password (md5 of `user:realm:password`, realm `Administrator`), and an API key.
It prints a job from its own storage (`/api/v1/files/local/...`) by sending the file's lines over the
serial port, so the emulator's own list of executed commands is the test's oracle.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest
import requests

ROOT = Path(__file__).resolve().parents[1]
PRUSALINK = ROOT / ".venv-prusalink" / "bin" / "prusalink"
USER, PASSWORD, API_KEY = "maker", "test-password-1", "arappTestKey42"
REALM = "Administrator"
# seconds PrusaLink shows a job FINISHED or STOPPED (its end screen) and takes no new one: 11 in PrusaLink
# (const.PRINT_END_TIMEOUT). The tests print one job after another, and each waited out the last one's 11 s
# (the link's `_settled`): set shorter here, the way a fake clock stands in for a real timeout. The wait itself
# stays: test_a_job_right_after_another_waits_for_the_end_screen meets it.
PRINT_END_S = 2.5
# PrusaLink's own entry point (bin/prusalink) with that one constant set first (argv[1]); it runs in-process
LAUNCH = """\
import sys
import prusa.link.const as const
const.PRINT_END_TIMEOUT = float(sys.argv.pop(1))
import prusa.link.printer_adapter.state_manager as state_manager
state_manager.PRINT_END_TIMEOUT = const.PRINT_END_TIMEOUT
from prusa.link.__main__ import main
sys.argv[0] = "prusalink"
sys.exit(main())
"""

PRUSALINK_INI = """\
[daemon]
data_dir = {data}
pid_file = {data}/prusalink.pid

[http]
address = 127.0.0.1
port = {port}

[printer]
port = {tty}
settings = {data}/prusa_printer_settings.ini
directory = {storage}

[cameras]
auto = False
"""

SETTINGS_INI = """\
[printer]
type = MK3S
name = arapp-test

[service::local]
enable = 1
username = {user}
digest = {digest}
api_key = {key}
"""


def storage_folder() -> Path:
    """A new folder for PrusaLink's local storage, outside /tmp: PrusaLink ignores any storage under /tmp,
    /dev, /sys or /proc (its BLACKLISTED_PATHS), where pytest's temporary folders are."""
    parent = ROOT / ".prusalink-test"
    if any(str(parent).startswith(p) for p in ("/tmp", "/dev", "/sys", "/proc")):
        parent = Path.home() / ".cache" / "arapp-prusalink-test"
    parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix="PrusaLink-gcodes-", dir=parent))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PrusaLinkServer:
    """PrusaLink in `base` on the pty of `firmware` (a PrusaFirmwarePty); `url`, `api_key`, `storage`."""

    def __init__(self, base: Path, firmware):
        self.base, self.firmware = base, firmware
        data = base / "data"
        data.mkdir(parents=True, exist_ok=True)
        self.storage = storage_folder()
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.api_key = API_KEY
        digest = hashlib.md5(f"{USER}:{REALM}:{PASSWORD}".encode()).hexdigest()
        (data / "prusa_printer_settings.ini").write_text(SETTINGS_INI.format(user=USER, digest=digest, key=API_KEY))
        (base / "prusalink.ini").write_text(PRUSALINK_INI.format(data=data, port=self.port, tty=firmware.port,
                                                                   storage=self.storage))
        self._log = open(base / "prusalink.out", "w")
        # unbuffered: its log is whole when a test fails (a terminated PrusaLink leaves no buffer behind)
        self.proc = subprocess.Popen([str(PRUSALINK.parent / "python"), "-c", LAUNCH, str(PRINT_END_S),
                                      "-f", "-c", str(base / "prusalink.ini")],
                                     stdout=self._log, stderr=subprocess.STDOUT, cwd=data,
                                     env={**os.environ, "PYTHONUNBUFFERED": "1"})

    def log_tail(self, n: int = 3000) -> str:
        lines = (self.base / "prusalink.out").read_text(errors="replace").splitlines()
        # without the warning PrusaLink repeats every second while no job runs
        return "\n".join(line for line in lines if "differs from the local one" not in line)[-n:]

    def status(self) -> dict:
        r = requests.get(self.url + "/api/v1/status", headers={"X-Api-Key": API_KEY}, timeout=2)
        r.raise_for_status()
        return r.json()

    def wait_state(self, states=("IDLE", "READY", "FINISHED", "STOPPED"), timeout: float = 90.0,
                   temperatures: bool = False) -> dict:
        """Until PrusaLink reports the printer in one of `states` (and, with `temperatures`, the temperatures
        the firmware reports once PrusaLink has turned its reports on: PrusaLink sends M155 on a 10 s tick, and
        when that tick comes before it has found the printer, 60 s later)."""
        deadline = time.monotonic() + timeout
        last = None
        while True:
            try:
                last = self.status()
                if last.get("printer", {}).get("state") in states and (
                        not temperatures or last["printer"].get("temp_nozzle") is not None):
                    return last
            except (requests.RequestException, ValueError):
                pass
            if self.proc.poll() is not None:
                raise RuntimeError(f"prusalink exited ({self.proc.returncode}):\n{self.log_tail()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"PrusaLink not in {states} after {timeout:g} s (last status {last}):\n"
                                   f"{self.log_tail()}")
            time.sleep(0.25)

    def job_recorded(self) -> bool:
        """Whether PrusaLink shows a job with its file's path (it records the path after it has started the
        job's file printer thread; tests/prusa_firmware.py holds the chime's M400 until then)."""
        try:
            r = requests.get(self.url + "/api/v1/job", headers={"X-Api-Key": API_KEY}, timeout=2)
            return r.status_code == 200 and bool((r.json().get("file") or {}).get("path"))
        except (requests.RequestException, ValueError):
            return False

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._log.close()


@pytest.fixture(scope="session")
def prusalink_server(tmp_path_factory):
    """A running PrusaLink with the Prusa-answering emulator IDLE behind it, shared by the test session."""
    if not PRUSALINK.is_file():
        pytest.skip("PrusaLink is part of the test set-up: run `make test` (it makes .venv-prusalink)")
    from prusa_firmware import PrusaFirmwarePty

    base = tmp_path_factory.mktemp("prusalink")
    firmware = PrusaFirmwarePty()
    server = PrusaLinkServer(base, firmware)
    firmware.job_recorded = server.job_recorded
    try:
        server.wait_state()
        yield server
    finally:
        server.stop()
        firmware.close()
        shutil.rmtree(server.storage, ignore_errors=True)
