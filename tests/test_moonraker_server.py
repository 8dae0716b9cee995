"""Moonraker link against the real Moonraker 0.11.0 and the real Klipper host (Klippy) behind it
(tests/moonraker_server.py: Klippy in its file-output mode, no microcontroller).

Oracles: the G-code as the test writes it (its commands counted by the rule below: what is left of a
line once `;` comments and blanks are dropped), the file Moonraker stored (read from its gcodes folder),
and Klipper's own status (`print_stats`, `extruder`) asked through Moonraker's HTTP API by the test.
Klipper runs motion faster than real time here, so a job stops where a test wants it with Klipper's
PAUSE in the G-code (a filament change does the same on a real printer).
"""

from __future__ import annotations

import logging
import threading
import time

import pytest
import requests

from arapp.printing.link import LinkError, PrinterHalted
from arapp.printing.link.moonraker import FileInUse, JobWatch, MoonrakerError, MoonrakerLink, check_moonraker


def commands(lines) -> int:
    """G-code commands in `lines`: what remains of each line without its `;` comment, when not blank."""
    return sum(1 for line in lines if line.split(";", 1)[0].strip())


def job(n: int, layers: int = 3, pause_at: int | None = None) -> list[str]:
    """`n` extruder moves in `layers` layers (`;LAYER:k`), the hotend target set to 200 °C first, and
    Klipper's PAUSE after move `pause_at`."""
    lines = ["; arapp test job", "G90", "M82", "M104 S200", "G92 E0"]
    per = n // layers
    for i in range(n):
        if i % per == 0 and i // per < layers:
            lines.append(f";LAYER:{i // per}")
        lines.append(f"G1 E{0.01 * (i + 1):.3f} F6000")
        if i == pause_at:
            lines.append("PAUSE")
    return lines


def until_paused(link, then):
    """A progress callback that calls `then()` once, on the first paused report; keeps every report."""
    seen = []

    def on_progress(p):
        seen.append(p)
        if p.state == "paused" and not any(q.state == "paused" for q in seen[:-1]):
            then()

    return seen, on_progress


def test_print_round_trip_runs_our_exact_file(moonraker_server, tmp_path):
    lines = job(3000)
    link = MoonrakerLink(moonraker_server.url)  # no key: the test machine is a trusted client
    link.connect()
    assert link.version == "Moonraker 0.11.0"
    seen = []
    state = link.print_gcode(lines, progress=seen.append, gcode_path=str(tmp_path / "arapp-part.gcode"))
    link.close()
    assert state.status == "done"
    assert state.commands_done == state.commands_total == commands(lines) == 3004
    assert state.layer == 2 and state.layer_count == 3
    # the file Moonraker stored is byte for byte ours, and Klipper printed that file to its end
    assert (moonraker_server.gcodes / "arapp-part.gcode").read_bytes() == ("\n".join(lines) + "\n").encode()
    ps = moonraker_server.query("print_stats")["print_stats"]
    assert ps["state"] == "complete" and ps["filename"] == "arapp-part.gcode"
    # the temperatures reached the app: the target the job set (the reading is 0 °C: no MCU here)
    assert seen[-1].state == "done" and seen[-1].temperatures["T"] == (0.0, 200.0)
    assert [p.percent for p in seen] == sorted(p.percent for p in seen)


def test_pause_in_the_gcode_reports_the_exact_line_then_resumes(moonraker_server, tmp_path):
    lines = job(3000, pause_at=1700)
    before_pause = commands(lines[:lines.index("PAUSE") + 1])
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    seen, on_progress = until_paused(link, link.resume)
    state = link.print_gcode(lines, progress=on_progress, gcode_path=str(tmp_path / "pause.gcode"))
    link.close()
    paused = [p for p in seen if p.state == "paused"]
    assert paused, [p.state for p in seen]
    # Klipper stopped after the PAUSE line: the link counted every command up to it, in layer 1
    assert paused[0].lines_done == before_pause == 1706 and paused[0].layer == 1
    assert 0 < paused[0].percent < 100
    assert state.status == "done" and state.commands_done == commands(lines)


def test_cancel_stops_the_job_and_turns_the_heaters_off(moonraker_server, tmp_path):
    lines = job(3000, pause_at=500)
    before_pause = commands(lines[:lines.index("PAUSE") + 1])
    cancel = threading.Event()
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    seen, on_progress = until_paused(link, cancel.set)
    state = link.print_gcode(lines, progress=on_progress, cancel=cancel, gcode_path=str(tmp_path / "long.gcode"))
    link.close()
    assert state.status == "cancelled"
    assert state.commands_done == before_pause < state.commands_total
    status = moonraker_server.query("print_stats", "extruder")
    assert status["print_stats"]["state"] == "cancelled"
    assert status["extruder"]["target"] == 0.0  # the job had set 200 °C


