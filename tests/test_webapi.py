"""The HTTP backends' shared pieces (arapp.printing.link.webapi): secrets stay on their host across a
redirect, URLs with credentials are refused, a file position maps to commands done and layer.

Oracles: the headers a second local server actually received; the G-code lines counted by the test.
"""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
import requests

from arapp.printing.link import LinkError
from arapp.printing.link.job import Program
from arapp.printing.link.moonraker import MoonrakerLink
from arapp.printing.link.webapi import FileProgress, SecretSession, check_base_url, gcode_bytes

KEY = "5ecret0key0that0must0stay0home00"


def serve(handler):
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def test_a_redirect_to_another_host_carries_neither_key_nor_authorization():
    seen = []

    class Other(BaseHTTPRequestHandler):
        def log_message(self, *a):
            pass

        def do_GET(self):
            seen.append(dict(self.headers))
            body = json.dumps({"result": {"klippy_connected": False}}).encode()
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

    other = serve(Other)

    class Redirect(BaseHTTPRequestHandler):
        def log_message(self, *a):
            pass

        def do_GET(self):
            self.send_response(302)
            # "localhost" is another host than "127.0.0.1" for the redirect rule, as a real one would be
            self.send_header("Location", f"http://localhost:{other.server_address[1]}{self.path}")
            self.send_header("Content-Length", "0")
            self.end_headers()

    first = serve(Redirect)
    try:
        link = MoonrakerLink(f"http://127.0.0.1:{first.server_address[1]}", KEY)
        with pytest.raises(LinkError):
            link.connect()
        s = SecretSession()
        s.get(f"http://127.0.0.1:{first.server_address[1]}/x", headers={"Authorization": "Basic c2VjcmV0"},
              timeout=5)
    finally:
        first.shutdown()
        other.shutdown()
    assert len(seen) == 2
    for headers in seen:
        assert "X-Api-Key" not in headers and "Authorization" not in headers
        assert KEY not in json.dumps(headers)


def test_urls_with_credentials_or_queries_are_refused_redacted():
    with pytest.raises(ValueError) as info:
        check_base_url("http://maker:hunter22@voron.local", "Moonraker", "http://mainsailos.local")
    assert "hunter22" not in str(info.value) and "***@voron.local" in str(info.value)
    with pytest.raises(ValueError):
        check_base_url("ftp://voron.local", "Moonraker", "http://mainsailos.local")
    assert check_base_url(" http://voron.local:7125/ ", "Moonraker", "x") == "http://voron.local:7125"


def test_file_position_gives_commands_done_and_layer():
    lines = ["; start", "G90", "", ";LAYER:0", "G1 X1", "G1 X2 ; two", ";LAYER:1", "G1 X3"]
    data = gcode_bytes(lines)
    fp = FileProgress(data, Program.from_lines(lines))
    # the rule: a command is done once the reader is past its line's newline
    ends = []
    pos = 0
    for line in lines:
        pos += len(line) + 1
        ends.append(pos)
    assert fp.at(0) == (0, -1)
    assert fp.at(ends[1] - 1) == (0, -1) and fp.at(ends[1]) == (1, -1)   # G90 done
    assert fp.at(ends[5]) == (3, 0)                                        # G1 X2 done, layer 0
    assert fp.at(len(data)) == (4, 1) and fp.at_fraction(1.0) == (4, 1)


def _silent_server():
    """A listening socket nobody accepts from: the kernel completes the connection and takes the request,
    no answer ever comes (a server that is up but stuck)."""
    import socket

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    return sock


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]   # closed again: nothing listens there


@pytest.mark.parametrize("kind", ["prusalink", "moonraker", "octoprint"])
def test_no_answer_is_told_apart_from_unreachable_and_a_send_says_to_check_the_printer(kind):
    from arapp.printing.link import LinkLost
    from arapp.printing.link.octoprint import OctoPrintLink
    from arapp.printing.link.prusalink import PrusaLinkLink

    make = {"prusalink": lambda url: PrusaLinkLink(url, KEY, timeout=0.3),
            "moonraker": lambda url: MoonrakerLink(url, KEY, timeout=0.3),
            "octoprint": lambda url: OctoPrintLink(url, KEY, timeout=0.3)}[kind]
    server = {"prusalink": "PrusaLink", "moonraker": "Moonraker", "octoprint": "OctoPrint"}[kind]
    sock = _silent_server()
    try:
        url = f"http://127.0.0.1:{sock.getsockname()[1]}"
        link = make(url)
        link._session = SecretSession()   # as connect() leaves it, without the requests connect() makes
        for method, path, says in (("GET", "/api/version", ""),
                                   ("POST", "/printer/print/cancel", "; it may still act on it: check the printer"),
                                   ("PUT", "/api/v1/files/local/part.gcode", "; it may still act on it: check the "
                                    "printer before you send the job again")):
            with pytest.raises(LinkLost) as info:
                link._request(method, path)
            # the rule: the server named, the request named, the time waited, one line, no key; a request that
            # may have acted says to look, and one that may have started the job says not to send it twice
            assert str(info.value) == (f"{server} at {url} took {method} {path} but did not answer within 0.3 s "
                                       f"(busy or stuck){says}")
            assert KEY not in str(info.value)
    finally:
        sock.close()
    url = f"http://127.0.0.1:{_closed_port()}"
    link = make(url)
    link._session = SecretSession()
    with pytest.raises(LinkLost) as info:
        link._request("GET", "/api/version")
    assert str(info.value) == f"{server} at {url} cannot be reached: ConnectionError"
