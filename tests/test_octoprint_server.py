"""OctoPrint link against the real OctoPrint server (1.11.8) and its virtual printer (the session fixture
`octoprint`: tests/octoprint_server.py). The stand-in server in test_octoprint_link.py covers the replies that
are hard to provoke here (409 conflicts, a dropped connection).
"""

from __future__ import annotations

import threading

import pytest
import requests

from arapp.printing.link import LinkError
from arapp.printing.link.octoprint import OctoPrintError, OctoPrintLink
from arapp.printing.link.job import Program

from octoprint_server import KEY


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
