"""benchmarks/run_all.py --merge: re-measured sections replace their old text, the others stay as written."""

import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("run_all", Path(__file__).parents[1] / "benchmarks" / "run_all.py")
run_all = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(run_all)


def test_marked_sections_split_back_by_module_name():
    text = "# Benchmarks\n\nheader\n\n" + "\n".join([
        run_all.marked("geometry", "## NURBS\n\n| a |\n", "then"),
        run_all.marked("slam", "## SLAM\n\nbody with ## inside a line\n", "now"),
    ])
    sections = run_all.split_sections(text)
    assert list(sections) == ["geometry", "slam"]
    assert sections["geometry"].startswith("## NURBS\n<!-- bench: geometry -->")
    # each section says when, and on which machine (a merged file holds sections of several runs)
    assert sections["geometry"].rstrip().endswith(f"*Section measured then on {run_all.machine()}.*")
    assert "header" not in sections["geometry"]
    assert sections["slam"].startswith("## SLAM") and "body with ## inside" in sections["slam"]


def test_the_committed_file_is_marked_for_every_bench_module():
    # every bench module's section can be refreshed alone with --merge
    root = Path(__file__).parents[1]
    modules = {p.stem[len("bench_"):] for p in (root / "benchmarks").glob("bench_*.py")}
    sections = run_all.split_sections((root / "BENCHMARKS.md").read_text())
    assert set(sections) <= modules
    assert {"geometry", "anchors", "slam", "render", "link"} <= set(sections)
