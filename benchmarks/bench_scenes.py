"""Saved scenes (issue 30 part 1): map a desk in one session, save the scene file, then start fresh runs on
recordings that revisit the desk (another path; another time of day; the marker removed) from that file.

Recordings: tracking.synth.revisits, rendered on first use into the recordings cache (.cache/recordings, git-ignored, cached by a
hash of the scene). The report is on the `test_scene` set (seeds never used while tuning); the
`tune_scene` set is what parameters were chosen on (`python benchmarks/bench_scenes.py --set tune_scene`).

Per revisit: relocalised (a pose within 1 s of the first frame: the desk is in view from the start), time
to the first pose, the error of the first pose and the mean over the revisit against ground truth (the
first session's world frame), the first pose's source (marker or map). Per scene file: size, keyframes,
bytes per keyframe. Goals (issue 30): >= 95 % relocalise within 1 s, position <= 1 cm, rotation <= 1 deg.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GOAL_S, GOAL_M, GOAL_DEG = 1.0, 0.01, 1.0


def recording(name: str) -> Path:
    """The folder of the revisit recording `name`, rendered on first use (tracking.synth.cache)."""
    from tracking.synth.cache import cached_recording

    return cached_recording(name)


def frames_of(folder: Path):
    from tracking.poses import read_tum
    from tracking.sources import RecordingSource

    gt_t, gt = read_tum(folder / "groundtruth.tum")
    out = []
    with RecordingSource(folder) as source:
        session = source.session
        for frame in source:
            j = int(np.argmin(np.abs(gt_t - frame.t)))
            out.append((float(frame.t), frame.image, gt[j]))
    return out, session


def make_scene(set_name: str, out: Path) -> tuple[Path, dict]:
    """Track the set's mapping session and save its scene file to `out`; (path, facts)."""
    from arapp.engine.scene_run import SceneRun
    from tracking.fusion import Tracker

    frames, session = frames_of(recording(f"{set_name}_map"))
    blocks = [a.to_dict() for a in session.anchors]
    tr = Tracker(session.camera, session.anchors, slam=True)
    try:
        run = SceneRun.start(tr, session.camera, blocks)
        for t, img, _ in frames:
            res = tr.process(img, t)
            tr.catch_up()
            run.observe(img, t, res.world_from_camera, res.state)
        t0 = time.perf_counter()
        run.save(out, [{"path": str(ROOT / "models" / "bracket.json"), "placement": {"size_mm": 40}}])
        save_s = time.perf_counter() - t0
        m = tr.map
        facts = {"keyframes": len(m.keyframes), "points": len(m.points), "bytes": out.stat().st_size,
                 "save_s": save_s}
    finally:
        tr.close()
    return out, facts


def run_revisit(scene_path: Path | None, name: str) -> dict:
    """Start a fresh tracker on `scene_path` (None: without a scene, the baseline) and track the revisit
    `name`; the figures of one revisit."""
    from arapp.engine.scene_run import SceneRun
    from tracking.poses import rotation_angle
    from tracking.fusion import Tracker

    frames, session = frames_of(recording(name))
    blocks = [a.to_dict() for a in session.anchors]
    tr = Tracker(session.camera, session.anchors, slam=True)
    try:
        t0 = time.perf_counter()
        run = SceneRun.start(tr, session.camera, blocks, load=scene_path)
        load_s = time.perf_counter() - t0
        errs, rots, first = [], [], None
        busy = load_s   # seconds of work from start (the scene's load, then each frame) to the first pose
        for i, (t, img, gt) in enumerate(frames):
            t1 = time.perf_counter()
            res = tr.process(img, t)
            if first is None:
                busy += time.perf_counter() - t1
            tr.catch_up()
            run.observe(img, t, res.world_from_camera, res.state)
            p = res.world_from_camera
            if p is not None:
                e = float(np.linalg.norm(p[:3, 3] - gt[:3, 3]))
                r = float(np.degrees(rotation_angle(p[:3, :3].T @ gt[:3, :3])))
                errs.append(e)
                rots.append(r)
                if first is None:
                    first = (t - frames[0][0], res.state, e, r, i, busy)
    finally:
        tr.close()
    s = run.summary()
    out = {"name": name, "load_s": load_s, "frames": len(frames), "tracked": len(errs),
           "first_s": None if first is None else first[0], "first_work_s": None if first is None else first[5], "first_state": None if first is None else first[1],
           "first_err_m": None if first is None else first[2], "first_rot_deg": None if first is None else first[3],
           "mean_err_m": float(np.mean(errs)) if errs else None, "mean_rot_deg": float(np.mean(rots)) if rots else None,
           "max_err_m": float(np.max(errs)) if errs else None, "check": s.get("marker_vs_map")}
    out["relocalised"] = first is not None and first[0] <= GOAL_S
    return out