def test_api_key_wrong_refused_right_accepted_never_shown(moonraker_server, tmp_path, caplog):
    caplog.set_level(logging.DEBUG)
    wrong = "0123456789abcdef0123456789abcdef"
    link = MoonrakerLink(moonraker_server.url, wrong)
    with pytest.raises(MoonrakerError) as info:
        link.connect()
    assert "refused the API key (HTTP 401)" in str(info.value)
    assert wrong not in str(info.value) + caplog.text + repr(link)
    key = moonraker_server.api_key()
    link = MoonrakerLink(moonraker_server.url, key)
    link.connect()  # the websocket opens with a oneshot token, not the key
    state = link.print_gcode(job(300), gcode_path=str(tmp_path / "keyed.gcode"))
    link.close()
    assert state.status == "done"
    assert key not in caplog.text + repr(link) + state.port


def test_file_too_large_is_one_clear_line_and_nothing_is_stored(moonraker_server, tmp_path):
    big = job(70000)  # over 1 MB, the most this Moonraker takes
    size_mb = len(("\n".join(big) + "\n").encode()) / 2**20
    assert size_mb > 1.05
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    with pytest.raises(MoonrakerError) as info:
        link.print_gcode(big, gcode_path=str(tmp_path / "big.gcode"))
    assert str(info.value) == (f"the G-code is {size_mb:.1f} MB; Moonraker at {moonraker_server.url} takes uploads up to "
                               "1 MB (max_upload_size in moonraker.conf [server])")
    # when the limit is not known beforehand, Moonraker's own refusal says the same in one line
    link.max_upload = None
    with pytest.raises(MoonrakerError) as info:
        link.print_gcode(big, gcode_path=str(tmp_path / "big.gcode"))
    link.close()
    assert str(info.value).startswith(f"Moonraker at {moonraker_server.url} refused the upload of big.gcode "
                                      f"({size_mb:.1f} MB) without a reason (")
    assert "max_upload_size" in str(info.value) and "\n" not in str(info.value)
    assert not (moonraker_server.gcodes / "big.gcode").exists()


def test_test_connection_reports_moonraker_and_klipper(moonraker_server):
    ok, summary, details = check_moonraker(moonraker_server.url)
    assert ok and summary == "Moonraker 0.11.0: Klipper ready (Printer is ready)"
    ok, summary, _ = check_moonraker(moonraker_server.url, "f" * 32)
    assert not ok and "refused the API key" in summary
    ok, summary, _ = check_moonraker("http://127.0.0.1:9")  # nothing listens there
    assert not ok and "cannot be reached" in summary


def test_klipper_shutdown_mid_job_then_not_ready(moonraker_server, tmp_path):
    """Last here: it shuts Klipper down (M112), checks what the user is told, and restarts it."""
    lines = job(3000, pause_at=300)
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    # Klipper answers the M112 request itself with an error (it shut down): only the shutdown matters here
    seen, on_progress = until_paused(link, lambda: requests.post(moonraker_server.url + "/printer/gcode/script",
                                                                 json={"script": "M112"}, timeout=10))
    try:
        with pytest.raises(PrinterHalted) as info:
            link.print_gcode(lines, progress=on_progress, gcode_path=str(tmp_path / "halt.gcode"))
        assert str(info.value).startswith("Klipper shut down:") and "\n" not in str(info.value)
        link.close()
        again = MoonrakerLink(moonraker_server.url)
        with pytest.raises(MoonrakerError) as info:
            again.connect()
        text = str(info.value)
        assert text.startswith(f"Klipper behind Moonraker at {moonraker_server.url} is not ready (state shutdown")
        assert "\n" not in text and "FIRMWARE_RESTART" in text
        assert isinstance(info.value, LinkError)
    finally:
        requests.post(moonraker_server.url + "/printer/restart", timeout=10)
        time.sleep(0.5)
        moonraker_server.wait_ready()


