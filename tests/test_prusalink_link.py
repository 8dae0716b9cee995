"""PrusaLink link without a PrusaLink: its secrets stay on their host across a redirect (the digest
challenge of another host is not answered with our password, the API key is not sent there), and a
target without credentials is refused in one line.

Oracle: the headers a second local server actually received.
"""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from arapp.printing.link.factory import PrusaLinkTarget, make_link
from arapp.printing.link.prusalink import PrusaLinkError, PrusaLinkLink

KEY = "5ecret0key0that0must0stay0home00"
PASSWORD = "pa55word0that0must0stay0home"


def serve(handler):
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


@pytest.mark.parametrize("how", ["key", "digest"])
def test_a_redirect_to_another_host_gets_neither_key_nor_digest(how):
    seen = []

    class Other(BaseHTTPRequestHandler):
        def log_message(self, *a):
            pass

        def do_GET(self):
            seen.append(dict(self.headers))
            # a digest challenge, as PrusaLink's own: a link that kept its digest hook would answer it
            self.send_response(401)
            self.send_header("WWW-Authenticate", 'Digest realm="Administrator", nonce="abc123", qop="auth"')
            self.send_header("Content-Length", "0")
            self.end_headers()

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
    url = f"http://127.0.0.1:{first.server_address[1]}"
    try:
        link = PrusaLinkLink(url, KEY) if how == "key" else PrusaLinkLink(url, user="maker", password=PASSWORD)
        with pytest.raises(PrusaLinkError) as err:
            link.connect()
    finally:
        first.shutdown()
        other.shutdown()
    assert "HTTP 401" in str(err.value) and KEY not in str(err.value) and PASSWORD not in str(err.value)
    assert len(seen) == 1  # the challenge went unanswered
    assert "X-Api-Key" not in seen[0] and "Authorization" not in seen[0]
    assert KEY not in json.dumps(seen) and "maker" not in json.dumps(seen)


def test_a_target_without_credentials_is_refused_in_one_line():
    with pytest.raises(ValueError, match="--api-key-file F, or --prusalink-user NAME and --password-file F"):
        make_link(PrusaLinkTarget("http://prusa-mk4.local"))
    with pytest.raises(ValueError, match="holds a user name or password"):
        PrusaLinkLink("http://maker:secret@prusa-mk4.local", KEY)
