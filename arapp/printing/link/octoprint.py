"""OctoPrint link: upload G-code and run the job through OctoPrint's REST API.

Endpoints (docs.octoprint.org, REST API): `GET /api/version` (check the key),
`GET /api/connection` (is a printer attached), `POST /api/files/local`
(multipart `file`, `select=true`, `print=true`), `GET /api/job` (state,
progress: completion %, file position in bytes, times), `POST /api/job`
(`cancel`, `pause` with action `pause`/`resume`), `GET /api/printer`
(temperatures). The API key goes in the `X-Api-Key` header only: it is never
logged, printed or put in an error message, and key files are written with
mode 600 (and refused when others can read them).

The key never leaves for another host: `webapi.SecretSession` drops `X-Api-Key` from a
redirect to another scheme/host/port (requests keeps custom headers on every
redirect, it strips only `Authorization`). A URL holding a user name or
password (`http://user:pw@host`) is refused, and `redact_url` is what any
message shows of a URL, so a password is never printed nor stored in a job file.
"""

from __future__ import annotations

import bisect
import logging
import re
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import requests

from .base import (
    CANCELLED,
    CANCELLING,
    DONE,
    HEATING,
    PAUSED,
    PRINTING,
    LinkError,
    LinkLost,
    PrinterHalted,
    PrintLink,
    Progress,
    ProgressCallback,
    eta,
)
from .job import JobState, Program, new_state
from .webapi import API_KEY_HEADER, SecretSession, check_base_url, finish_job, unanswered

log = logging.getLogger("arapp.printing.octoprint")

_LAYER = re.compile(rb";\s*LAYER\s*:\s*(-?\d+)", re.IGNORECASE)



def _layer_offsets(data: bytes) -> tuple[list[int], list[int]]:
    """Byte offset and number of each layer comment in the G-code, to turn OctoPrint's file position into a layer."""
    offsets, layers = [], []
    for m in _LAYER.finditer(data):
        offsets.append(m.start())
        layers.append(int(m.group(1)))
    return offsets, layers

class OctoPrintError(LinkError):
    """OctoPrint refused a request or could not be reached."""


def check_octoprint_url(url: str) -> str:
    """The OctoPrint base URL without a trailing slash (webapi.check_base_url's rules)."""
    return check_base_url(url, "OctoPrint", "http://octopi.local")


