"""Repository weight (issue 29): what recordings/ holds in the tree, against every preset bundled (the peer:
the repository as it was, all of them committed), and what rendering the others costs: each preset not bundled
rendered from nothing into a fresh cache (tracking/synth/cache.py) in this run, checked byte for byte against
the cache the tests read (rendering is deterministic), and the check `make test` runs first when the cache is
full. Run: .venv/bin/python benchmarks/bench_weight.py [--quick] (quick: one preset rendered, not all)."""

from __future__ import annotations

import filecmp
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

QUICK_PRESET = "tune_qr_webcam"   # the cheapest preset to render (one core, ~8 s)


def _tree_bytes(paths) -> int:
    return sum(p.stat().st_size for p in paths if p.is_file())


def _render(args) -> tuple[str, float, float]:
    """(name, wall s, CPU s) of rendering preset `name` into the cache folder `root`."""
    name, root = args
    from tracking.synth.cache import cached_recording

    w0, c0 = time.perf_counter(), time.process_time()
    cached_recording(name, Path(root))
    return name, time.perf_counter() - w0, time.process_time() - c0


def _same_bytes(a: Path, b: Path) -> bool:
    names = sorted(p.name for p in a.iterdir())
    return names == sorted(p.name for p in b.iterdir()) and all(
        filecmp.cmp(a / n, b / n, shallow=False) for n in names)


def run(quick: bool = False) -> str:
    from tracking.synth.cache import BUNDLED, bundled_folder, cached_recording
    from tracking.synth.presets import HELD, PRESETS

    tracked = subprocess.run(["git", "ls-files", "recordings"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    bundled = sorted(p.name for p in BUNDLED.iterdir() if (p / "groundtruth.tum").is_file())
    tree = _tree_bytes(ROOT / t for t in tracked)
    on_demand = [n for n in PRESETS if bundled_folder(n) is None]
    cache = {n: cached_recording(n) for n in [*on_demand, *HELD]}   # the tests' cache (filled when empty)
    all_bundled = tree + _tree_bytes(p for n in on_demand for p in cache[n].iterdir())
    pack = subprocess.run(["git", "count-objects", "-v"], cwd=ROOT, capture_output=True, text=True).stdout
    pack_kib = dict(line.split(": ") for line in pack.splitlines() if ": " in line).get("size-pack", "?")

    names = [QUICK_PRESET] if quick else [*on_demand, *HELD]
    jobs = min(2, os.cpu_count() or 1)
    with tempfile.TemporaryDirectory(prefix="arapp-bench-weight-") as tmp:
        w0 = time.perf_counter()
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            timed = list(pool.map(_render, [(n, tmp) for n in names]))
        wall = time.perf_counter() - w0
        same = {n: _same_bytes(cached_recording(n, Path(tmp)), cache[n]) for n in names}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    w0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "arapp", "synth", "all", "--cached", "--jobs", str(jobs)], cwd=ROOT,
                   env=env, capture_output=True, check=True)
    warm = time.perf_counter() - w0

    lines = ["## Repository weight: bundled recordings and the recordings cache", "",
             "`recordings/` holds what a user replays and the tests read most; every other preset is rendered "
             "by `arapp synth` into the recordings cache (`.cache/recordings/`, git-ignored) by `make setup` / "
             "`make test` or on first use (recordings/README.md). Peer: every preset bundled, as the repository "
             "held them before issue 29. Sizes in MB (10^6 bytes).", "",
             "| what | arapp now | every preset bundled | goal | met |", "|---|---|---|---|---|",
             f"| `recordings/` in the tree | {tree / 1e6:.1f} MB ({len(bundled)} recordings) | "
             f"{all_bundled / 1e6:.1f} MB ({len(bundled) + len(on_demand)}) | <= 20 MB | "
             f"{'yes' if tree <= 20e6 else 'no'} |", "",
             f"`.git` pack: {int(pack_kib) / 1024 if str(pack_kib).isdigit() else pack_kib:.1f} MiB (the history "
             "keeps the deleted videos; no recording is rewritten in place: a changed one is a new preset).", "",
             f"Rendering from an empty cache ({'one preset, --quick' if quick else 'every preset not bundled'}, "
             f"{jobs} processes at once): {wall:.0f} s wall for {len(names)} recordings, "
             f"{sum(t[2] for t in timed):.0f} s of CPU; byte-identical to the tests' cache: "
             f"{sum(same.values())} of {len(same)}"
             + (f" (differ: {', '.join(n for n, s in same.items() if not s)})" if not all(same.values()) else "")
             + f". The check `make test` runs first when the cache is full: {warm:.1f} s.", "",
             "| recording | render wall s | CPU s | same bytes |", "|---|---|---|---|"]
    lines += [f"| {n} | {w:.1f} | {c:.1f} | {'yes' if same[n] else 'no'} |" for n, w, c in timed]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