def chain(scene_path: Path, names: list[str]) -> list[tuple[int, int]]:
    """Each revisit in turn extends the scene file (loaded, tracked, saved over it): (keyframes, bytes) after
    each save, to show the file's growth is bounded (keyframe culling)."""
    from arapp.engine.scene_run import SceneRun
    from tracking.fusion import Tracker

    out = []
    for name in names:
        frames, session = frames_of(recording(name))
        with Tracker(session.camera, session.anchors, slam=True) as tr:
            run = SceneRun.start(tr, session.camera, [a.to_dict() for a in session.anchors], load=scene_path)
            for t, img, _ in frames:
                tr.process(img, t)
                tr.catch_up()
            run.save(scene_path)
            out.append((len(tr.map.keyframes), scene_path.stat().st_size))
    return out


def measure(set_name: str, revisits: int, variants=None) -> tuple[dict, list[dict]]:
    from tracking.synth.revisits import VARIANTS

    with tempfile.TemporaryDirectory() as tmp:
        scene_path, facts = make_scene(set_name, Path(tmp) / "desk.arscene")
        rows = [run_revisit(scene_path, f"{set_name}_revisit_{i}_{v}")
                for i in range(revisits) for v in (variants or VARIANTS)]
        facts["chain"] = chain(scene_path, [r["name"] for r in rows if r["name"].split("_", 4)[-1] != "bare_wide"])
    # the baseline: the revisits without the marker, started without the scene file
    base = [run_revisit(None, r["name"]) for r in rows if "bare" in r["name"]]
    facts["without_scene"] = {"revisits": len(base), "frames": sum(b["frames"] for b in base),
                              "tracked": sum(b["tracked"] for b in base)}
    return facts, rows


def _fmt(v, scale=1.0, digits=1):
    return "-" if v is None else f"{v * scale:.{digits}f}"


