"""What the HTTP printer links (OctoPrint, Moonraker) share: the base URL check, a session that keeps
secrets on their host, the server's own refusal text, and the map from a file position to the job's
progress.

Secrets rules, for every backend's key or password: keys and passwords are read
from files of mode 600 (`load_api_key`), never taken on the command line, never put in a message, a
log, a repr or a job file; `SecretSession` drops the `X-Api-Key` and `Authorization` headers *and* the
digest-auth hook (which would answer another host's challenge with our password) from a redirect to
another scheme, host or port; a URL holding a user name or password is refused and `redact_url` is all
any message shows of a URL.
"""

from __future__ import annotations

import bisect
import os
import stat
from collections.abc import Sequence
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import requests

from .base import DONE, Progress
from .job import JobState, Program

__all__ = ["API_KEY_HEADER", "ApiKeyError", "save_api_key", "load_api_key", "redact_url", "check_base_url",
           "SecretSession", "server_message", "FileProgress", "gcode_bytes", "finish_job"]


class ApiKeyError(ValueError):
    """An API key file that is missing, empty or readable by others."""


API_KEY_HEADER = "X-Api-Key"


def redact_url(url: str) -> str:
    """`url` with any user name and password replaced by `***` (what messages and job files may show)."""
    try:
        parts = urlsplit(str(url))
    except ValueError:
        return "<unparsable URL>"
    if "@" not in parts.netloc:
        return str(url)
    host = parts.netloc.rpartition("@")[2]
    return urlunsplit((parts.scheme, f"***@{host}", parts.path, parts.query, parts.fragment))


def save_api_key(path, key: str) -> Path:
    """Write `key` to `path` with file mode 600 (created that way, never wider)."""
    key = key.strip()
    if not key or any(c.isspace() for c in key):
        raise ApiKeyError("the API key is empty or contains spaces; copy it from the printer server's settings (OctoPrint: Settings > API)")
    path = Path(path).expanduser()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)  # whatever the umask
        os.write(fd, (key + "\n").encode("ascii"))
    finally:
        os.close(fd)
    os.replace(tmp, path)
    return path


def load_api_key(path) -> str:
    """Read an API key file; refuse one that group or others can read."""
    path = Path(path).expanduser()
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        raise ApiKeyError(f"cannot read the API key file {path}: {exc.strerror}") from exc
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ApiKeyError(
            f"the API key file {path} can be read by other users (mode {stat.S_IMODE(mode):03o}); "
            f"run: chmod 600 {path}"
        )
    key = path.read_text(encoding="ascii", errors="replace").strip()
    if not key:
        raise ApiKeyError(f"the API key file {path} is empty")
    return key


def check_base_url(url: str, what: str, example: str) -> str:
    """`url` without a trailing slash when it is http(s)://host[:port][/path] with no credentials, query or
    fragment; ValueError naming `what` (e.g. "Moonraker") and showing the URL redacted otherwise."""
    text = str(url).strip()
    try:
        parts = urlsplit(text)
        _ = parts.port  # ValueError for a port that is not a number or out of range
    except ValueError:
        raise ValueError(f"{what} URL {redact_url(text)!r} cannot be parsed; give e.g. {example}") from None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"{what} URL must start with http:// or https:// and name a host (e.g. {example}), "
                         f"got {redact_url(text)!r}")
    if parts.username is not None or parts.password is not None:
        raise ValueError(f"{what} URL {redact_url(text)!r} holds a user name or password; give it without "
                         "them (arapp reads keys and passwords from files of mode 600, and would otherwise "
                         "print and store the password)")
    if parts.query or parts.fragment:
        raise ValueError(f"{what} URL {redact_url(text)!r} has a query or fragment; give the server's base URL only")
    return text.rstrip("/")