def test_cli_prints_through_moonraker_with_and_without_a_key(moonraker_server, tmp_path, capsys, monkeypatch):
    from arapp.cli import main

    g = tmp_path / "cli-part.gcode"
    g.write_text("\n".join(job(600)) + "\n")
    rc = main(["print", str(g), "--moonraker", moonraker_server.url])  # trusted LAN: no key
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert f"connected to Moonraker 0.11.0 at {moonraker_server.url}" in out.err
    assert out.out.startswith(f"done: {commands(job(600))}/{commands(job(600))} lines")
    assert (moonraker_server.gcodes / "cli-part.gcode").read_bytes() == g.read_bytes()
    # a key stored once (mode 600, read from the environment, never from argv) and used; a file of another
    # name: Moonraker's own job record can lag the job just printed for longer than the link's retries (once,
    # after the Klipper restart of the test before: it still showed cli-part.gcode printing), and uploading
    # over a printing file has its own test (test_an_upload_over_the_file_being_printed_is_retried_...)
    g2 = tmp_path / "cli-keyed.gcode"
    g2.write_bytes(g.read_bytes())
    key = moonraker_server.api_key()
    keyfile = tmp_path / "moonraker.key"
    monkeypatch.setenv("ARAPP_API_KEY", key)
    rc = main(["print", str(g2), "--moonraker", moonraker_server.url, "--save-key", str(keyfile)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert oct(keyfile.stat().st_mode & 0o777) == "0o600" and keyfile.read_text().strip() == key
    assert key not in out.out + out.err + (tmp_path / "cli-keyed.gcode.job.json").read_text()
    # two links at once: one line naming both
    rc = main(["print", str(g), "--moonraker", moonraker_server.url, "--port", "/dev/null"])
    err = capsys.readouterr().err
    assert rc == 2 and "--port and --moonraker" in err and len(err.strip().splitlines()) == 1


def test_the_app_job_reports_layers_from_moonraker(moonraker_server, tmp_path):
    """The app's print job (arapp.app.printlink.start_job, what the print panel and the AR layer highlight
    use) on a MoonrakerTarget: its events carry the layer Klipper is in, up to the end."""
    from arapp.app.printlink import start_job
    from arapp.printing.link import MoonrakerTarget

    lines = job(3000, pause_at=1700)
    events, done = [], threading.Event()
    resumed = []

    def on_event(ev):
        events.append(ev)
        if ev.progress is not None and ev.progress.state == "paused" and not resumed:
            resumed.append(ev.progress)
            pj.resume()
        if ev.finished:
            done.set()

    pj = start_job(MoonrakerTarget(moonraker_server.url), "\n".join(lines) + "\n", None, on_event,
                   job_path=tmp_path / "app.printjob.json", gcode_path=str(tmp_path / "app-part.gcode"))
    assert done.wait(60)
    assert [e.error for e in events if e.error] == []
    assert events[-1].text == "Print finished"
    # while paused mid-file the app was told layer 1 (the PAUSE sits in the second of three layers)
    assert resumed and resumed[0].layer == 1 and resumed[0].layer_count == 3
    layers = [e.progress.layer for e in events if e.progress is not None]
    assert layers == sorted(layers) and layers[-1] == 2


def test_a_profile_with_a_moonraker_link_prints_without_link_flags(moonraker_server, tmp_path, capsys):
    import json

    from arapp.cli import main

    prof = tmp_path / "voron.json"
    prof.write_text(json.dumps({"format": "arapp-printer/1", "name": "Voron 0.2",
                                "bed": {"width": 120, "depth": 120, "height": 120},
                                "link": {"kind": "moonraker", "url": moonraker_server.url}}))
    g = tmp_path / "from-profile.gcode"
    g.write_text("\n".join(job(300)) + "\n")
    rc = main(["print", str(g), "--printer", str(prof)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert f"at {moonraker_server.url}" in out.err and out.out.startswith("done:")
    assert (moonraker_server.gcodes / "from-profile.gcode").read_bytes() == g.read_bytes()


@pytest.mark.parametrize("link, says", [
    ({"kind": "klipper", "url": "http://x"}, "link.kind: 'klipper' is not a link kind; use one of serial, "
                                             "octoprint, moonraker"),
    ({"kind": "moonraker"}, "link.url: missing (a moonraker link needs the server's address"),
    ({"kind": "moonraker", "url": "http://x", "api_key": "abc"}, "link.api_key: unknown key"),
])
def test_profile_link_kind_errors_name_the_key(tmp_path, link, says):
    from arapp.printing.profile import ProfileError, parse_profile

    data = {"format": "arapp-printer/1", "name": "p", "bed": {"width": 100, "depth": 100, "height": 100},
            "link": link}
    with pytest.raises(ProfileError) as info:
        parse_profile(data, "p.json", defaults={"link": {"port": "", "baud": 115200}, "flavor": "marlin",
                                                "nozzle_diameter": 0.4, "filament_diameter": 1.75,
                                                "start_gcode": "", "end_gcode": ""})
    assert says in str(info.value) and str(info.value).startswith("p.json: ")


def test_an_upload_over_the_file_being_printed_is_retried_then_explained(moonraker_server, tmp_path):
    """Moonraker refuses (HTTP 403, "File is loaded, upload not permitted") to replace the file of a job that
    is printing or paused, also for a moment after the job ended, until Klipper's next report reaches it: the
    link asks again for `in_use_wait_s`, then says what holds the file (not that the key was refused)."""
    lines = job(3000, pause_at=400)
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    tries = []

    def upload_over_it():
        other = MoonrakerLink(moonraker_server.url, in_use_wait_s=0.6)
        other.connect()
        t0 = time.monotonic()
        with pytest.raises(FileInUse) as info:
            other.upload(b"G28\n", name="in-use.gcode", start=False)
        tries.append((time.monotonic() - t0, str(info.value)))
        other.close()
        link.resume()

    seen, on_progress = until_paused(link, upload_over_it)
    state = link.print_gcode(lines, progress=on_progress, gcode_path=str(tmp_path / "in-use.gcode"))
    link.close()
    assert state.status == "done"
    (waited, text), = tries
    assert 0.6 <= waited < 5.0
    assert "in-use.gcode while Klipper prints it" in text and "HTTP 403" in text and "\n" not in text
    assert "API key" not in text
    # the stored file is the job's, not the upload refused over it
    assert (moonraker_server.gcodes / "in-use.gcode").read_bytes() == ("\n".join(lines) + "\n").encode()


def test_a_file_loaded_but_not_yet_started_is_a_job_about_to_start(moonraker_server):
    """Klipper's SDCARD_PRINT_FILE loads the file (print_stats: "standby", our file name, durations 0) and
    starts reading it on the reactor's next turn; a status report between the two once ended a print as
    "cancelled" under load. M23 loads a file the same way and stops there, so Klipper's own report of that
    moment is what the watch is given: waiting; then M24 starts it and it ends done. Once loaded, the file
    reset (SDCARD_RESET_FILE, before it was seen printing) is a cancelled job."""
    link = MoonrakerLink(moonraker_server.url)
    link.connect()
    for name in ("loaded.gcode", "reset.gcode"):
        link.upload(("\n".join(job(30)) + "\n").encode(), name=name, start=False)
    link.close()
    for name, then, outcome in (("loaded.gcode", "M24", "done"), ("reset.gcode", "SDCARD_RESET_FILE", "cancelled")):
        watch = JobWatch(name, moonraker_server.query("print_stats")["print_stats"])
        moonraker_server.gcode(f"M23 {name}")
        ps = moonraker_server.query("print_stats")["print_stats"]
        assert (ps["state"], ps["filename"]) == ("standby", name)   # Klipper's report between load and start
        assert watch.update(ps) == "waiting"
        moonraker_server.gcode(then)
        deadline = time.monotonic() + 30
        while (ps := moonraker_server.query("print_stats")["print_stats"])["state"] in JobWatch.ACTIVE:
            assert time.monotonic() < deadline, ps
            time.sleep(0.1)
        assert watch.update(ps) == outcome, ps


def test_job_watch_reads_klippers_print_stats_as_its_rules_say():
    """The watch's rules on report sequences Klipper's print_stats can give (its fields as Klipper sets them:
    set_current_file resets to "standby" with the file's name, note_start "printing", note_complete
    "complete", note_cancel "cancelled", reset() "standby" with no file); no server needed."""
    before = {"state": "complete", "filename": "old.gcode", "total_duration": 9.0, "print_duration": 8.0}
    loaded = {"state": "standby", "filename": "ours.gcode", "total_duration": 0.0, "print_duration": 0.0}
    cases = [
        ([before], ["waiting"]),                                           # nothing new yet
        ([{**before, "filename": "other.gcode"}], ["waiting"]),            # another file, never ours
        ([loaded, {**loaded, "state": "printing"}, {**loaded, "state": "complete", "print_duration": 2.0}],
         ["waiting", "printing", "done"]),
        ([loaded, {**loaded, "state": "complete", "print_duration": 0.5}], ["waiting", "done"]),  # too short to see
        ([{**loaded, "state": "complete", "print_duration": 0.5}], ["done"]),                     # nor its load
        ([loaded, {**loaded, "state": "paused"}, {**loaded, "state": "cancelled"}], ["waiting", "paused", "cancelled"]),
        ([loaded, {**loaded, "state": "error", "message": "MCU"}], ["waiting", "error"]),
        ([loaded, {**before, "state": "standby", "filename": ""}], ["waiting", "cancelled"]),   # reset once loaded
        ([{**loaded, "state": "printing"}, {**loaded, "filename": ""}], ["printing", "cancelled"]),  # reset mid-job
        ([{**loaded, "state": "printing"}, {**loaded, "state": "complete", "filename": "next.gcode"}],
         ["printing", "cancelled"]),                                       # another file took over
    ]
    for reports, outcomes in cases:
        watch = JobWatch("ours.gcode", before)
        assert [watch.update(r, now=0.1 * i) for i, r in enumerate(reports)] == outcomes, reports
    # loaded and never started (Klipper failed to begin reading it): waited for, then ended, not forever
    watch = JobWatch("ours.gcode", before, start_wait_s=10.0)
    assert [watch.update(loaded, now=t) for t in (0.0, 9.9, 10.0)] == ["waiting", "waiting", "cancelled"]
