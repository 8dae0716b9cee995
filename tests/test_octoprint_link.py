"""OctoPrint link against a local HTTP server speaking OctoPrint's REST API.

test_octoprint_server.py runs the link against the real OctoPrint server (its own
environment, .venv-octoprint). This stand-in, fast and fully scripted, checks what
arrives at the server in detail (form fields, the API key header), pause and
resume at chosen moments, the `arapp print` command line and the key file. Its
replies are copies of the real server's (same JSON shapes,
status codes 201/204/403/409, the job-state strings "Operational", "Printing",
"Paused", "Cancelling").
The stand-in runs the job by advancing the file position through the uploaded
bytes; the tests check what arrived (the exact G-code, the form fields, the
API key header) and what the link reported.
"""

from __future__ import annotations

from email import policy
from email.parser import BytesParser
import json
import logging
import os
import stat
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
import requests

from arapp.printing.link.octoprint import OctoPrintError, OctoPrintLink
from arapp.printing.link.webapi import ApiKeyError, load_api_key, save_api_key

KEY = "Zq8v3KJ2x9TEST0KEY0do0not0log0Wm"


class FakeOctoPrint:
    """OctoPrint's REST API for one printer; a job advances `rate` bytes per second."""

    def __init__(self, rate: float = 40000.0):
        self.rate = rate
        self.uploads: list[dict] = []
        self.commands: list[dict] = []
        self.keys_seen: list[str] = []
        self.state = "Operational"
        self.data = b""
        self.name = None
        self.pos = 0.0
        self.completion = None
        self.last = time.monotonic()
        self.lock = threading.Lock()
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _send(self, code, body=None):
                raw = b"" if body is None else json.dumps(body).encode()
                self.send_response(code)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(raw)))
                self.end_headers()
                self.wfile.write(raw)

            def _auth(self):
                key = self.headers.get("X-Api-Key", "")
                fake.keys_seen.append(key)
                if key != KEY:
                    self._send(403, {"error": "You don't have the permission to access the requested resource."})
                    return False
                return True

            def do_GET(self):
                if not self._auth():
                    return
                path = self.path.split("?")[0]
                with fake.lock:
                    fake._advance()
                    if path == "/api/version":
                        self._send(200, {"api": "0.1", "server": "1.11.8", "text": "OctoPrint 1.11.8"})
                    elif path == "/api/connection":
                        self._send(200, {"current": {"baudrate": 115200, "port": "VIRTUAL",
                                                     "printerProfile": "_default", "state": fake.state}})
                    elif path == "/api/job":
                        busy = fake.state != "Operational" or fake.completion is not None
                        self._send(200, {
                            "job": {"file": {"name": fake.name, "path": fake.name, "origin": "local",
                                             "size": len(fake.data)}, "estimatedPrintTime": 13.0},
                            "progress": {
                                "completion": fake.completion,
                                "filepos": int(fake.pos) if busy else None,
                                "printTime": 1 if busy else None,
                                "printTimeLeft": max(0, int((len(fake.data) - fake.pos) / fake.rate)) if busy else None,
                                "printTimeLeftOrigin": "estimate" if busy else None,
                            },
                            "state": fake.state,
                        })
                    elif path == "/api/printer":
                        if fake.state in ("Offline", "Closed"):
                            self._send(409, {"error": "Printer is not operational"})
                        else:
                            self._send(200, {"temperature": {"bed": {"actual": 60.0, "offset": 0, "target": 60.0},
                                                             "tool0": {"actual": 209.5, "offset": 0, "target": 210.0}}})
                    else:
                        self._send(404, {"error": "not found"})

            def do_POST(self):
                if not self._auth():
                    return
                length = int(self.headers.get("Content-Length", "0"))
                body = self.rfile.read(length)
                with fake.lock:
                    fake._advance()
                    if self.path == "/api/files/local":
                        head = f"Content-Type: {self.headers['Content-Type']}\r\n\r\n".encode()
                        message = BytesParser(policy=policy.HTTP).parsebytes(head + body)
                        form = {}
                        for part in message.iter_parts():
                            field = part.get_param("name", header="content-disposition")
                            form[field] = (part.get_filename(), part.get_payload(decode=True))
                        upload = {"name": form["file"][0], "data": form["file"][1],
                                  "select": form["select"][1].decode(), "print": form["print"][1].decode()}
                        fake.uploads.append(upload)
                        if upload["print"] == "true":
                            fake.data, fake.name, fake.pos = upload["data"], upload["name"], 0.0
                            fake.state, fake.completion = "Printing", 0.0
                        self._send(201, {"done": True, "effectivePrint": upload["print"] == "true",
                                         "effectiveSelect": True,
                                         "files": {"local": {"name": upload["name"], "origin": "local",
                                                             "path": upload["name"]}}})
                    elif self.path == "/api/job":
                        cmd = json.loads(body)
                        fake.commands.append(cmd)
                        if cmd["command"] == "cancel" and fake.state in ("Printing", "Paused"):
                            fake.state, fake.completion = "Cancelling", None
                        elif cmd["command"] == "pause" and cmd.get("action") == "pause" and fake.state == "Printing":
                            fake.state = "Paused"
                        elif cmd["command"] == "pause" and cmd.get("action") == "resume" and fake.state == "Paused":
                            fake.state = "Printing"
                        else:
                            self._send(409, {"error": f"Printer is {fake.state}"})
                            return
                        self._send(204)
                    else:
                        self._send(404, {"error": "not found"})

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self.thread.start()

    def _advance(self):
        now = time.monotonic()
        dt, self.last = now - self.last, now
        if self.state == "Printing":
            self.pos = min(len(self.data), self.pos + dt * self.rate)
            self.completion = 100.0 * self.pos / max(1, len(self.data))
            if self.pos >= len(self.data):
                self.state = "Operational"
        elif self.state == "Cancelling":
            self.state = "Operational"

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def octo():
    server = FakeOctoPrint()
    yield server
    server.close()


