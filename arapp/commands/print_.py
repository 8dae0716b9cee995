"""`arapp print`: slice a model (or take G-code) and print it over USB serial, OctoPrint, Moonraker (Klipper)
or PrusaLink."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

HELP = "print a model or G-code on a Marlin printer (USB serial) or through OctoPrint, Moonraker (Klipper) or PrusaLink"

GCODE_SUFFIXES = (".gcode", ".gco", ".g")


def add_arguments(parser):
    parser.add_argument("input", nargs="?",
                        help="G-code file, or a model (JSON model, .stl/.obj/.3mf) to slice first")
    link = parser.add_argument_group("link (one of)")
    link.add_argument("--port", help="serial device or pyserial URL (e.g. /dev/ttyUSB0); "
                                     "default: the printer profile's link.port")
    link.add_argument("--baud", type=int, default=None, help="baud rate (default: profile's, 115200)")
    link.add_argument("--octoprint", metavar="URL", help="OctoPrint server, e.g. http://octopi.local")
    link.add_argument("--moonraker", metavar="URL",
                      help="Moonraker server of a Klipper printer, e.g. http://mainsailos.local or http://host:7125 "
                           "(no key needed from one of its trusted_clients)")
    link.add_argument("--prusalink", metavar="URL",
                      help="PrusaLink of a Prusa printer (MK4, MINI, XL, CORE One, or a Pi on an MK3S), "
                           "e.g. http://prusa-mk4.local; with --api-key-file F, or --prusalink-user NAME and "
                           "--password-file F")
    link.add_argument("--prusalink-user", metavar="NAME", default="",
                      help="PrusaLink user for HTTP digest (the printer's Settings > Network > PrusaLink)")
    link.add_argument("--password-file", metavar="F", default="",
                      help="file holding that user's PrusaLink password (mode 600; never on the command line)")
    link.add_argument("--api-key-file", metavar="F",
                      help="file holding the OctoPrint, Moonraker or PrusaLink API key (mode 600)")
    link.add_argument("--save-key", metavar="F",
                      help="store an API key in F with mode 600 (read from $ARAPP_API_KEY or "
                           "$ARAPP_OCTOPRINT_API_KEY, or asked for without echo) and use it")
    parser.add_argument("--printer", default=None, metavar="PROFILE",
                        help="printer profile JSON (arapp-printer/1) or shipped name")
    parser.add_argument("--resume", metavar="JOB.json", help="continue a print whose link dropped (serial only)")
    parser.add_argument("--after-halt", action="store_true",
                        help="resume a job during which the printer halted (read why first: arapp says it)")
    parser.add_argument("--job", metavar="JOB.json",
                        help="where to keep the job state for --resume (default: next to the G-code)")
    parser.add_argument("-o", "--output", metavar="GCODE",
                        help="where to write the G-code sliced from a model (default: MODEL.gcode in the "
                             "current directory)")
    parser.add_argument("--window", type=int, default=1,
                        help="serial: unacknowledged lines in flight (default 1)")
    parser.add_argument("--timeout", type=float, default=10.0,
                        help="serial: progress window, seconds without an acknowledged line before an M105 poke; "
                             "12 windows with nothing from the printer end the print (default 10)")
    sl = parser.add_argument_group("slicing (models only; see arapp slice)")
    sl.add_argument("--material", default="PLA", type=str.upper, choices=["PLA", "PETG", "ABS", "TPU", "NYLON"])
    sl.add_argument("--layer-height", type=float, default=0.2, help="mm (default 0.2)")
    sl.add_argument("--first-layer-height", type=float, default=None, help="mm (default: layer height)")
    sl.add_argument("--infill", type=float, default=20.0, help="percent (default 20)")
    sl.add_argument("--pattern", choices=["zigzag", "grid"], default="zigzag")
    sl.add_argument("--perimeters", type=int, default=2)
    sl.add_argument("--size", type=float, default=None, metavar="MM", help="largest extent of the part, mm")
    sl.add_argument("--thickness", type=float, default=2.0, metavar="MM", help="wall for open surfaces, mm")
    sl.add_argument("--slicer", choices=["builtin", "prusa"], default="builtin")
    sl.add_argument("--scale-to-fit", action="store_true")
    sl.add_argument("--z-hop", type=float, default=0.0, metavar="MM")
    sl.add_argument("--retract", type=float, default=1.0, metavar="MM")


def _read_key_interactively(what: str = "API key") -> str:
    key = os.environ.get("ARAPP_API_KEY", "") or os.environ.get("ARAPP_OCTOPRINT_API_KEY", "")
    if key:
        return key
    if sys.stdin.isatty():
        import getpass

        return getpass.getpass(f"{what}: ")
    return sys.stdin.readline()


# The network links: flag -> (name, target maker); a target's key file may be "" where the server allows it.
def _network_links():
    from arapp.printing.link.factory import MoonrakerTarget, OctoPrintTarget, PrusaLinkTarget

    return {"octoprint": ("OctoPrint", lambda args: OctoPrintTarget(args.octoprint, args.api_key_file)),
            "moonraker": ("Moonraker", lambda args: MoonrakerTarget(args.moonraker, args.api_key_file or "")),
            "prusalink": ("PrusaLink", lambda args: PrusaLinkTarget(
                args.prusalink, args.api_key_file or "", getattr(args, "prusalink_user", "") or "",
                getattr(args, "password_file", "") or ""))}


def _chosen_links(args) -> list[str]:
    return [flag for flag in ("octoprint", "moonraker", "prusalink") if getattr(args, flag, None)]


def _slice_model(args, profile) -> Path:
    """Slice a model with the same options as `arapp slice`; returns the G-code path."""
    from arapp.commands.slice import load_for_printing, settings_from_args
    from arapp.printing import slice_mesh

    settings = settings_from_args(args)
    mesh = load_for_printing(args.input, args.size, args.thickness, profile)
    if args.slicer == "prusa":
        from arapp.printing.prusa import slice_with_prusa

        result = slice_with_prusa(mesh, settings, profile)
    else:
        result = slice_mesh(mesh, settings, profile)
    out = Path(args.output) if args.output else Path(Path(args.input).stem + ".gcode")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(result.gcode)
    print(f"sliced {args.input} -> {out} ({result.layers} layers)", file=sys.stderr)
    return out


def format_progress(p) -> str:
    """One status line: bar, percent, lines, layer, ETA, temperatures, state."""
    width = 24
    filled = int(round(width * min(100.0, p.percent) / 100.0))
    parts = [f"[{'#' * filled}{'.' * (width - filled)}] {p.percent:5.1f}%",
             f"lines {p.lines_done}/{p.lines_total}"]
    if p.layer_count:
        parts.append(f"layer {max(p.layer, 0) + 1}/{p.layer_count}")
    if p.eta_s is not None:
        m, s = divmod(int(p.eta_s), 60)
        h, m = divmod(m, 60)
        parts.append(f"ETA {h:d}:{m:02d}:{s:02d}")
    for name in ("T", "T0", "B"):
        if name in p.temperatures:
            actual, target = p.temperatures[name]
            parts.append(f"{name} {actual:.1f}" + (f"/{target:.0f}" if target is not None else ""))
    parts.append(p.state)
    return "  ".join(parts)


def _progress_writer(stream):
    tty = stream.isatty()
    last = {"state": None, "pct": -1}

    def show(p):
        line = format_progress(p)
        if tty:
            print("\r" + line + "\x1b[K", end="", file=stream, flush=True)
        elif p.state != last["state"] or int(p.percent) // 10 != last["pct"]:
            # Not a terminal (a log): one line per state change and per 10 %.
            print(line, file=stream, flush=True)
        last["state"], last["pct"] = p.state, int(p.percent) // 10

    return show


def _run_job(link, job_fn):
    """Run the job on a worker thread; Ctrl-C cancels the print and waits for the cancel to end.

    Returns (final state, interrupted). The worker's exception (a LinkError) is raised here.
    """
    box = {}
    finished = threading.Event()

    def work():
        try:
            box["state"] = job_fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread, raised there
            box["error"] = exc
        finally:
            finished.set()

    threading.Thread(target=work, name="arapp-print", daemon=True).start()
    interrupted = False
    while not finished.is_set():
        try:
            finished.wait()
        except KeyboardInterrupt:
            # An Event wait survives an interrupt (a Thread.join interrupted may report the thread
            # ended while it still runs); the print ends through the link's cancel, heaters off.
            if not interrupted:
                print("\ncancelling the print: heaters off, nozzle up (waiting for the printer)", file=sys.stderr)
            interrupted = True
            link.cancel()
    if "error" in box:
        raise box["error"]
    return box["state"], interrupted


def _check_job_file(job_path: Path, state) -> None:
    """Refuse the print before it starts when the job file cannot be written (one line)."""
    from arapp.printing.link.job import JobState

    probe = state or JobState()
    existed = job_path.exists()
    try:
        if existed:
            with open(job_path, "a", encoding="utf-8"):
                pass
        else:
            probe.save(job_path)
            job_path.unlink()
    except OSError as exc:
        raise OSError(f"cannot write the job file {job_path}: {exc.strerror or exc}; "
                      "nothing was sent: choose a writable place with --job") from exc


def _check_link_args(args) -> None:
    """One link, a window of at least one line, a timeout under a day; ValueError naming the option otherwise."""
    chosen = (["port"] if args.port else []) + _chosen_links(args)
    if len(chosen) > 1:
        raise ValueError(f"give one link (--port, --octoprint, --moonraker or --prusalink), not "
                         f"{' and '.join('--' + c for c in chosen)}")
    if args.window < 1:
        raise ValueError(f"--window must be at least 1 line, got {args.window}")
    if not (0 < args.timeout < 86400):
        raise ValueError(f"--timeout must be between 0 and 86400 seconds, got {args.timeout}")


def _job_to_resume(args, profile):
    """The job state to resume (None for a new print) and the file to print (G-code or a model to slice).

    With --resume the job file is checked (resumable, the right printer) and
    becomes --job unless one was given; the G-code is the job's own unless given.
    """
    # lazy like every command module's imports: `arapp --help` stays fast
    from arapp.printing.link.job import JobState, check_resumable

    if not args.resume:
        if args.input is None:
            raise ValueError("nothing to print: give a G-code file or a model (or --resume JOB.json)")
        return None, Path(args.input)
    if _chosen_links(args):
        raise ValueError("--resume works with the serial link (--port) only")
    state = JobState.load(args.resume, profile)
    check_resumable(state, args.resume, after_halt=args.after_halt)
    if state.status == "halted":
        print(f"resuming after a printer halt: {state.message}", file=sys.stderr)
    args.job = args.job or args.resume
    return state, Path(args.input or state.gcode)


def run(args) -> int:
    from arapp.printing.link.job import Program

    if args.save_key and _save_key(args):
        return 0
    _check_link_args(args)
    network = _chosen_links(args)
    profile = _profile_if_needed(args, network)
    state, gcode_path = _job_to_resume(args, profile)
    if gcode_path.suffix.lower() not in GCODE_SUFFIXES:
        gcode_path = _slice_model(args, profile)
    if not gcode_path.is_file():
        raise FileNotFoundError(f"G-code file not found: {gcode_path}")
    lines = gcode_path.read_text(encoding="utf-8", errors="replace").splitlines()
    program = Program.from_lines(lines)
    job_path = Path(args.job) if args.job else gcode_path.with_name(gcode_path.name + ".job.json")
    _check_job_file(job_path, state)
    show = _progress_writer(sys.stderr)

    kind = profile.link.kind if (profile is not None and not network and not args.port) else "serial"
    if kind != "serial":
        # the printer profile's own link (link.kind, link.url, link.api_key_file)
        setattr(args, kind, profile.link.url)
        args.api_key_file = args.api_key_file or profile.link.api_key_file or None
        network = [kind]
        if state is not None:
            raise ValueError("--resume works with the serial link (--port) only")
    if network:
        link, job = _network_job(args, network[0], profile, job_path, lines, show, gcode_path)
    else:
        link, job = _serial_job(args, profile, job_path, lines, show, gcode_path, program, state)
    try:
        final, interrupted = _run_job(link, job)
    finally:
        link.close()
    print(file=sys.stderr)
    note = "; not resumable" if final.status == "cancelled" else ""
    if final.message and final.status != "cancelled":
        note += f"; {final.message}"
    print(f"{final.status}: {final.commands_done}/{final.commands_total} lines, job state in {job_path}{note}")
    return 130 if interrupted else 0


def _save_key(args) -> bool:
    """Store the API key typed in for --save-key; True when that is all there is to do (no job given)."""
    from arapp.printing.link.webapi import save_api_key

    path = save_api_key(args.save_key, _read_key_interactively())
    print(f"API key saved to {path} (mode 600)", file=sys.stderr)
    if args.api_key_file is None:
        args.api_key_file = str(path)
    return args.input is None and args.resume is None


def _profile_if_needed(args, network: list[str]):
    """The printer profile when the job needs one (named, resuming, slicing, or the profile's own link);
    else None."""
    if args.printer is not None or args.resume or (not network and not args.port) or (
            args.input and Path(args.input).suffix.lower() not in GCODE_SUFFIXES):
        from arapp.printing import load_profile

        return load_profile(args.printer)
    return None


def _network_job(args, which: str, profile, job_path: Path, lines, show, gcode_path: Path):
    """(link, job): the network link `which` connected, and the call that prints through it."""
    from arapp.printing.link.factory import make_link

    name, target = _network_links()[which]
    link = make_link(target(args), profile=profile, job_path=job_path)
    link.connect()
    print(f"connected to {link.version or name} at {link.url}", file=sys.stderr)
    return link, lambda: link.print_gcode(lines, progress=show, gcode_path=str(gcode_path))


def _serial_job(args, profile, job_path: Path, lines, show, gcode_path: Path, program, state):
    """(link, job): the serial link connected, and the call that prints (or resumes `state`) through it."""
    from arapp.printing.link.factory import SerialTarget, make_link
    from arapp.printing.link.job import resume_commands

    port = args.port or (profile.link.port if profile is not None else None)
    baud = args.baud or (profile.link.baud if profile is not None else 115200)
    link = make_link(SerialTarget(port or "", baud, args.window, args.timeout), profile=profile,
                     job_path=job_path)
    preamble = []
    if state is not None:
        state.check_program(program, gcode_path)
        bed_height = profile.bed.height if profile is not None else None
        preamble = resume_commands(state, bed_height=bed_height)
        print(f"resuming {gcode_path} at line {state.next_line + 1} (layer {state.layer})", file=sys.stderr)
    link.connect()
    print(f"connected to {link.firmware or 'printer'} on {port}", file=sys.stderr)
    return link, lambda: link.print_gcode(lines, progress=show, gcode_path=str(gcode_path.resolve()),
                                          program=program, state=state, preamble=preamble)