class SecretSession(requests.Session):
    """A requests Session whose secrets stay with the server they were meant for: on a redirect to another
    scheme, host or port, `X-Api-Key` is removed (requests itself strips only `Authorization`) and so are
    the response hooks (HTTPDigestAuth's hook would answer the new host's 401 challenge with a digest of
    our password)."""

    def rebuild_auth(self, prepared_request, response):
        super().rebuild_auth(prepared_request, response)
        if self.should_strip_auth(response.request.url, prepared_request.url):
            prepared_request.headers.pop(API_KEY_HEADER, None)
            prepared_request.headers.pop("Authorization", None)
            prepared_request.hooks["response"] = []


def unanswered(server: str, url: str, method: str, path: str, exc: requests.RequestException,
               timeout: float) -> str:
    """One line for a request that got no HTTP answer: a server that cannot be reached (refused, no route,
    no name) is told apart from one that took the request and did not answer in `timeout` seconds (busy or
    stuck), and a request that may have started a job says to look at the printer. Never the headers."""
    if isinstance(exc, requests.ReadTimeout):
        text = (f"{server} at {url} took {method} {path.split('?')[0]} but did not answer within {timeout:g} s "
                "(busy or stuck)")
        if method in ("POST", "PUT"):
            text += "; it may still act on it: check the printer"
            if "/files" in path or "/print/start" in path:   # an upload or a start: sent twice, printed twice
                text += " before you send the job again"
        return text
    return f"{server} at {url} cannot be reached: {type(exc).__name__}"


def server_message(r: requests.Response, limit: int = 200) -> str:
    """The reason a server gave for refusing a request, on one line: Moonraker's `{"error": {"message"}}`,
    PrusaLink's `{"title", "message"}`, else the body's text (tracebacks and HTML dropped)."""
    try:
        body = r.json()
    except ValueError:
        body = None
    text = ""
    if isinstance(body, dict):
        err = body.get("error")
        if isinstance(err, dict):
            text = str(err.get("message") or "")
        elif isinstance(err, str):
            text = err
        if not text:
            text = " ".join(str(body[k]) for k in ("title", "message") if body.get(k))
    elif r.text and not r.text.lstrip().startswith("<"):
        text = r.text
    return " ".join(text.split())[:limit]


def gcode_bytes(lines: Sequence[str]) -> bytes:
    """The job's file as it is uploaded: every line ended by one newline, UTF-8."""
    return "".join(line if line.endswith("\n") else line + "\n" for line in lines).encode("utf-8")


class FileProgress:
    """Maps how far a server has read the uploaded file (bytes, or a fraction of them) to the commands
    it has run and the layer it is in (`Program`'s layer numbering)."""

    def __init__(self, data: bytes, program: Program):
        starts, pos = [], 0
        for line in data.split(b"\n"):
            starts.append(pos)
            pos += len(line) + 1
        self.size = len(data)
        self.program = program
        # byte offset just after each command's line (its newline included): a command is done once the
        # reader is past it
        ends = []
        for c in program.commands:
            nxt = starts[c.index + 1] if c.index + 1 < len(starts) else self.size
            ends.append(min(nxt, self.size))
        self._ends = ends

    def at(self, position: float) -> tuple[int, int]:
        """(commands done, layer) once the reader is at byte `position`; the layer is -1 before the first."""
        done = bisect.bisect_right(self._ends, int(position))
        layer = self.program.commands[done - 1].layer if done > 0 else -1
        return done, layer

    def at_fraction(self, fraction: float) -> tuple[int, int]:
        """(commands done, layer) at `fraction` (0..1) of the file's bytes."""
        return self.at(max(0.0, min(1.0, float(fraction))) * self.size)


def finish_job(state: JobState, job_path: str | None, progress, elapsed: float, temperatures: dict) -> None:
    """How a server link ends a job: the final state saved to `job_path` (when there is one) and the last
    Progress report (100 % of the lines done on a finished job, the stop's own share otherwise)."""
    if job_path:
        state.save(job_path)
    if progress is not None:
        total = state.commands_total
        progress(Progress(
            state=state.status, lines_done=state.commands_done, lines_total=total,
            layer=state.layer, layer_count=state.layer_count,
            percent=100.0 * state.commands_done / total if total else 100.0,
            elapsed_s=elapsed, eta_s=0.0 if state.status == DONE else None,
            temperatures=dict(temperatures), message=state.message,
        ))
