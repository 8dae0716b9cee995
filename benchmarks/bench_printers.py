"""Network printer backends: upload -> printing -> done against the real servers.

Moonraker 0.11.0 in front of the real Klippy (tests/moonraker_server.py: Klippy in its file-output
mode, no microcontroller, so motion runs faster than real time and the figures are the link's and the
servers' own overhead, not a print's length). Per job: upload (POST /server/files/upload, and
Moonraker's metadata pass), start (POST /printer/print/start) until the websocket reports our file
printing, and start until done. Each job's end is checked against Klipper's own print_stats (state
complete, our file). PrusaLink: not run (its printer detection needs Prusa firmware answers the test
emulator does not give: docs/printer-links.md).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "tests") not in sys.path:
    sys.path.insert(0, str(ROOT / "tests"))


def _job(n: int) -> list[str]:
    lines = ["G90", "M82", "M104 S200", "G92 E0"]
    for i in range(n):
        if i % (n // 3) == 0:
            lines.append(f";LAYER:{i // (n // 3)}")
        lines.append(f"G1 E{0.01 * (i + 1):.3f} F6000")
    return lines


def run(quick: bool = False) -> str:
    import moonraker_server as ms

    from arapp.printing.link.moonraker import MoonrakerLink

    head = "## Network printer backends (upload -> printing -> done, real servers)\n\n"
    if not (ms.MOONRAKER.is_file() and ms.KLIPPY.is_file()):
        return head + "Skipped: .venv-moonraker / .venv-klippy missing (`make setup` makes them).\n"
    sizes = (3000,) if quick else (3000, 30000)
    repeats = 3 if quick else 5
    rows = []
    with tempfile.TemporaryDirectory(prefix="arapp-bench-moonraker-") as tmp:
        server = ms.MoonrakerServer(Path(tmp))
        try:
            t0 = time.monotonic()
            server.wait_ready()
            startup = time.monotonic() - t0
            for n in sizes:
                lines = _job(n)
                size_kb = len(("\n".join(lines) + "\n").encode()) / 1024
                ups, starts, totals, ok = [], [], [], 0
                for r in range(repeats):
                    link = MoonrakerLink(server.url)
                    link.connect()
                    marks = {}
                    orig_upload, orig_start = link.upload, link.start

                    def upload(*a, **k):
                        marks["u0"] = time.perf_counter()
                        out = orig_upload(*a, **k)
                        marks["u1"] = time.perf_counter()
                        return out

                    def start(*a, **k):
                        marks["s0"] = time.perf_counter()
                        return orig_start(*a, **k)

                    link.upload, link.start = upload, start

                    def on_progress(p):
                        if "printing" not in marks and p.lines_done > 0:
                            marks["printing"] = time.perf_counter()

                    name = f"bench-{n}-{r}.gcode"
                    state = link.print_gcode(lines, progress=on_progress, gcode_path=str(Path(tmp) / name))
                    end = time.perf_counter()
                    link.close()
                    ps = server.query("print_stats")["print_stats"]
                    ok += int(state.status == "done" and ps["state"] == "complete" and ps["filename"] == name)
                    ups.append(marks["u1"] - marks["u0"])
                    if "printing" in marks:
                        starts.append(marks["printing"] - marks["s0"])
                    totals.append(end - marks["s0"])
                med = statistics.median
                rows.append(f"| {n} | {size_kb:.0f} | {med(ups) * 1000:.0f} | "
                            f"{(med(starts) * 1000 if starts else float('nan')):.0f} ({len(starts)}/{repeats}) | "
                            f"{med(totals) * 1000:.0f} | {ok}/{repeats} |")
        finally:
            server.stop()
    return (head + __doc__.split("\n\n", 1)[1].strip() + "\n\n"
            + f"Moonraker + Klippy start-up to ready: {startup:.1f} s.\n\n"
            + "| G-code lines | KiB | upload ms (median) | start -> first progress ms (seen/jobs) | "
              "start -> done ms | done, checked by Klipper |\n| --- | --- | --- | --- | --- | --- |\n"
            + "\n".join(rows) + "\n")


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
