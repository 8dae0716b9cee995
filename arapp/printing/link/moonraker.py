"""Moonraker link: a Klipper printer reached through Moonraker's HTTP API and its websocket (as Mainsail,
Fluidd and KlipperScreen reach it).

HTTP (moonraker.readthedocs.io, "Printer Administration", "File Manager"): `GET /server/info` (is Klippy
connected and ready), `GET /printer/info` (Klippy's state message), `GET /server/config` (the upload
limit), `POST /server/files/upload` (multipart `file`, `root=gcodes`, `print=true` starts it),
`POST /printer/print/{start,pause,resume,cancel}`, `POST /printer/gcode/script` (TURN_OFF_HEATERS after a
cancel), `GET /access/oneshot_token` (a one-use token that opens the websocket without the key).
Websocket (`/websocket`, JSON-RPC 2.0): `printer.objects.subscribe` for `print_stats` (state, file name,
message), `virtual_sdcard` (file position), `extruder` and `heater_bed` (temperature, target); Moonraker
then sends `notify_status_update` with what changed, and `notify_klippy_shutdown` /
`notify_klippy_disconnected` when Klipper stops.

The API key (`X-Api-Key`) is optional: Moonraker lets its `trusted_clients` in without one. With a key,
the same rules as OctoPrint's hold (arapp.printing.link.webapi): file of mode 600, never in argv, a
message or a repr, dropped from a redirect to another host; the websocket is opened with a oneshot token
instead of the key, and never follows a redirect.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path

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

log = logging.getLogger("arapp.printing.moonraker")

# What the link subscribes to (Klipper's status reference: print_stats, virtual_sdcard, heaters).
SUBSCRIPTION = {
    "print_stats": ["state", "filename", "message", "print_duration", "total_duration"],
    "virtual_sdcard": ["file_position", "file_size", "file_path", "progress", "is_active"],
    "extruder": ["temperature", "target"],
    "heater_bed": ["temperature", "target"],
}
KEY_HINT = ("the key is Moonraker's API key (Mainsail/Fluidd: Settings > ... > API key; or "
            "`GET /access/api_key` from a trusted machine)")


class MoonrakerError(LinkError):
    """Moonraker (or Klipper behind it) refused a request; the message is one line for the user."""


class FileInUse(MoonrakerError):
    """Moonraker will not replace (or delete) the file Klipper is printing or has paused (its HTTP 403)."""


# Moonraker's words when it refuses to touch the file a job has loaded (file_manager: HTTP 403)
IN_USE_MESSAGES = ("file currently in use", "file is loaded")
IN_USE_RETRY_S = 0.25   # Klipper reports its state every 250 ms


def first_line(text) -> str:
    """The first non-empty line of a Klipper message (its shutdown messages run to many lines)."""
    for line in str(text or "").splitlines():
        if line.strip():
            return line.strip()
    return ""


class RpcSocket:
    """Moonraker's websocket as JSON-RPC 2.0: `call` waits for its answer, keeping the notifications that
    arrive meanwhile for `poll`. Used from one thread (the print loop's)."""

    def __init__(self, url: str, timeout: float, where: str):
        import websocket  # websocket-client: only for Moonraker

        self._wsmod = websocket
        self.where = where
        try:
            self._ws = websocket.create_connection(url, timeout=timeout, redirect_limit=0)
        except (websocket.WebSocketException, OSError) as exc:
            raise LinkLost(f"Moonraker's websocket at {where} cannot be opened: {type(exc).__name__}") from None
        status = getattr(self._ws.handshake_response, "status", 101)
        if status != 101:
            self._ws.close()
            raise MoonrakerError(f"Moonraker at {where} answered the websocket with HTTP {status} (a redirect is "
                                 "not followed); give the server's own address")
        self._next = 0
        self.pending: deque[dict] = deque()

    def close(self) -> None:
        try:
            self._ws.close()
        except (self._wsmod.WebSocketException, OSError):
            pass

    def _recv(self, timeout: float) -> dict | None:
        self._ws.settimeout(max(0.01, timeout))
        try:
            raw = self._ws.recv()
        except self._wsmod.WebSocketTimeoutException:
            return None
        except (self._wsmod.WebSocketException, OSError) as exc:
            raise LinkLost(f"Moonraker at {self.where} closed the websocket ({type(exc).__name__})") from None
        if not raw:
            raise LinkLost(f"Moonraker at {self.where} closed the websocket")
        try:
            msg = json.loads(raw)
        except ValueError:
            return None
        return msg if isinstance(msg, dict) else None

    def call(self, method: str, params: dict | None = None, timeout: float = 10.0):
        self._next += 1
        ident = self._next
        self._ws.send(json.dumps({"jsonrpc": "2.0", "method": method, "params": params or {}, "id": ident}))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise LinkLost(f"Moonraker at {self.where} did not answer {method} within {timeout:g} s")
            msg = self._recv(left)
            if msg is None:
                continue
            if msg.get("id") == ident:
                if "error" in msg:
                    err = msg["error"] if isinstance(msg["error"], dict) else {"message": msg["error"]}
                    raise MoonrakerError(f"Moonraker refused {method}: {first_line(err.get('message'))}")
                return msg.get("result")
            if "method" in msg:
                self.pending.append(msg)

    def poll(self, wait: float) -> list[dict]:
        """The notifications received, waiting up to `wait` seconds for one when none is kept."""
        if not self.pending:
            msg = self._recv(wait)
            if msg is not None and "method" in msg:
                self.pending.append(msg)
        out = list(self.pending)
        self.pending.clear()
        return out


class JobWatch:
    """Our job as Moonraker's `print_stats` shows it: `update(print_stats)` -> "waiting" (not seen yet),
    "printing", "paused", "done", "cancelled" or "error".

    Klipper reports what changed every 250 ms, so a short job can start and end between two reports:
    the job counts as seen once print_stats names our file and differs from its values before the upload
    (state, file, durations), or once it was printing. `SDCARD_PRINT_FILE` loads the file (state "standby",
    our file name, durations 0) and starts reading it on the reactor's next turn: a report between the two
    shows our file in standby, which is a job about to start, not one that ended; once seen, our file
    leaving the report before the job was seen printing means it was reset or replaced, and our file still
    in standby `start_wait_s` seconds later means Klipper did not start it (both end the job as cancelled).
    """

    ACTIVE = ("printing", "paused")
    _FIELDS = ("state", "filename", "total_duration", "print_duration")

    def __init__(self, filename: str, before: dict, start_wait_s: float = 10.0):
        self.filename = filename
        self.before = {k: before.get(k) for k in self._FIELDS}
        self.started = False
        self.loaded_at: float | None = None  # time.monotonic() when our file was first seen loaded
        self.start_wait_s = start_wait_s

    def update(self, ps: dict, now: float | None = None) -> str:
        """The job's outcome so far from print_stats `ps` (Klipper's fields merged as reported) at `now`
        (time.monotonic() seconds; the clock when None)."""
        now = time.monotonic() if now is None else now
        state, ours = ps.get("state"), ps.get("filename") == self.filename
        if ours and state in self.ACTIVE:
            self.started = True
            return state
        loaded = self.loaded_at is not None
        fresh = self.started or loaded or (ours and any(ps.get(k) != self.before[k] for k in self._FIELDS))
        if not fresh:
            return "waiting"
        if state == "standby" and ours and not self.started:
            self.loaded_at = now if self.loaded_at is None else self.loaded_at
            return "waiting" if now - self.loaded_at < self.start_wait_s else "cancelled"
        if state == "complete" and ours:
            return "done"
        if state == "error":
            return "error"
        # cancelled, or reset to standby (SDCARD_RESET_FILE), or another file took over
        return "cancelled"


class MoonrakerLink(PrintLink):
    """A Klipper printer behind Moonraker (url like http://mainsailos.local or http://host:7125).

    api_key: Moonraker's API key, or None on a trusted LAN (Moonraker's `trusted_clients`). in_use_wait_s:
    seconds an upload is asked again while Moonraker still counts a job of the same file name as printing
    (right after that job ended, until Klipper's next report reaches it).
    """

    def __init__(self, url: str, api_key: str | None = None, *, timeout: float = 30.0, job_path=None,
                 name: str = "arapp.gcode", poll_interval: float = 0.25, in_use_wait_s: float = 5.0):
        self.url = check_base_url(url, "Moonraker", "http://mainsailos.local")
        self.in_use_wait_s = float(in_use_wait_s)
        self._key = api_key or None
        self.timeout = float(timeout)
        self.poll_interval = min(0.25, float(poll_interval))  # cancel is looked at 4 times a second
        self.job_path = job_path
        self.name = name
        self._session: SecretSession | None = None
        self._rpc: RpcSocket | None = None
        self._cancel_req = threading.Event()
        self.version = ""
        self.klippy_state = ""
        self.max_upload: int | None = None
        self.status: dict = {k: {} for k in SUBSCRIPTION}
        self.temperatures: dict = {}
        self.state: JobState | None = None
        self._halt: str | None = None

    def __repr__(self):
        return f"MoonrakerLink({self.url!r})"  # never the key

    # ----------------------------------------------------------------- http
    def _request(self, method: str, path: str, **kw):
        if self._session is None:
            raise LinkError("not connected to Moonraker: call connect() first")
        try:
            r = self._session.request(method, self.url + path, timeout=self.timeout, **kw)
        except requests.RequestException as exc:
            raise LinkLost(unanswered("Moonraker", self.url, method, path, exc, self.timeout)) from None
        if r.status_code == 403 and any(m in r.text.lower() for m in IN_USE_MESSAGES):
            # (Moonraker 0.11 answers "Forbidden" and names the reason only in its traceback)
            raise FileInUse(f"Moonraker at {self.url} refused {method} {path.split('?')[0]} (HTTP 403): Klipper is "
                            "printing that file; wait for its job to end, or cancel it")
        if r.status_code == 401:   # (Moonraker's 403s are about files and folders, never the key)
            if self._key:
                raise MoonrakerError(f"Moonraker at {self.url} refused the API key (HTTP {r.status_code}); "
                                     f"check the key file ({KEY_HINT})")
            raise MoonrakerError(f"Moonraker at {self.url} wants an API key (HTTP {r.status_code}: this computer "
                                 f"is not one of its trusted_clients); give --api-key-file F ({KEY_HINT})")
        if r.status_code == 413:
            raise MoonrakerError(f"Moonraker at {self.url} refused the file as too large (HTTP 413); raise "
                                 "max_upload_size in moonraker.conf [server]")
        if r.status_code >= 400:
            detail = server_message(r) or "no reason given"
            raise MoonrakerError(f"Moonraker {method} {path.split('?')[0]} failed: HTTP {r.status_code}: {detail}")
        try:
            body = r.json()
        except ValueError:
            raise MoonrakerError(f"{self.url}{path} answered, but not as Moonraker does (no JSON); "
                                 "check the address") from None
        # Moonraker wraps answers in {"result": ...}, except the upload's (a bare object)
        return body["result"] if isinstance(body, dict) and "result" in body else body

    def _klippy_not_ready(self, state: str) -> MoonrakerError:
        try:
            message = first_line(self._request("GET", "/printer/info").get("state_message"))
        except LinkError:
            message = ""
        why = f"state {state}" + (f": {message}" if message else "")
        return MoonrakerError(f"Klipper behind Moonraker at {self.url} is not ready ({why}); fix that (e.g. "
                              "FIRMWARE_RESTART in Mainsail/Fluidd) and try again")

    def connect(self) -> None:
        self._session = SecretSession()
        if self._key:
            self._session.headers[API_KEY_HEADER] = self._key
        info = self._request("GET", "/server/info") or {}
        self.version = f"Moonraker {info.get('moonraker_version', '')}".strip()
        self.klippy_state = str(info.get("klippy_state", ""))
        if not info.get("klippy_connected"):
            raise MoonrakerError(f"Moonraker at {self.url} is not connected to Klipper (state "
                                 f"{self.klippy_state or 'disconnected'}); start Klipper (klippy) first")
        if self.klippy_state != "ready":
            raise self._klippy_not_ready(self.klippy_state)
        try:
            size = ((self._request("GET", "/server/config") or {}).get("config") or {}).get("server", {})
            self.max_upload = int(size["max_upload_size"]) * 1024 * 1024 if "max_upload_size" in size else None
        except (LinkError, ValueError, TypeError, AttributeError):
            self.max_upload = None  # not every Moonraker lets a user read its config
        self._open_socket()

    def _open_socket(self) -> None:
        ws_url = "ws" + self.url[len("http"):] + "/websocket"
        if self._key:
            token = self._request("GET", "/access/oneshot_token")
            ws_url += f"?token={token}"
        self._rpc = RpcSocket(ws_url, self.timeout, self.url)
        result = self._rpc.call("printer.objects.subscribe", {"objects": SUBSCRIPTION}, timeout=self.timeout)
        for name, fields in ((result or {}).get("status") or {}).items():
            self.status.setdefault(name, {}).update(fields or {})
        self._read_temperatures()

    def close(self) -> None:
        if self._rpc is not None:
            self._rpc.close()
        self._rpc = None
        if self._session is not None:
            self._session.close()
        self._session = None

    # ------------------------------------------------------------ controls
    def pause(self) -> None:
        self._request("POST", "/printer/print/pause")

    def resume(self) -> None:
        self._request("POST", "/printer/print/resume")

    def cancel(self) -> None:
        """Cancel the job (Klipper's CANCEL_PRINT: the printer's own macro when it has one); the print loop
        then turns the heaters off."""
        self._cancel_req.set()
        self._request("POST", "/printer/print/cancel")

    def start(self, name: str) -> None:
        """Start printing the stored file `name` (a path in the gcodes root)."""
        try:
            self._request("POST", "/printer/print/start", params={"filename": name})
        except MoonrakerError as exc:
            busy = (self.status.get("print_stats") or {}).get("state", "")
            if busy in JobWatch.ACTIVE:
                raise MoonrakerError(f"Klipper at {self.url} is busy ({busy} {self.status['print_stats'].get('filename')}); "
                                     f"{name} is stored but not started: wait for that job to end") from None
            raise MoonrakerError(f"Klipper at {self.url} did not start {name}: {str(exc).split(': ', 1)[-1]}") from None

    # ----------------------------------------------------------------- job
    def upload(self, data: bytes, name: str | None = None, start: bool = True) -> dict:
        """Store G-code bytes in Moonraker's `gcodes` root, optionally starting the print; returns
        Moonraker's answer (`item.path`, `print_started`)."""
        name = name or self.name
        if self.max_upload is not None and len(data) > self.max_upload:
            raise MoonrakerError(
                f"the G-code is {len(data) / 1048576:.1f} MB; Moonraker at {self.url} takes uploads up to "
                f"{self.max_upload / 1048576:g} MB (max_upload_size in moonraker.conf [server])")
        files = {"file": (name, data, "application/octet-stream")}
        form = {"root": "gcodes", "print": "true" if start else "false"}
        try:
            return self._upload_when_free(name, files, form)
        except FileInUse:
            raise
        except MoonrakerError as exc:
            if "HTTP 400: no reason given" not in str(exc):
                raise
            how = "HTTP 400"
        except LinkLost:
            self._request("GET", "/server/info")  # still there? (else: LinkLost, it went away)
            how = "it closed the connection"
        # Tornado drops a body over max_upload_size with a bare 400, or closes the connection mid-body
        raise MoonrakerError(f"Moonraker at {self.url} refused the upload of {name} ({len(data) / 1048576:.1f} MB) "
                             f"without a reason ({how}): it refuses a file over its max_upload_size that way "
                             "(moonraker.conf [server])") from None

    def _upload_when_free(self, name: str, files: dict, form: dict) -> dict:
        """POST the upload; while Moonraker still counts a job of the same file name as printing (it learns
        that a job ended from Klipper's next report, which can come after ours), ask again for up to
        `in_use_wait_s`, then say why it was refused (FileInUse)."""
        deadline = time.monotonic() + self.in_use_wait_s
        while True:
            try:
                return self._request("POST", "/server/files/upload", files=files, data=form) or {}
            except FileInUse as exc:
                if time.monotonic() >= deadline:
                    raise FileInUse(f"Moonraker at {self.url} will not replace {name} while Klipper prints it "
                                    f"(HTTP 403, still after {self.in_use_wait_s:g} s): wait for that job to end, "
                                    "cancel it, or print under another file name") from exc
                if self._cancel_req.wait(IN_USE_RETRY_S):
                    raise   # cancelled meanwhile: no more tries

    def _take(self, notes: list[dict]) -> None:
        """Apply Moonraker's notifications to `status`; remember a Klipper shutdown or disconnect."""
        for note in notes:
            method = note.get("method")
            params = note.get("params") or []
            if method == "notify_status_update" and params and isinstance(params[0], dict):
                for name, fields in params[0].items():
                    if isinstance(fields, dict):
                        self.status.setdefault(name, {}).update(fields)
            elif method == "notify_klippy_shutdown":
                self._halt = "shutdown"
            elif method == "notify_klippy_disconnected":
                self._halt = self._halt or "disconnected"
        self._read_temperatures()

    def _read_temperatures(self) -> None:
        for key, name in (("T", "extruder"), ("B", "heater_bed")):
            heater = self.status.get(name) or {}
            if heater.get("temperature") is not None:
                target = heater.get("target")
                self.temperatures[key] = (float(heater["temperature"]), None if target is None else float(target))
        if self.state is not None:
            self.state.read_temperatures(self.temperatures)

    def print_gcode(
        self,
        lines: Sequence[str],
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
        *,
        gcode_path: str = "",
    ) -> JobState:
        """Upload and start the G-code, then follow Moonraker's status until the job ends. Returns the final
        job state; raises MoonrakerError (refused), PrinterHalted (Klipper's error or shutdown), LinkLost."""
        if self._rpc is None:
            raise LinkError("not connected to Moonraker: call connect() first")
        data = gcode_bytes(lines)
        program = Program.from_lines(data.decode("utf-8").splitlines())
        fp = FileProgress(data, program)
        state = new_state(program, gcode_path)
        state.port, state.status = self.url, PRINTING
        self.state = state
        name = Path(gcode_path).name if gcode_path else self.name
        self._take(self._rpc.poll(0))
        watch = JobWatch(name, self.status.get("print_stats") or {})
        self._cancel_req.clear()
        # Stored first, then started as a request of its own: Klipper itself refuses a start while it is busy
        # (one clear line), where an upload's `print=true` leaves the file unstarted when Moonraker's own job
        # record still shows the previous job running (it lags a job that ended within Klipper's report period).
        info = self.upload(data, name=name, start=False)
        name = (info.get("item") or {}).get("path") or name
        watch.filename = name
        self.start(name)
        t0 = time.monotonic()
        cancelling = False
        while True:
            if cancel is not None and cancel.is_set() and not cancelling:
                self.cancel()
            cancelling = cancelling or self._cancel_req.is_set()
            self._take(self._rpc.poll(self.poll_interval))
            elapsed = time.monotonic() - t0
            if self._halt:
                self._klippy_stopped(state, progress, elapsed)
            ps = self.status.get("print_stats") or {}
            outcome = watch.update(ps)
            vsd = self.status.get("virtual_sdcard") or {}
            if watch.started and vsd.get("file_size") == fp.size and str(vsd.get("file_path") or "").endswith(name):
                done, layer = fp.at(vsd.get("file_position") or 0)
                if done >= state.commands_done:  # a cancel resets the position to 0: keep the last
                    state.commands_done, state.layer = done, layer
            if outcome == "done":
                state.layer = fp.at(fp.size)[1]
            if outcome in ("done", "cancelled", "error"):
                return self._ended(state, outcome, ps, progress, elapsed)
            if progress is not None:
                kind = CANCELLING if cancelling else PAUSED if outcome == "paused" else PRINTING
                total = state.commands_total
                progress(Progress(
                    state=kind, lines_done=state.commands_done, lines_total=total, layer=state.layer,
                    layer_count=state.layer_count, percent=100.0 * state.commands_done / total if total else 0.0,
                    elapsed_s=elapsed, eta_s=eta(state.commands_done, total, elapsed),
                    temperatures=dict(self.temperatures), message=str(ps.get("message") or ""),
                ))

    def _klippy_stopped(self, state: JobState, progress, elapsed: float) -> None:
        """Klipper shut down or went away mid-job: raise PrinterHalted / LinkLost with its own message."""
        if self._halt == "shutdown":
            try:
                message = first_line((self._request("GET", "/printer/info") or {}).get("state_message"))
            except LinkError:
                message = ""
            state.status, state.message = "halted", message or "Klipper shut down"
            self._finish(state, progress, elapsed)
            raise PrinterHalted(f"Klipper shut down: {state.message}", state, self.job_path)
        state.status, state.message = "link_lost", "Moonraker lost its connection to Klipper"
        self._finish(state, progress, elapsed)
        raise LinkLost(state.message, state, self.job_path)

    def _ended(self, state: JobState, outcome: str, ps: dict, progress, elapsed: float) -> JobState:
        if outcome == "error":
            state.status, state.message = "halted", first_line(ps.get("message")) or "print error"
            self._finish(state, progress, elapsed)
            raise PrinterHalted(f"Klipper stopped the print: {state.message}", state, self.job_path)
        if outcome == "done":
            state.status = DONE
            state.commands_done = state.commands_total
        else:
            state.status = CANCELLED
            # Klipper's own CANCEL_PRINT only stops reading the file; a cancelled print must not be left hot
            try:
                self._request("POST", "/printer/gcode/script", json={"script": "TURN_OFF_HEATERS"})
            except LinkError as exc:
                state.message = f"the heaters could not be turned off: {exc}"
        self._finish(state, progress, elapsed)
        return state

    def _finish(self, state: JobState, progress, elapsed: float) -> None:
        finish_job(state, self.job_path, progress, elapsed, self.temperatures)


def check_moonraker(url: str, api_key: str | None = None, timeout_s: float = 5.0) -> tuple[bool, str, dict]:
    """Test connection: (ok, one line for the user, details) from Moonraker's `/server/info` and Klippy's
    state. Never raises for a server that is off, refuses the key or has Klipper not ready."""
    try:
        link = MoonrakerLink(url, api_key, timeout=timeout_s)
    except ValueError as exc:
        return False, str(exc), {}
    link._session = SecretSession()
    if link._key:
        link._session.headers[API_KEY_HEADER] = link._key
    try:
        info = link._request("GET", "/server/info") or {}
        version = f"Moonraker {info.get('moonraker_version', '')}".strip()
        state = str(info.get("klippy_state") or "disconnected")
        message = ""
        if info.get("klippy_connected"):
            message = first_line((link._request("GET", "/printer/info") or {}).get("state_message"))
    except LinkError as exc:
        return False, str(exc), {}
    finally:
        link._session.close()
    details = {"version": version, "state": state, "message": message}
    printer = f"Klipper {state}" + (f" ({message})" if message else "")
    if state != "ready":
        return False, f"{version}: {printer}; Klipper must be ready to print", details
    return True, f"{version}: {printer}", details
