"""The real OctoPrint server (1.11.8) with its virtual printer, started once per test session for the tests
that ask for it (`octoprint`: its URL): the files that use it are one group on one worker (tests/conftest.py
SERVER_GROUPS), so it starts once.

The server runs from its own environment, `.venv-octoprint` (made by `make test`: its dependencies cannot share
arapp's), on a free local port, with a fresh base folder: one admin user and an application key written where
OctoPrint's appkeys plugin keeps them, the first-run wizard and every network check off.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
from pathlib import Path

import pytest
import requests

ROOT = Path(__file__).resolve().parents[1]
SERVER = ROOT / ".venv-octoprint" / "bin" / "octoprint"
KEY = "Zq8v3KJ2x9REAL0KEY0do0not0log0Wm"
CONFIG = """\
server:
  firstRun: false
  onlineCheck: {enabled: false}
  pluginBlacklist: {enabled: false}
  seenWizards: {corewizard: 4}
plugins:
  _disabled: [tracking, announcements, softwareupdate, backup, firmware_check, pluginmanager, achievements,
              health_check]
  virtual_printer: {enabled: true}
serial: {autoconnect: false}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def octoprint(tmp_path_factory):
    """URL of a running OctoPrint connected to its virtual printer."""
    if not SERVER.is_file():
        pytest.fail("the OctoPrint server is part of the test set-up: run `make test` (it makes .venv-octoprint)")
    base = tmp_path_factory.mktemp("octoprint")
    (base / "config.yaml").write_text(CONFIG)
    subprocess.run([str(SERVER), "--basedir", str(base), "user", "add", "arapp", "--password", "arapp-tests",
                    "--admin"], check=True, capture_output=True, timeout=120)
    keys = base / "data" / "appkeys"
    keys.mkdir(parents=True)
    (keys / "keys.yaml").write_text(f"arapp:\n- app_id: arapp tests\n  api_key: {KEY}\n")
    port = free_port()
    log = open(base / "server.log", "w")
    cmd = [str(SERVER), "--basedir", str(base), "serve", "--host", "127.0.0.1", "--port", str(port)]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--iknowwhatimdoing")   # CI machines run the tests as root
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    headers = {"X-Api-Key": KEY}
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                if requests.get(url + "/api/version", headers=headers, timeout=2).ok:
                    break
            except requests.ConnectionError:
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"OctoPrint did not start: {(base / 'server.log').read_text()[-2000:]}")
            time.sleep(0.3)
        r = requests.post(url + "/api/connection", headers=headers, timeout=10,
                          json={"command": "connect", "port": "VIRTUAL", "baudrate": 115200})
        assert r.status_code == 204, r.text
        deadline = time.monotonic() + 30
        def state():
            return requests.get(url + "/api/connection", headers=headers, timeout=5).json()["current"]["state"]

        while state() != "Operational":
            assert time.monotonic() < deadline, "the virtual printer did not become operational"
            time.sleep(0.2)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