def table(facts: dict, rows: list[dict]) -> str:
    from tracking.synth.revisits import VARIANTS

    lines = ["| revisits | relocalised within 1 s | time to first pose (median, max) | work to first pose (median) | first pose from marker / map | "
             "first pose error (median, max) | mean error over the revisit (median) |",
             "|---|---|---|---|---|---|---|"]
    for v in (*VARIANTS, "all"):
        rs = [r for r in rows if v == "all" or r["name"].split("_", 4)[-1] == v]
        if not rs:
            continue
        ok = [r for r in rs if r["relocalised"]]
        fs = [r["first_s"] for r in ok]
        fe = [r["first_err_m"] for r in ok]
        fr = [r["first_rot_deg"] for r in ok]
        me = [r["mean_err_m"] for r in ok]
        mr = [r["mean_rot_deg"] for r in ok]
        fw = [r["first_work_s"] for r in ok]
        src = f"{sum(r['first_state'] == 'marker' for r in ok)} / {sum(r['first_state'] == 'slam' for r in ok)}"
        lines.append(
            f"| {v} ({len(rs)}) | {len(ok)}/{len(rs)} ({100 * len(ok) / len(rs):.0f} %) | "
            f"{_fmt(np.median(fs) if fs else None, 1000, 0)} ms, {_fmt(max(fs) if fs else None, 1000, 0)} ms | "
            f"{_fmt(np.median(fw) if fw else None, 1000, 0)} ms | {src} | "
            f"{_fmt(np.median(fe) if fe else None, 1000)} mm / {_fmt(np.median(fr) if fr else None, 1, 2)} deg, "
            f"{_fmt(max(fe) if fe else None, 1000)} mm / {_fmt(max(fr) if fr else None, 1, 2)} deg | "
            f"{_fmt(np.median(me) if me else None, 1000)} mm / {_fmt(np.median(mr) if mr else None, 1, 2)} deg |")
    checks = [r["check"] for r in rows if r["check"]]
    file_line = (f"Scene file: {facts['bytes'] / 1e6:.2f} MB for {facts['keyframes']} keyframes and {facts['points']} "
                 f"map points, {facts['bytes'] / max(facts['keyframes'], 1) / 1e3:.0f} kB per keyframe; saved in "
                 f"{facts['save_s']:.2f} s, loaded in {np.median([r['load_s'] for r in rows]):.2f} s (median).")
    ch = facts.get("chain")
    if ch:
        file_line += (f" Extended by {len(ch)} revisits in turn (each loads the file, tracks, saves over it): "
                      f"{', '.join(str(k) for k, _ in ch)} keyframes, {ch[-1][1] / 1e6:.2f} MB at the end.")
    ws = facts.get("without_scene")
    if ws and ws["revisits"]:
        file_line += (f" Without the scene file the {ws['revisits']} revisits without the marker track "
                      f"{ws['tracked']} of {ws['frames']} frames (nothing else defines the world).")
    check_line = ""
    if checks:
        d = [c["position_m"] for c in checks]
        a = [c["rotation_deg"] for c in checks]
        check_line = (f"Marker against saved map (revisits with the marker, the first frames it gives the pose): "
                      f"{sum(c['agree'] for c in checks)}/{len(checks)} agree (<= 1 cm, 1 deg); offset median "
                      f"{np.median(d) * 1000:.1f} mm / {np.median(a):.2f} deg, max {max(d) * 1000:.1f} mm / {max(a):.2f} deg.")
    return "\n".join(lines) + "\n\n" + file_line + ("\n\n" + check_line if check_line else "")


def run(quick: bool = False) -> str:
    revisits = 2 if quick else 5
    facts, rows = measure("test_scene", revisits)
    return ("## Saved scenes: relocalising on a revisit (issue 30)\n\n"
            "A desk mapped in a first 3 s session (`test_scene_map`, aruco marker, 640x480) is saved as a scene "
            "file; each revisit (1.2 s, its own path and seed, `tracking.synth.revisits`) starts a fresh tracker "
            "from that file. `path`: another path; `evening`: another time of day (the lamp on the other side "
            "of the desk, the room dimmer, a fixed exposure that no longer matches, warmer white balance, noisier); `bare`: the marker removed from the desk, only the map can place "
            "the camera; `bare_wide`: no marker, from views up to 20 deg past the first session's sweep, nearer "
            "or farther. Errors against ground truth in the first session's world frame. Goals: >= 95 % "
            "relocalise within 1 s, <= 10 mm, <= 1 deg. Test set only (seeds 700+); tuned on `tune_scene` "
            "(seeds 600+). Measured on a shared, loaded machine (2 cores).\n\n" + table(facts, rows) + "\n")


if __name__ == "__main__":
    import argparse

    sys.path.insert(0, str(ROOT))
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", default="tune_scene")
    ap.add_argument("--revisits", type=int, default=3)
    ap.add_argument("--json", help="write every revisit's figures here")
    ap.add_argument("--variants", nargs="*", help="only these revisit variants (tracking.synth.revisits.VARIANTS)")
    a = ap.parse_args()
    facts, rows = measure(a.set, a.revisits, a.variants)
    for r in rows:
        print(json.dumps(r, default=float))
    print(table(facts, rows))
    if a.json:
        Path(a.json).write_text(json.dumps({"facts": facts, "rows": rows}, indent=1, default=float))
