"""Run every benchmarks/bench_*.py and write BENCHMARKS.md.

Each module exposes `run(quick=False) -> str`, a Markdown section comparing
arapp with the peer its issue names, measured in the same run. A benchmark
that fails is reported as failed in the file, not hidden.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import sys
import time
import traceback
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ORDER = ["geometry", "anchors", "slam", "render", "slicer", "link", "gui"]


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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="BENCHMARKS.md")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (for smoke tests)")
    parser.add_argument("--only", nargs="*", help="names such as geometry render")
    args = parser.parse_args(argv)
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(HERE.parent))

    found = {p.stem[len("bench_"):]: p for p in HERE.glob("bench_*.py")}
    names = [n for n in ORDER if n in found] + sorted(set(found) - set(ORDER))
    if args.only:
        names = [n for n in names if n in args.only]
    sections = []
    for name in names:
        print(f"bench: {name} ...", flush=True)
        spec = importlib.util.spec_from_file_location(f"bench_{name}", found[name])
        module = importlib.util.module_from_spec(spec)
        t0 = time.perf_counter()
        try:
            spec.loader.exec_module(module)
            text = module.run(quick=args.quick)
        except Exception:  # a failing benchmark is reported in the file, the others still run
            text = f"## {name}\n\nFAILED:\n\n```\n{traceback.format_exc()}```\n"
        print(f"bench: {name} done in {time.perf_counter() - t0:.1f} s", flush=True)
        sections.append(text.strip() + "\n")

    header = (
        "# Benchmarks\n\n"
        f"Written by `make bench` on {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC.\n\n"
        f"Machine: {machine()}. No GPU machine was used for these figures unless a section says so.\n"
        "Absolute times on these shared machines are noisy; each section compares arapp with its peer "
        "measured in the same run, and the ratios are what to read.\n\n"
    )
    Path(args.out).write_text(header + "\n".join(sections))
    print(f"bench: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