class OctoPrintLink(PrintLink):
    """A printer behind an OctoPrint server (url like http://octopi.local)."""

    def __init__(self, url: str, api_key: str, *, poll_interval: float = 1.0, timeout: float = 30.0,
                 job_path=None, name: str = "arapp.gcode"):
        self.url = check_octoprint_url(url)
        self._key = api_key
        self.poll_interval = float(poll_interval)
        self.timeout = float(timeout)
        self.job_path = job_path
        self.name = name
        self._session = None
        self._cancel_req = threading.Event()
        self.version = ""
        self.state: JobState | None = None
        self.temperatures: dict = {}

    def __repr__(self):
        return f"OctoPrintLink({self.url!r})"  # never the key

    # ----------------------------------------------------------------- http
    def _request(self, method: str, path: str, **kw):
        if self._session is None:
            raise LinkError("not connected to OctoPrint: call connect() first")
        try:
            r = self._session.request(method, self.url + path, timeout=self.timeout, **kw)
        except requests.RequestException as exc:
            raise LinkLost(unanswered("OctoPrint", self.url, method, path, exc, self.timeout)) from None
        if r.status_code in (401, 403):
            raise OctoPrintError(
                f"OctoPrint at {self.url} refused the API key (HTTP {r.status_code}); "
                "check the key file (OctoPrint: Settings > API, or a user's Application Key)"
            )
        if r.status_code >= 400:
            detail = r.text.strip()[:200]
            raise OctoPrintError(f"OctoPrint {method} {path} failed: HTTP {r.status_code} {detail}")
        return r

    def connect(self) -> None:
        self._session = SecretSession()
        self._session.headers[API_KEY_HEADER] = self._key
        self.version = self._request("GET", "/api/version").json().get("text", "")
        current = self._request("GET", "/api/connection").json().get("current", {})
        if str(current.get("state", "")).lower().startswith(("closed", "offline", "error")):
            raise OctoPrintError(
                f"OctoPrint at {self.url} is not connected to a printer (state: {current.get('state')}); "
                "connect it in OctoPrint first"
            )

    def close(self) -> None:
        if self._session is not None:
            self._session.close()
        self._session = None

    # ------------------------------------------------------------ controls
    def pause(self) -> None:
        self._request("POST", "/api/job", json={"command": "pause", "action": "pause"})

    def resume(self) -> None:
        self._request("POST", "/api/job", json={"command": "pause", "action": "resume"})

    def cancel(self) -> None:
        """Cancel the job (OctoPrint runs its own cancel script on the printer)."""
        self._cancel_req.set()
        self._request("POST", "/api/job", json={"command": "cancel"})

    # ----------------------------------------------------------------- job
    def upload(self, data: bytes, name: str | None = None, start: bool = True) -> dict:
        """Upload G-code bytes to OctoPrint's local storage, optionally starting the print."""
        name = name or self.name
        files = {"file": (name, data, "application/octet-stream")}
        form = {"select": "true", "print": "true" if start else "false"}
        r = self._request("POST", "/api/files/local", files=files, data=form)
        return r.json() if r.content else {}

    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        gcode_path: str = "",
    ) -> JobState:
        """Upload, start, then follow the job until it ends. Returns the final job state."""
        data = "".join(line if line.endswith("\n") else line + "\n" for line in lines).encode("utf-8")
        program = Program.from_lines(data.decode("utf-8").splitlines())
        state = new_state(program, gcode_path)
        state.port = self.url
        state.status = PRINTING
        self.state = state
        offsets, layers = _layer_offsets(data)
        name = Path(gcode_path).name if gcode_path else self.name
        info = self.upload(data, name=name, start=True)
        uploaded = ((info.get("files") or {}).get("local") or {}).get("name", name)
        self._cancel_req.clear()
        t0 = time.monotonic()
        started = False
        cancelling = False
        never = threading.Event()
        while True:
            if cancel is not None and cancel.is_set() and not cancelling:
                self.cancel()
            if self._cancel_req.is_set():
                cancelling = True
            job, ours, completion, prog = self._poll_job(state, (uploaded, name), offsets, layers)
            text = str(job.get("state", ""))
            low = text.lower()
            if ours and (low.startswith(("printing", "pausing", "paused", "cancelling", "finishing", "starting"))):
                started = True
            elapsed = time.monotonic() - t0
            back = low.startswith("operational") and (started or (ours and completion is not None))
            if self._job_ended(state, job, text, back, cancelling, completion, layers, progress, elapsed):
                return state
            if progress is not None:
                progress(self._progress(state, text, cancelling, prog, elapsed))
            # Wait for the next poll; cancel() from another thread wakes it early.
            (never if cancelling else self._cancel_req).wait(self.poll_interval)

    def _poll_job(self, state: JobState, names: tuple, offsets: list, layers: list):
        """(job JSON, whether it is our file (uploaded under one of `names`), completion % or None, its
        progress block), temperatures read too; lines done and layer updated in `state` from our job's
        progress."""
        job = self._request("GET", "/api/job").json()
        self._read_temperatures()
        file_name = ((job.get("job") or {}).get("file") or {}).get("name")
        prog = job.get("progress") or {}
        completion = prog.get("completion")
        filepos = prog.get("filepos") or 0
        ours = file_name in names
        if ours and completion is not None:
            # After a cancel OctoPrint reports no progress: keep the last known.
            fraction = completion / 100.0
            state.commands_done = int(round(fraction * state.commands_total))
            if offsets:
                i = bisect.bisect_right(offsets, filepos) - 1
                state.layer = layers[i] if i >= 0 else -1
        return job, ours, completion, prog

    def _progress(self, state: JobState, text: str, cancelling: bool, prog: dict, elapsed: float) -> Progress:
        """The Progress to report for OctoPrint's state `text` and progress block `prog`."""
        low = text.lower()
        fraction = state.commands_done / state.commands_total if state.commands_total else 0.0
        kind = PAUSED if "paus" in low else CANCELLING if cancelling or "cancel" in low else PRINTING
        if "heat" in low:
            kind = HEATING
        left = prog.get("printTimeLeft")
        return Progress(
            state=kind, lines_done=state.commands_done, lines_total=state.commands_total,
            layer=state.layer, layer_count=state.layer_count, percent=100.0 * fraction,
            elapsed_s=elapsed,
            eta_s=float(left) if left is not None else eta(state.commands_done, state.commands_total, elapsed),
            temperatures=dict(self.temperatures), message=text,
        )

    def _job_ended(self, state: JobState, job: dict, text: str, back: bool, cancelling: bool,
                   completion: float | None, layers: list[int], progress, elapsed: float) -> bool:
        """Whether OctoPrint's job state `text` ends our job: raises PrinterHalted or LinkLost on a printer
        error or a lost printer; when the printer is `back` to operational after our job, sets `state`
        to cancelled or done and returns True. Calls _finish(state, ...) in every ending."""
        low = text.lower()
        if low.startswith("error") or low.startswith("offline after error"):
            state.status, state.message = "halted", job.get("error") or text
            self._finish(state, progress, elapsed)
            raise PrinterHalted(f"OctoPrint reports a printer error: {state.message}", state, self.job_path)
        if low.startswith(("offline", "closed")):
            state.status, state.message = "link_lost", f"OctoPrint lost its printer ({text})"
            self._finish(state, progress, elapsed)
            raise LinkLost(state.message, state, self.job_path)
        if not back:
            return False
        if cancelling or (completion is not None and completion < 100.0):
            state.status = CANCELLED
        else:
            state.status = DONE
            state.commands_done = state.commands_total
            if layers:
                state.layer = layers[-1]
        self._finish(state, progress, elapsed)
        return True

    def _read_temperatures(self) -> None:
        try:
            r = self._request("GET", "/api/printer", params={"exclude": "sd,state"})
        except OctoPrintError:
            return  # 409 while the printer is not operational
        temps = (r.json() or {}).get("temperature") or {}
        names = {"tool0": "T", "bed": "B", "chamber": "C"}
        for key, value in temps.items():
            if key in names and isinstance(value, dict) and value.get("actual") is not None:
                self.temperatures[names[key]] = (float(value["actual"]),
                                                 None if value.get("target") is None else float(value["target"]))
        if self.state is not None:
            self.state.read_temperatures(self.temperatures)

    def _finish(self, state: JobState, progress, elapsed: float) -> None:
        finish_job(state, self.job_path, progress, elapsed, self.temperatures)
