"""Run every benchmarks/bench_*.py and write BENCHMARKS.md.

Each module exposes `run(quick=False) -> str`, a Markdown section comparing
arapp with the peer its issue names, measured in the same run. A benchmark
that fails is reported as failed in the file, not hidden.

`--only NAME ... --merge` re-measures the named sections and keeps the others
as the file has them; every section ends with the time it was measured, so a
merged file says which figures come from which run.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import sys
import time
import re
import traceback
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ORDER = ["geometry", "anchors", "slam", "slam_cpu", "render", "slicer", "link", "gui"]


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, Python {platform.python_version()}, {platform.system()}"


# a section's first line after its heading: which module wrote it (for --merge)
_MARK = re.compile(r"^<!-- bench: (\w+) -->$", re.M)


def split_sections(text: str) -> dict[str, str]:
    """The marked sections of a BENCHMARKS.md, by module name, in file order (unmarked text is dropped)."""
    marks = list(_MARK.finditer(text))
    sections = {}
    for i, m in enumerate(marks):
        start = text.rfind("\n## ", 0, m.start()) + 1
        end = text.rfind("\n## ", 0, marks[i + 1].start()) + 1 if i + 1 < len(marks) else len(text)
        sections[m.group(1)] = text[start:end].strip() + "\n"
    return sections


def marked(name: str, text: str, when: str) -> str:
    """A section with its module mark under the heading and the time it was measured at the end."""
    head, _, body = text.strip().partition("\n")
    return f"{head}\n<!-- bench: {name} -->\n{body.strip()}\n\n*Section measured {when} on {machine()}.*\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="BENCHMARKS.md")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (for smoke tests)")
    parser.add_argument("--only", nargs="*", help="names such as geometry render")
    parser.add_argument("--merge", action="store_true",
                        help="keep the sections of --out that are not re-run (with their own dates)")
    args = parser.parse_args(argv)
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(HERE.parent))

    found = {p.stem[len("bench_"):]: p for p in HERE.glob("bench_*.py")}
    every = [n for n in ORDER if n in found] + sorted(set(found) - set(ORDER))
    names = [n for n in every if not args.only or n in args.only]
    when = f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
    out = Path(args.out)
    kept = split_sections(out.read_text()) if args.merge and out.exists() else {}
    fresh = {}
    for name in names:
        print(f"bench: {name} ...", flush=True)
        spec = importlib.util.spec_from_file_location(f"bench_{name}", found[name])
        module = importlib.util.module_from_spec(spec)
        # registered under its name, so what it hands to worker processes (functions it defines) pickles
        sys.modules[spec.name] = module
        t0 = time.perf_counter()
        try:
            spec.loader.exec_module(module)
            text = module.run(quick=args.quick)
        except Exception:  # a failing benchmark is reported in the file, the others still run
            text = f"## {name}\n\nFAILED:\n\n```\n{traceback.format_exc()}```\n"
        print(f"bench: {name} done in {time.perf_counter() - t0:.1f} s", flush=True)
        fresh[name] = marked(name, text, when)
    sections = [fresh.get(n) or kept[n] for n in every if n in fresh or n in kept]

    header = (
        "# Benchmarks\n\n"
        f"Written by `make bench` on {when}"
        + (" (re-measuring only " + ", ".join(names) + "; each section says when it was measured)" if kept else "")
        + ".\n\n"
        f"Machine: {machine()}"
        + (" (this run's; a section kept from an earlier run may come from another machine, its last line says "
           "when, and since 2026-12-08 which)" if kept else "")
        + ". No GPU machine was used for these figures unless a section says so.\n"
        "Absolute times on these shared machines are noisy; each section compares arapp with its peer "
        "measured in the same run, and the ratios are what to read.\n\n"
    )
    tmp = out.with_suffix(".tmp")
    tmp.write_text(header + "\n".join(sections))
    tmp.replace(out)  # a bench that dies half-way leaves the old file whole
    print(f"bench: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
