"""PrusaLink link: a Prusa printer reached through PrusaLink's HTTP API (version 1), as Prusa's own web page
and PrusaSlicer's "Send to printer" reach it. The MK4, MINI, XL and CORE One run PrusaLink inside their
Buddy firmware; the MK3S/MK2.5 run it on a Raspberry Pi (`prusalink` on the package index). Both speak
the same API:

`GET /api/version` (server, firmware, printer kind), `GET /api/v1/status` (printer state, temperatures,
storage, the current job's id and percent done), `GET /api/v1/job`, `PUT /api/v1/files/<storage>/<name>`
with `Print-After-Upload: ?1` (store and start in one request; the storage is the first writable one the
status lists: `local` on the Pi, `usb` on the Buddy printers), `PUT /api/v1/job/<id>/pause|resume`,
`DELETE /api/v1/job/<id>` (stop: the firmware's own stop sequence, heaters and motors off).

Authentication: an API key (`X-Api-Key`) or HTTP digest with PrusaLink's user and password (the Buddy
printers' default). The secrets rules of arapp.printing.link.webapi hold for both: read from files of mode
600, never on the command line, in a message, a log or a repr; dropped (the key header and the digest
hook) on a redirect to another host.

Progress: PrusaLink reports percent done (`job.progress`), not a file position, so the commands done are
that fraction of the file's bytes mapped to commands (FileProgress.at_fraction): a whole-percent step.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from urllib.parse import quote

import requests

from .base import (
    CANCELLED,
    CANCELLING,
    DONE,
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
from .webapi import (API_KEY_HEADER, FileProgress, SecretSession, check_base_url, finish_job, gcode_bytes,
                     server_message, unanswered)

log = logging.getLogger("arapp.printing.prusalink")

# PrusaLink's printer states (prusa.connect.printer.const.State)
READY_STATES = ("IDLE", "READY", "FINISHED", "STOPPED")
ACTIVE_STATES = ("PRINTING", "PAUSED", "ATTENTION")
KEY_HINT = ("the key is on the printer (Settings > Network > PrusaLink) or in PrusaLink's web page "
            "(Settings > API key)")


class PrusaLinkError(LinkError):
    """PrusaLink (or the printer behind it) refused a request; the message is one line for the user."""


class PrusaLinkLink(PrintLink):
    """A Prusa printer behind PrusaLink (url like http://prusa-mk4.local or http://192.168.1.20).

    api_key: PrusaLink's API key; or user + password for HTTP digest (one of the two is needed).
    """

    def __init__(self, url: str, api_key: str | None = None, *, user: str | None = None,
                 password: str | None = None, timeout: float = 30.0, job_path=None, name: str = "arapp.gcode",
                 poll_interval: float = 0.25, settle_s: float = 15.0):
        self.url = check_base_url(url, "PrusaLink", "http://prusa-mk4.local")
        if not api_key and not (user and password):
            raise ValueError("PrusaLink needs its API key (--api-key-file F) or its user and password "
                             "(--prusalink-user NAME --password-file F)")
        self._key = api_key or None
        self._user, self._password = (user, password) if not api_key else (None, None)
        self.timeout = float(timeout)
        self.poll_interval = min(0.25, float(poll_interval))  # cancel is looked at 4 times a second
        self.settle_s = float(settle_s)
        self.job_path = job_path
        self.name = name
        self._session: SecretSession | None = None
        self._cancel_req = threading.Event()
        self._cancel_lock = threading.Lock()
        self._cancel_sent = False
        self.version = ""
        self.printer_kind = ""
        self.status: dict = {}
        self.temperatures: dict = {}
        self.state: JobState | None = None
        self.job_id: int | None = None

    def __repr__(self):
        return f"PrusaLinkLink({self.url!r})"  # never the key or password

    # ----------------------------------------------------------------- http
    def _open_session(self) -> None:
        self._session = SecretSession()
        if self._key:
            self._session.headers[API_KEY_HEADER] = self._key
        else:
            self._session.auth = requests.auth.HTTPDigestAuth(self._user, self._password)

    def _request(self, method: str, path: str, **kw) -> requests.Response:
        if self._session is None:
            raise LinkError("not connected to PrusaLink: call connect() first")
        try:
            r = self._session.request(method, self.url + path, timeout=self.timeout, allow_redirects=True, **kw)
        except requests.RequestException as exc:
            raise LinkLost(unanswered("PrusaLink", self.url, method, path, exc, self.timeout)) from None
        where = path.split("?")[0]
        if r.status_code in (401, 403):
            if self._key:
                raise PrusaLinkError(f"PrusaLink at {self.url} refused the API key (HTTP {r.status_code}); "
                                     f"check the key file ({KEY_HINT})")
            raise PrusaLinkError(f"PrusaLink at {self.url} refused the user name or password (HTTP "
                                 f"{r.status_code}); check them in the printer's Settings > Network > PrusaLink")
        if r.status_code == 413:
            raise PrusaLinkError(f"PrusaLink at {self.url} refused the file as too large (HTTP 413: "
                                 f"{server_message(r) or 'no room'}); free space on the printer's storage")
        if r.status_code == 409:
            raise PrusaLinkError(f"PrusaLink at {self.url} refused {method} {where}: the printer is busy or not "
                                 f"ready ({self._printer_state_text()}; HTTP 409: {server_message(r) or 'conflict'})")
        if r.status_code >= 400:
            raise PrusaLinkError(f"PrusaLink {method} {where} failed: HTTP {r.status_code}: "
                                 f"{server_message(r) or 'no reason given'}")
        return r

    def _json(self, method: str, path: str, **kw) -> dict:
        r = self._request(method, path, **kw)
        if r.status_code == 204 or not r.content:
            return {}
        try:
            body = r.json()
        except ValueError:
            raise PrusaLinkError(f"{self.url}{path} answered, but not as PrusaLink does (no JSON); "
                                 "check the address") from None
        return body if isinstance(body, dict) else {}

    def _printer_state_text(self) -> str:
        printer = self.status.get("printer") or {}
        text = f"state {printer.get('state', 'unknown')}"
        sp = printer.get("status_printer") or {}
        if sp and not sp.get("ok", True) and sp.get("message"):
            text += f": {sp['message']}"
        return text

    def read_status(self) -> dict:
        """`GET /api/v1/status`, kept in `status`; temperatures updated."""
        self.status = self._json("GET", "/api/v1/status")
        printer = self.status.get("printer") or {}
        for key, actual, target in (("T", "temp_nozzle", "target_nozzle"), ("B", "temp_bed", "target_bed")):
            if printer.get(actual) is not None:
                t = printer.get(target)
                self.temperatures[key] = (float(printer[actual]), None if t is None else float(t))
        if self.state is not None:
            self.state.read_temperatures(self.temperatures)
        return self.status

    def connect(self) -> None:
        self._open_session()
        info = self._json("GET", "/api/version")
        self.version = str(info.get("text") or f"PrusaLink {info.get('server', '')}").strip()
        self.printer_kind = str(info.get("original") or "")
        self.read_status()
        printer = self.status.get("printer") or {}
        state = printer.get("state")
        sp = printer.get("status_printer") or {}
        if state not in READY_STATES or not sp.get("ok", True):
            raise PrusaLinkError(f"the printer behind PrusaLink at {self.url} is not ready to print "
                                 f"({self._printer_state_text()}); see the printer's screen")

    def close(self) -> None:
        if self._session is not None:
            self._session.close()
        self._session = None

    # ------------------------------------------------------------ controls
    def _job(self) -> int:
        if self.job_id is None:
            job = (self.read_status().get("job") or {})
            if job.get("id") is None:
                raise PrusaLinkError(f"PrusaLink at {self.url} runs no job ({self._printer_state_text()})")
            self.job_id = int(job["id"])
        return self.job_id

    def pause(self) -> None:
        self._request("PUT", f"/api/v1/job/{self._job()}/pause")

    def resume(self) -> None:
        self._request("PUT", f"/api/v1/job/{self._job()}/resume")

    def cancel(self) -> None:
        """Stop the job: PrusaLink stops sending it and has the firmware run its own stop sequence (M603 on the
        MK3S: heaters off, the head parked)."""
        self._cancel_req.set()
        self._send_cancel()

    def _send_cancel(self) -> None:
        """DELETE the job once its id is known (before that, the print loop sends it as soon as it is)."""
        with self._cancel_lock:
            if self._cancel_sent:
                return
            job_id = self.job_id  # set by the print loop once PrusaLink shows our job
            if job_id is None:
                return
            try:
                self._request("DELETE", f"/api/v1/job/{int(job_id)}")
            except PrusaLinkError as exc:
                log.warning("cancel: %s", exc)  # the job may have ended meanwhile; the print loop sees that
            self._cancel_sent = True

    # ----------------------------------------------------------------- job
    def storage(self) -> str:
        """The first writable storage PrusaLink lists (`local` on the Pi, `usb` on the Buddy printers)."""
        for item in self.status.get("storage") or []:
            if isinstance(item, dict) and not item.get("read_only") and item.get("path"):
                return str(item["path"]).strip("/")
        return "usb"

    def upload(self, data: bytes, name: str | None = None, start: bool = True) -> str:
        """Store G-code bytes in PrusaLink's writable storage (replacing a file of that name), optionally
        starting the print; returns the path it was stored at (`/storage/name`)."""
        name = name or self.name
        free = next((item.get("free_space") for item in self.status.get("storage") or []
                     if isinstance(item, dict) and not item.get("read_only")), None)
        if isinstance(free, (int, float)) and len(data) > free:
            raise PrusaLinkError(f"the G-code is {len(data) / 1048576:.1f} MB; the printer's storage behind "
                                 f"PrusaLink at {self.url} has {free / 1048576:.1f} MB free")
        storage = self.storage()
        headers = {"Content-Type": "text/x.gcode", "Overwrite": "?1", "Print-After-Upload": "?1" if start else "?0"}
        self._request("PUT", f"/api/v1/files/{storage}/{quote(name)}", data=data, headers=headers)
        return f"/{storage}/{name}"

    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        gcode_path: str = "",
    ) -> JobState:
        """Upload and start the G-code, then follow PrusaLink's status until the job ends. Returns the final
        job state; raises PrusaLinkError (refused), PrinterHalted (the printer's error state), LinkLost."""
        if self._session is None:
            raise LinkError("not connected to PrusaLink: call connect() first")
        data = gcode_bytes(lines)
        program = Program.from_lines(data.decode("utf-8").splitlines())
        fp = FileProgress(data, program)
        state = new_state(program, gcode_path)
        state.port, state.status = self.url, PRINTING
        self.state = state
        name = Path(gcode_path).name if gcode_path else self.name
        self._cancel_req.clear()
        self._cancel_sent = False
        self.job_id = None
        if not self._settled(cancel, progress, state):
            state.status = CANCELLED
            self._finish(state, progress, 0.0)
            return state
        before = (self.status.get("job") or {}).get("id")
        # PrusaLink starts the print before it answers the upload (Print-After-Upload): a 201 means started,
        # so a FINISHED or STOPPED state seen afterwards is this job's end, even one too short to be polled
        self.upload(data, name=name, start=True)
        t0 = time.monotonic()
        while True:
            if cancel is not None and cancel.is_set():
                self._cancel_req.set()
            cancelling = self._cancel_req.is_set()
            status = self.read_status()
            elapsed = time.monotonic() - t0
            printer_state = (status.get("printer") or {}).get("state")
            job = status.get("job") or {}
            if job.get("id") is not None and job.get("id") != before:
                self.job_id = int(job["id"])
            if cancelling and self.job_id is not None:
                self._send_cancel()
            if self.job_id is not None and job.get("progress") is not None:
                done, layer = fp.at_fraction(float(job["progress"]) / 100.0)
                if done >= state.commands_done:
                    state.commands_done, state.layer = done, layer
            if printer_state in ("FINISHED", "STOPPED", "IDLE", "READY", "ERROR"):
                return self._ended(state, printer_state, cancelling, fp, progress, elapsed)
            if progress is not None:
                kind = CANCELLING if cancelling else PAUSED if printer_state in ("PAUSED", "ATTENTION") else PRINTING
                total = state.commands_total
                message = "the printer needs attention (see its screen)" if printer_state == "ATTENTION" else ""
                progress(Progress(
                    state=kind, lines_done=state.commands_done, lines_total=total, layer=state.layer,
                    layer_count=state.layer_count, percent=100.0 * state.commands_done / total if total else 0.0,
                    elapsed_s=elapsed, eta_s=eta(state.commands_done, total, elapsed),
                    temperatures=dict(self.temperatures), message=message,
                ))
            time.sleep(self.poll_interval)  # PrusaLink has no push channel in its v1 API: poll at 4 Hz

    def _settled(self, cancel, progress, state: JobState) -> bool:
        """Wait (at most `settle_s`) while PrusaLink still shows the last job FINISHED or STOPPED: it takes no
        new job for 11 s after one ends (PRINT_END_TIMEOUT, the time a user has to see the result). False when
        cancelled meanwhile; after the wait the upload goes ahead and PrusaLink's own refusal is the answer."""
        deadline = time.monotonic() + self.settle_s
        while True:
            printer_state = (self.read_status().get("printer") or {}).get("state")
            if printer_state not in ("FINISHED", "STOPPED") or time.monotonic() > deadline:
                return True
            if (cancel is not None and cancel.is_set()) or self._cancel_req.is_set():
                return False
            if progress is not None:
                progress(Progress(state=PRINTING, lines_total=state.commands_total, layer_count=state.layer_count,
                                  temperatures=dict(self.temperatures),
                                  message=f"waiting for the printer to leave {printer_state} (the last job's end)"))
            time.sleep(self.poll_interval)

    def _heaters_left_on(self, wait_s: float = 10.0) -> list[str]:
        """The heaters ("T", "B") that still have a target after a stop. PrusaLink reads the printer's
        temperatures on its own schedule, so its status may show the targets of before the firmware's stop
        sequence for a few seconds: look again (4 times a second, at most `wait_s`) before saying so."""
        deadline = time.monotonic() + wait_s
        while True:
            hot = [k for k, (_, target) in self.temperatures.items() if target]
            if not hot or time.monotonic() > deadline:
                return hot
            time.sleep(self.poll_interval)
            self.read_status()

    def _ended(self, state: JobState, printer_state: str, cancelling: bool, fp: FileProgress, progress,
               elapsed: float) -> JobState:
        if printer_state == "ERROR":
            sp = ((self.status.get("printer") or {}).get("status_printer") or {})
            state.status, state.message = "halted", str(sp.get("message") or "printer error")
            self._finish(state, progress, elapsed)
            raise PrinterHalted(f"the printer stopped the print: {state.message}", state, self.job_path)
        if printer_state == "FINISHED" or (printer_state in ("IDLE", "READY") and not cancelling):
            state.status = DONE
            state.commands_done, state.layer = state.commands_total, fp.at(fp.size)[1]
        else:
            state.status = CANCELLED
            # the firmware's stop sequence turns the heaters off; PrusaLink's API sends no G-code of ours, so
            # all the link can do is say when a heater still has a target
            hot = self._heaters_left_on()
            if hot:
                state.message = (f"the printer still reports heater targets after the stop ({', '.join(hot)}); "
                                 "turn them off on its screen")
        self._finish(state, progress, elapsed)
        return state

    def _finish(self, state: JobState, progress, elapsed: float) -> None:
        finish_job(state, self.job_path, progress, elapsed, self.temperatures)


def check_prusalink(url: str, api_key: str | None = None, *, user: str | None = None, password: str | None = None,
                    timeout_s: float = 5.0) -> tuple[bool, str, dict]:
    """Test connection: (ok, one line for the user, details) from `/api/version` and `/api/v1/status`. Never
    raises for a server that is off, refuses the credentials or has the printer not ready."""
    try:
        link = PrusaLinkLink(url, api_key, user=user, password=password, timeout=timeout_s)
        link.connect()
    except (ValueError, LinkError) as exc:
        return False, str(exc), {}
    finally:
        if "link" in locals():
            link.close()
    printer = link.status.get("printer") or {}
    details = {"version": link.version, "printer": link.printer_kind, "state": printer.get("state")}
    return True, f"{link.version}: {link.printer_kind or 'printer'} {printer.get('state')}", details
