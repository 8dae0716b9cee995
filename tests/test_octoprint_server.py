"""OctoPrint link against the real OctoPrint server (1.11.8) and its virtual printer.

The server runs from its own environment, `.venv-octoprint` (made by `make test`:
its dependencies cannot share arapp's), on a free local port, with a fresh base
folder: one admin user and an application key written where OctoPrint's appkeys
plugin keeps them, the first-run wizard and every network check off. The
stand-in server in test_octoprint_link.py covers the replies that are hard to
provoke here (409 conflicts, a dropped connection).
"""

from __future__ import annotations

import os
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
import requests

from arapp.printing.link import LinkError
from arapp.printing.link.octoprint import OctoPrintError, OctoPrintLink
from arapp.printing.link.job import Program

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


@pytest.fixture(scope="module")
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
        while requests.get(url + "/api/connection", headers=headers, timeout=5).json()["current"]["state"] != "Operational":
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


def job(n: int, layers: int = 3) -> list[str]:
    """Distinct short moves in `layers` layers, with the layer comments the link follows."""
    lines = ["; arapp test job", "G90", "M82", "G92 E0"]
    per = n // layers
    for i in range(n):
        if i % per == 0 and i // per < layers:
            lines += [f";LAYER:{i // per}", f"G1 Z{0.2 * (i // per + 1):.1f} F3000"]
        lines.append(f"G1 X{10 + i % 50}.{i % 10} Y{20 + i % 37}.{i % 3} E{0.01 * (i + 1):.3f} F6000")
    return lines


def test_print_on_the_real_server_runs_our_exact_file(octoprint, tmp_path):
    lines = job(150)
    seen = []
    link = OctoPrintLink(octoprint, KEY, poll_interval=0.1)
    link.connect()
    assert link.version == "OctoPrint 1.11.8"
    state = link.print_gcode(lines, progress=seen.append, gcode_path=str(tmp_path / "arapp-part.gcode"))
    link.close()
    assert state.status == "done"
    assert state.commands_done == state.commands_total == len(Program.from_lines(lines).commands)
    assert state.layer == 2 and state.layer_count == 3
    percents = [p.percent for p in seen]
    assert percents == sorted(percents) and seen
    # the file OctoPrint printed is byte for byte the one we sent
    got = requests.get(f"{octoprint}/downloads/files/local/arapp-part.gcode", headers={"X-Api-Key": KEY}, timeout=10)
    assert got.ok and got.content == ("\n".join(lines) + "\n").encode()
    # and OctoPrint's own record says it finished
    info = requests.get(f"{octoprint}/api/files/local/arapp-part.gcode", headers={"X-Api-Key": KEY}, timeout=10).json()
    assert info["prints"]["success"] >= 1


def test_cancel_on_the_real_server(octoprint, tmp_path):
    cancel = threading.Event()
    seen = []

    def on_progress(p):
        seen.append(p)
        if p.percent > 5:
            cancel.set()

    link = OctoPrintLink(octoprint, KEY, poll_interval=0.1)
    link.connect()
    state = link.print_gcode(job(6000), progress=on_progress, cancel=cancel, gcode_path=str(tmp_path / "long.gcode"))
    link.close()
    assert state.status == "cancelled"
    assert 0 < state.commands_done < state.commands_total
    current = requests.get(f"{octoprint}/api/job", headers={"X-Api-Key": KEY}, timeout=10).json()
    assert current["state"] == "Operational"


def test_wrong_key_is_refused_by_the_real_server(octoprint, caplog):
    wrong = "A" * 32
    link = OctoPrintLink(octoprint, wrong)
    with pytest.raises(OctoPrintError) as info:
        link.connect()
    assert "refused the API key" in str(info.value)
    assert wrong not in str(info.value) and wrong not in caplog.text
    assert isinstance(info.value, LinkError)