def gcode(layers=5, per_layer=400):
    lines = ["; arapp test", "G28", "M190 S60", "M109 S210"]
    for layer in range(layers):
        lines.append(f";LAYER:{layer}")
        lines.append(f"G1 Z{0.2 * (layer + 1):.1f}")
        lines += [f"G1 X{10 + i % 90} Y{20 + i % 70} E{0.01 * i:.2f} F1800" for i in range(per_layer)]
    return lines


def test_upload_starts_job_and_progress_reaches_done(octo, tmp_path, caplog):
    caplog.set_level(logging.DEBUG)  # urllib3/requests debug logging too
    lines = gcode()
    seen = []
    link = OctoPrintLink(octo.url, KEY, poll_interval=0.05, job_path=tmp_path / "job.json")
    link.connect()
    state = link.print_gcode(lines, progress=seen.append, gcode_path=str(tmp_path / "part.gcode"))
    link.close()
    assert state.status == "done" and state.commands_done == state.commands_total
    up = octo.uploads[0]
    assert up["data"].decode() == "\n".join(lines) + "\n"  # the exact G-code
    assert up["name"] == "part.gcode" and up["select"] == "true" and up["print"] == "true"
    assert set(octo.keys_seen) == {KEY}
    layers = [p.layer for p in seen]
    assert layers == sorted(layers) and len(set(layers)) >= 3  # the layer follows the file position
    assert seen[-1].state == "done" and seen[-1].layer == 4 and seen[-1].percent == 100.0
    assert seen[1].temperatures["T"] == (209.5, 210.0) and seen[1].temperatures["B"] == (60.0, 60.0)
    assert json.loads((tmp_path / "job.json").read_text())["status"] == "done"
    assert KEY not in caplog.text


def test_pause_resume_cancel(octo):
    octo.rate = 20000.0
    link = OctoPrintLink(octo.url, KEY, poll_interval=0.05)
    link.connect()
    states = []

    def on_progress(p):
        states.append(p.state)
        if p.percent > 10 and "paused" not in states and octo.state == "Printing":
            link.pause()
        elif p.state == "paused" and states.count("paused") == 3:
            link.resume()
        elif "paused" in states and p.state == "printing" and p.percent > 40:
            link.cancel()

    state = link.print_gcode(gcode(), progress=on_progress)
    link.close()
    assert [c["command"] for c in octo.commands] == ["pause", "pause", "cancel"]
    assert [c.get("action") for c in octo.commands[:2]] == ["pause", "resume"]
    assert state.status == "cancelled"
    assert 40 < 100.0 * state.commands_done / state.commands_total < 100


def test_wrong_key_is_refused_without_showing_it(octo, caplog):
    caplog.set_level(logging.DEBUG)
    wrong = "WRONGKEY0000secret0000000000000x"
    link = OctoPrintLink(octo.url, wrong)
    with pytest.raises(OctoPrintError) as info:
        link.connect()
    assert "refused the API key" in str(info.value)
    assert wrong not in str(info.value) and wrong not in repr(link) and wrong not in caplog.text


def test_unreachable_server_message_has_no_key(caplog):
    from arapp.printing.link import LinkLost

    caplog.set_level(logging.DEBUG)
    link = OctoPrintLink("http://127.0.0.1:9", KEY, timeout=2.0)
    with pytest.raises(LinkLost) as info:
        link.connect()
    assert "cannot be reached" in str(info.value)
    assert KEY not in str(info.value) and KEY not in caplog.text


def test_key_file_is_written_0600_and_loose_files_refused(tmp_path):
    old = os.umask(0o022)
    try:
        path = save_api_key(tmp_path / "keys" / "octoprint.key", KEY + "\n")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert load_api_key(path) == KEY
    # Overwriting an existing, too-open file narrows it to 600 as well.
    loose = tmp_path / "loose.key"
    loose.write_text("x")
    loose.chmod(0o644)
    with pytest.raises(ApiKeyError, match="chmod 600"):
        load_api_key(loose)
    save_api_key(loose, KEY)
    assert stat.S_IMODE(loose.stat().st_mode) == 0o600


def test_cli_prints_through_octoprint_and_never_shows_key(octo, tmp_path, capsys, monkeypatch):
    from arapp.cli import main

    g = tmp_path / "part.gcode"
    g.write_text("\n".join(gcode(layers=2, per_layer=50)) + "\n")
    keyfile = tmp_path / "key"
    monkeypatch.setenv("ARAPP_OCTOPRINT_API_KEY", KEY)
    rc = main(["print", str(g), "--octoprint", octo.url, "--save-key", str(keyfile)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert stat.S_IMODE(keyfile.stat().st_mode) == 0o600
    assert octo.uploads[0]["data"] == g.read_bytes()
    assert "done" in out.out and KEY not in out.out + out.err
    # A key file others can read is refused with the fix in the message.
    keyfile.chmod(0o640)
    rc = main(["print", str(g), "--octoprint", octo.url, "--api-key-file", str(keyfile)])
    err = capsys.readouterr().err
    assert rc == 2 and "chmod 600" in err and KEY not in err


class HeaderRecorder:
    """A second local server: records the headers of every request and answers like an idle OctoPrint
    (so a link that followed a redirect here would carry on talking to it)."""

    def __init__(self):
        self.headers: list[dict] = []
        rec = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_GET(self):
                rec.headers.append({k.lower(): v for k, v in self.headers.items()})
                raw = json.dumps({"text": "OctoPrint 1.11.8", "current": {"state": "Operational"}}).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(raw)))
                self.end_headers()
                self.wfile.write(raw)

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.port = self.server.server_address[1]
        threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


class Redirector:
    """The OctoPrint URL the user gave: answers every request with `code` to the same path at `target`."""

    def __init__(self, target: str, code: int = 307):
        self.keys_seen: list[str] = []
        red = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_GET(self):
                red.keys_seen.append(self.headers.get("X-Api-Key", ""))
                self.send_response(code)
                self.send_header("Location", target + self.path)
                self.send_header("Content-Length", "0")
                self.end_headers()

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.mark.parametrize("host", ["localhost", "127.0.0.1"])  # another host name; the same host, another port
@pytest.mark.parametrize("code", [301, 302, 307, 308])
def test_api_key_never_follows_a_redirect_to_another_server(host, code):
    other = HeaderRecorder()
    red = Redirector(f"http://{host}:{other.port}", code)
    try:
        link = OctoPrintLink(red.url, KEY, timeout=5)
        link.connect()  # followed to the other server, which answers as an OctoPrint would
        link.close()
        assert red.keys_seen and set(red.keys_seen) == {KEY}  # the server the user named gets the key
        assert other.headers, "the redirect was not followed at all"
        assert all("x-api-key" not in h for h in other.headers), "the API key reached another server"
    finally:
        red.close()
        other.close()


def test_api_key_is_kept_on_a_redirect_within_the_same_server(octo):
    # The rule written in the test: same scheme, host and port is the same server (OctoPrint behind a
    # reverse proxy redirecting /api/x to /api/x/); there the key must still arrive.
    from arapp.printing.link.webapi import SecretSession as KeySession

    session = KeySession()
    session.headers["X-Api-Key"] = KEY
    req = session.prepare_request(requests.Request("GET", octo.url + "/api/version"))
    resp = requests.Response()
    resp.request = session.prepare_request(requests.Request("GET", octo.url + "/old"))
    session.rebuild_auth(req, resp)
    assert req.headers.get("X-Api-Key") == KEY


@pytest.mark.parametrize("url", ["http://user:s3cretPW@{hostport}", "http://:s3cretPW@{hostport}/",
                                 "https://admin:s3cretPW@{hostport}/octoprint"])
def test_credentials_in_the_url_are_refused_without_showing_them(octo, url):
    hostport = octo.url.split("://", 1)[1]
    with pytest.raises(ValueError) as err:
        OctoPrintLink(url.format(hostport=hostport), KEY)
    assert "s3cretPW" not in str(err.value) and "***@" in str(err.value)
    assert octo.keys_seen == []  # refused before any request


def test_cli_refuses_credentials_in_the_url_and_stores_them_nowhere(octo, tmp_path, capsys):
    from arapp.cli import main

    keyfile = save_api_key(tmp_path / "octoprint.key", KEY)
    g = tmp_path / "part.gcode"
    g.write_text("\n".join(gcode(layers=1, per_layer=5)) + "\n")
    url = octo.url.replace("http://", "http://maker:s3cretPW@")
    rc = main(["print", str(g), "--octoprint", url, "--api-key-file", str(keyfile), "--job", str(tmp_path / "j.json")])
    out, err = capsys.readouterr()
    assert rc != 0 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert "s3cretPW" not in out + err
    for f in tmp_path.rglob("*"):
        if f.is_file():
            assert b"s3cretPW" not in f.read_bytes(), f"the password is stored in {f.name}"
    assert octo.uploads == []


def test_redact_url():
    from arapp.printing.link.webapi import redact_url

    assert redact_url("http://u:p@h:5000/x?y=1") == "http://***@h:5000/x?y=1"
    assert redact_url("http://h/x") == "http://h/x"
