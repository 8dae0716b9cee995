"""SLAM tracking (tracking.fusion.Tracker) against the plain OpenCV per-frame marker pose (and that pose
through arapp's filter class), on the synthetic recordings with ground truth (bundled in recordings/ or rendered
into the recordings cache on first use, tracking.synth.cache): tuning and test recordings
in separate tables (recordings/README.md). Run: .venv/bin/python benchmarks/bench_slam.py [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

# the synthetic scenes are test scaffolding kept in tests/ (tests/scenes.py, tests/scan_scene.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
for _p in (str(ROOT), str(HERE)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

# the tuning and test recordings, as recordings/README.md and the synthesiser's presets list them
from tracking.synth.cache import recording_folder  # noqa: E402
from tracking.synth.presets import HEADON_TEST, HEADON_TUNING, HELD_TEST, HELD_TUNING, TEST, TUNING  # noqa: E402

RECORDINGS = TUNING + TEST
QUICK = ["marker_occluded", "board_orbit_720p", "test_hand_border"]


def _plain(frames, session, qr_call):
    """The plain peer and the plain peer through arapp's filter class (benchmarks/peers.py) on every frame."""
    from peers import FilteredPeer, PlainPeer

    peer, filt = PlainPeer(session.anchors, session.camera, qr_call), FilteredPeer()
    times, poses, ms, ftimes, fposes = [], [], [], [], []
    for t, img, _ in frames:
        t0 = time.perf_counter()
        p = peer.pose(img)
        ms.append((time.perf_counter() - t0) * 1000.0)
        f = filt.update(p, t)
        if p is not None:
            times.append(t)
            poses.append(p)
            ftimes.append(t)
            fposes.append(f)
    return (np.array(times), np.array(poses).reshape(-1, 4, 4), np.array(ms),
            np.array(ftimes), np.array(fposes).reshape(-1, 4, 4))


def _errors(t_est, est, gt_t, gt) -> np.ndarray:
    """Position errors (metres) of the estimates at their ground-truth frames."""
    idx = {round(float(t), 6): k for k, t in enumerate(gt_t)}
    return np.array([np.linalg.norm(T[:3, 3] - gt[idx[round(float(t), 6)]][:3, 3]) for t, T in zip(t_est, est)
                     if round(float(t), 6) in idx])


def measure(name: str, qr_call: str = "QRCodeDetector.detectAndDecodeMulti") -> dict:
    """Metrics of the tracker (filtered output and, in a second run, with its filter off), the plain way and
    the filtered plain way on one recording."""
    from tracking.evaluation import evaluate
    from scenes import load_recording, run_tracker
    from tracking.fusion import Tracker

    frames, session = load_recording(recording_folder(name))
    gt_t = np.array([f[0] for f in frames])
    gt = np.array([f[2] for f in frames])
    pt, pp, pms, ft, fp = _plain(frames, session, qr_call)
    plain, plain_f = evaluate(pt, pp, gt_t, gt), evaluate(ft, fp, gt_t, gt)
    with Tracker(session.camera, session.anchors) as tr:
        r = run_tracker(tr, frames)
        kfs, pts = len(tr.map.keyframes), len(tr.map.points)
    with Tracker(session.camera, session.anchors, filter=False) as tr:
        raw = run_tracker(tr, frames)
    m = r["metrics"]
    first = next((i for i, st in enumerate(r["states"]) if st == "marker"), len(frames))
    since_first = float(np.mean(r["ok"][first:])) if first < len(frames) else 0.0
    dist = float(np.median(np.linalg.norm(gt[:, :3, 3], axis=1)))
    med = lambda e: float(np.nanmedian(e)) if np.isfinite(e).any() else float("nan")  # noqa: E731
    return {"name": name, "since_first": since_first, "first": first,
            "size": f"{session.camera.width}x{session.camera.height}", "frames": len(frames), "dist": dist,
            "slam": m, "raw": raw["metrics"], "plain": plain, "plain_f": plain_f,
            "median": {"slam": med(r["errors"]), "raw": med(raw["errors"]),
                       "plain": med(_errors(pt, pp, gt_t, gt)), "plain_f": med(_errors(ft, fp, gt_t, gt))},
            "slam_ms": float(np.median(r["ms"])), "plain_ms": float(np.median(pms)),
            "slam_p95": float(np.percentile(r["ms"], 95)), "max_err": float(np.nanmax(r["errors"])),
            "kfs": kfs, "pts": pts}


def measure_paced(name: str, pace: str) -> dict:
    """The tracker on one recording with frames handed in at another pace (see run_tracker)."""
    from scenes import load_recording, run_tracker
    from tracking.fusion import Tracker

    frames, session = load_recording(recording_folder(name))
    with Tracker(session.camera, session.anchors) as tr:
        r = run_tracker(tr, frames, pace=pace)
    return {"name": name, "pace": pace, "m": r["metrics"], "ms": float(np.median(r["ms"])),
            "p95": float(np.percentile(r["ms"], 95)), "max_err": float(np.nanmax(r["errors"]))}


HELD_QUICK = ["tune_held_board"]
HELD_MAX_M = 0.03   # issue 25: no frame of a held card placed more than 3 cm off



def _run_watching(tracker, frames, watch):
    """`run_tracker` over `frames`, and `watch(result)` of every frame's TrackResult, in order."""
    from scenes import run_tracker

    seen = []
    orig = tracker.process

    def process(img, t):
        res = orig(img, t)
        seen.append(watch(res))
        return res

    tracker.process = process
    return run_tracker(tracker, frames), seen

def measure_held(name: str) -> dict:
    """The tracker and the plain peer on one held-card recording (tracking.synth.presets.HELD, rendered and
    cached by tests/scenes.py): frames placed, position errors, and the frame the tracker saw the anchors
    move in the room."""
    from peers import PlainPeer
    from scenes import held_recording, run_tracker
    from tracking.fusion import Tracker

    frames, session = held_recording(name)
    peer = PlainPeer(session.anchors, session.camera)
    plain, pms = [], []
    for _, img, gt in frames:
        t0 = time.perf_counter()
        p = peer.pose(img)
        pms.append((time.perf_counter() - t0) * 1000.0)
        plain.append(np.nan if p is None else float(np.linalg.norm(p[:3, 3] - gt[:3, 3])))
    plain = np.array(plain)
    with Tracker(session.camera, session.anchors) as tr:
        r, seen = _run_watching(tr, frames, lambda res: tr.anchors_moving)
    e = r["errors"]
    return {"name": name, "frames": len(frames), "placed": int(np.isfinite(e).sum()),
            "plain_placed": int(np.isfinite(plain).sum()), "max": float(np.nanmax(e)), "plain_max": float(np.nanmax(plain)),
            "over": int(np.sum(e > HELD_MAX_M)), "plain_over": int(np.sum(plain > HELD_MAX_M)),
            "median": float(np.nanmedian(e)), "plain_median": float(np.nanmedian(plain)),
            "moving_from": next((i for i, m in enumerate(seen) if m), None),
            "ms": float(np.median(r["ms"])), "plain_ms": float(np.median(pms))}


def _held_section(names: list[str]) -> list[str]:
    rows = [measure_held(n) for n in names]
    out = ["### Cards held before the camera (the anchors move in the room)", "",
           "Recordings `tracking.synth.presets.HELD`, rendered on first use into the recordings cache (tracking/synth/cache.py): a "
           "board or lone-marker card waved before a still webcam (slow drifts, two fast swings smeared past reading) "
           "with a textured wall 0.8 m behind, `*_both`: a hand-held camera moving too, and `*_rest`: both move, the board "
           "card put down for 2.5 s between its swings. Ground truth: the camera "
           "in the card's frame. `plain`: PlainPeer on the same frames, same run. Goal (issue 25): frames placed >= "
           "plain, none more than 3 cm off. `moving from`: the frame the tracker saw the anchors move in the room "
           "(from then on the room's keypoints do not carry the pose).", "",
           "| recording | kind | placed arapp / plain | max err mm arapp / plain | frames > 30 mm arapp / plain "
           "| median err mm arapp / plain | moving from frame | median ms arapp / plain | goal met |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        met = r["placed"] >= r["plain_placed"] and r["over"] == 0
        out.append(f"| {r['name']} | {'test' if r['name'] in HELD_TEST else 'tuning'} | {r['placed']} / {r['plain_placed']} "
                   f"(of {r['frames']}) | {_mm(r['max'], 1)} / {_mm(r['plain_max'], 1)} | {r['over']} / {r['plain_over']} "
                   f"| {_mm(r['median'], 1)} / {_mm(r['plain_median'], 1)} | {r['moving_from']} "
                   f"| {r['ms']:.1f} / {r['plain_ms']:.1f} | {'met' if met else '**not met**'} |")
    return out + [""]


HEADON_QUICK = ["test_headon"]
# issue 25.4: rotation error <= 2 degrees after the first second, median position error <= 1 % of the distance,
# jitter <= half of plain OpenCV's
HEADON_ROT_DEG, HEADON_POS_FRACTION, HEADON_JITTER_RATIO = 2.0, 0.01, 0.5


def headon_errors(frames, poses) -> dict:
    """The head-on figures of one run against the ground truth in `frames` [(t, image, true pose)]: the
    largest rotation error (degrees) from one second after the first frame on, the median position error as
    a fraction of the camera's distance from the marker, the jitter (metres, tracking.evaluation.jitter) and
    the tracked fraction. `poses`: world_from_camera per frame, None when lost."""
    from tracking.evaluation import jitter
    from tracking.poses import rotation_angle

    t = np.array([f[0] for f in frames])
    gt = np.array([f[2] for f in frames])
    ok = np.array([p is not None for p in poses])
    rot = np.array([np.degrees(rotation_angle(p[:3, :3].T @ g[:3, :3])) if p is not None else np.nan
                    for p, g in zip(poses, gt)])
    pos = np.array([np.linalg.norm(p[:3, 3] - g[:3, 3]) / np.linalg.norm(g[:3, 3]) if p is not None else np.nan
                    for p, g in zip(poses, gt)])
    late = t >= t[0] + 1.0
    est = np.array([p for p in poses if p is not None]).reshape(-1, 4, 4)
    return {"rot_late_max": float(np.nanmax(rot[late])) if np.isfinite(rot[late]).any() else float("nan"),
            "rot_late_median": float(np.nanmedian(rot[late])) if np.isfinite(rot[late]).any() else float("nan"),
            "pos_fraction": float(np.nanmedian(pos)) if ok.any() else float("nan"),
            "jitter_m": jitter(t[ok], est, gt[ok]) if ok.sum() > 1 else float("nan"), "tracked": float(ok.mean())}


def measure_headon(name: str) -> dict:
    """The tracker and the plain peer on one head-on recording (tracking.synth.presets.HEADON, rendered and
    cached by tests/scenes.py), with the last frame the marker's tilt was undecided."""
    from peers import PlainPeer
    from scenes import held_recording, run_tracker
    from tracking.fusion import Tracker

    frames, session = held_recording(name)
    peer = PlainPeer(session.anchors, session.camera)
    pms, plain = [], []
    for _, img, _ in frames:
        t0 = time.perf_counter()
        plain.append(peer.pose(img))
        pms.append((time.perf_counter() - t0) * 1000.0)
    with Tracker(session.camera, session.anchors) as tr:
        r, flags = _run_watching(tr, frames, lambda res: res.ambiguous)
    undecided = [i for i, f in enumerate(flags) if f]
    return {"name": name, "arapp": headon_errors(frames, r["poses"]), "plain": headon_errors(frames, plain),
            "undecided_s": float(frames[undecided[-1]][0] - frames[0][0]) if undecided else None,
            "ms": float(np.median(r["ms"])), "plain_ms": float(np.median(pms))}


def _headon_section(names: list[str]) -> list[str]:
    rows = [measure_headon(n) for n in names]
    out = ["### A small marker seen head-on (the planar ambiguity, issue 25.4)", "",
           "Recordings `tracking.synth.presets.HEADON`, rendered on first use into the recordings cache (tracking.synth.cache, tests/scenes.py): a "
           "3 cm marker at ~0.7 m on a textured desk, the camera held by hand 4-7 degrees off the marker's normal, "
           "webcam effects (25 ms rolling shutter, MJPEG), 3 s at 640x480. `arapp`: the Tracker (the desk's keypoints "
           "judge the marker's tilt, tracking/anchors/desk.py); `plain`: PlainPeer, same frames, same run. Rotation: "
           "the largest error from 1 s on; position: the median error over the camera's distance; `undecided "
           "until`: the last frame the view asked to tilt the camera. Goals: rotation <= 2 deg, position <= 1 %, "
           "jitter <= half of plain's.", "",
           "| recording | kind | max rot err after 1 s deg arapp / plain | median pos err % dist arapp / plain "
           "| jitter mm arapp / plain | undecided until s | median ms arapp / plain | goals met (rot / pos / jitter) |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        a, p = r["arapp"], r["plain"]
        met = (a["rot_late_max"] <= HEADON_ROT_DEG, a["pos_fraction"] <= HEADON_POS_FRACTION,
               a["jitter_m"] <= HEADON_JITTER_RATIO * p["jitter_m"])
        until = "-" if r["undecided_s"] is None else f"{r['undecided_s']:.2f}"
        out.append(f"| {r['name']} | {'test' if r['name'] in HEADON_TEST else 'tuning'} "
                   f"| {a['rot_late_max']:.2f} / {p['rot_late_max']:.2f} | {100 * a['pos_fraction']:.2f} / "
                   f"{100 * p['pos_fraction']:.2f} | {_mm(a['jitter_m'], 1)} / {_mm(p['jitter_m'], 1)} | {until} "
                   f"| {r['ms']:.1f} / {r['plain_ms']:.1f} | "
                   + " / ".join("met" if m else "**not met**" for m in met) + " |")
    return out + [""]


GOALS = ("tracked >= plain", "median <= plain", "median < 0.4 % dist", "jitter <= 1/2 filtered plain",
         "max <= 20 mm")


def goals_met(r: dict) -> dict:
    """The issue's goals for a test recording, each True/False (the tracker's output against the peers)."""
    s, p, f, med = r["slam"], r["plain"], r["plain_f"], r["median"]
    return dict(zip(GOALS, (s.tracked_fraction >= p.tracked_fraction, med["slam"] <= med["plain"],
                            med["slam"] < 0.004 * r["dist"], s.jitter_m <= 0.5 * f.jitter_m, r["max_err"] <= 0.02)))


def _mm(x: float, digits: int = 2) -> str:
    return f"{x * 1000:.{digits}f}" if np.isfinite(x) else "-"


def _table(kind: str, rows: list[dict]) -> list[str]:
    out = [f"**{kind} recordings**" + (" (the tracker's parameters were chosen on these)" if kind == "Tuning"
                                       else " (never used to choose any parameter)"), "",
           "| recording | size | tracked slam / plain | ATE RMSE mm slam / raw / plain / plain+filter "
           "| median err mm slam / raw / plain / plain+filter | median err / distance slam "
           "| max err mm slam / raw / plain / plain+filter | jitter mm slam / raw / plain / plain+filter "
           "| jitter ratio slam / plain+filter | RPE m/s slam | median ms slam / plain (ratio) | p95 ms slam |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    if not rows:
        out.append("| (none in this run) | | | | | | | | | | | |")
    for r in rows:
        s, w, p, f, med = r["slam"], r["raw"], r["plain"], r["plain_f"], r["median"]
        jr = s.jitter_m / f.jitter_m if f.jitter_m > 0 else float("nan")
        tr = r["slam_ms"] / r["plain_ms"] if r["plain_ms"] > 0 else float("nan")
        out.append(
            f"| {r['name']} | {r['size']} | {s.tracked_fraction:.1%} / {p.tracked_fraction:.1%} "
            f"| {_mm(s.ate_rmse_m)} / {_mm(w.ate_rmse_m)} / {_mm(p.ate_rmse_m)} / {_mm(f.ate_rmse_m)} "
            f"| {_mm(med['slam'])} / {_mm(med['raw'])} / {_mm(med['plain'])} / {_mm(med['plain_f'])} "
            f"| {100 * med['slam'] / r['dist']:.3f} % "
            f"| {_mm(s.ate_max_m, 1)} / {_mm(w.ate_max_m, 1)} / {_mm(p.ate_max_m, 1)} / {_mm(f.ate_max_m, 1)} "
            f"| {_mm(s.jitter_m)} / {_mm(w.jitter_m)} / {_mm(p.jitter_m)} / {_mm(f.jitter_m)} | {jr:.2f} "
            f"| {s.rpe_trans_m_per_s:.4f} | {r['slam_ms']:.1f} / {r['plain_ms']:.1f} ({tr:.2f}) | {r['slam_p95']:.1f} |")
    late = [r for r in rows if r["first"] > 0]
    if late:
        out += ["", "Tracked from the first sighting of the anchors on (no pose can exist before they have been "
                "seen once): " + ", ".join(f"{r['name']} {r['since_first']:.1%} (first seen in frame {r['first']})"
                                           for r in late) + "."]
    return out + [""]


def run(quick: bool = False) -> str:
    from bench_anchors import choose_plain_qr

    qr_call, _ = choose_plain_qr(30 if quick else None)
    names = QUICK if quick else RECORDINGS   # the bundled ones, the others rendered into the cache on first use
    rows = {n: measure(n, qr_call) for n in names}
    tuning = [rows[n] for n in TUNING if n in rows]
    test = [rows[n] for n in TEST if n in rows]
    out = ["## SLAM tracking (anchors + keypoints) vs plain OpenCV marker pose", "",
           "The presets' recordings with ground truth (`recordings/`, the rest rendered by "
           "`arapp synth NAME --cached`); measured on this CPU machine (shared, so times are "
           "noisy). `slam`: the Tracker's output; `raw`: the same Tracker with its pose filter off "
           "(`Tracker(filter=False)`, a second run). `plain`: `benchmarks/peers.py` PlainPeer every frame "
           f"(detectMarkers + solvePnP; QR codes with `{qr_call}`, the fastest OpenCV QR call that decodes, "
           "chosen on the tuning recording qr_anchor as in the anchors section); `plain+filter`: those poses "
           "through arapp's own `PoseFilter` class (FilteredPeer). No trajectory alignment: poses are in the "
           "marker's world frame. ATE and errors are camera positions against the ground truth; the median "
           "error is also given as a fraction of the median camera distance to the world origin.", ""]
    out += _table("Tuning", tuning)
    out += _table("Test", test)
    if test:
        out += ["| test recording | " + " | ".join(GOALS) + " |", "|---|---|---|---|---|---|"]
        for r in test:
            out.append(f"| {r['name']} | " + " | ".join("met" if v else "**not met**" for v in goals_met(r).values())
                       + " |")
        out.append("")
    if [n for n in TEST if n not in rows] and not quick:
        out += ["Missing test recordings: " + ", ".join(n for n in TEST if n not in rows) + ".", ""]
    out += ["| size | recordings | median ms slam (worst) | median ms plain (worst) | worst ratio | goal | met |",
            "|---|---|---|---|---|---|---|"]
    for size, goal in (("640x480", "slam < 15 ms"), ("1280x720", "ratio <= 1")):
        rs = [r for r in rows.values() if r["size"] == size]
        if not rs:
            out.append(f"| {size} | none | | | | {goal} | - |")
            continue
        a = max(r["slam_ms"] for r in rs)
        p = max(r["plain_ms"] for r in rs)
        ratio = max(r["slam_ms"] / r["plain_ms"] for r in rs)
        met = a < 15.0 if size == "640x480" else ratio <= 1.0
        out.append(f"| {size} | {len(rs)} | {a:.1f} | {p:.1f} | {ratio:.2f} | {goal} | {'met' if met else '**not met**'} |")
    out += ["", "Goals (issue 13), on every **test** recording: tracked frames >= plain; median error <= plain and "
            "< 0.4 % of the camera distance; jitter <= half the filtered plain peer's (ratio <= 0.5); max error "
            "<= 20 mm while any anchor or map is in use. Earlier goals, kept: marker_occluded pose in >= 99 % of "
            "frames, max error <= 20 mm; median ms at 1280x720 <= plain's (ratio <= 1), at 640x480 < 15 ms.", "",
            "The tracker never waits for its mapping thread (triangulation, local bundle adjustment). In "
            "the tables above frames are handed in as fast as possible and, between frames, "
            "`Tracker.catch_up()` gives the mapping thread the time a live camera's frame interval would "
            "(outside the measured ms), so the figures do not depend on the machine's load. The same "
            "recordings handed in at their own frame rate (`live`, as from a camera) and as fast as "
            "possible with no catch-up at all (`flat-out`, the map lagging as far behind as the machine "
            "makes it):", "",
            "| recording | kind | pace | tracked | ATE RMSE mm | max err mm | median ms | p95 ms | plain median ms (above) |",
            "|---|---|---|---|---|---|---|---|---|"]
    plain_ms = {n: r["plain_ms"] for n, r in rows.items()}
    paced = ["marker_occluded", "fast_motion", "board_orbit_720p", "test_fast_pan"] if not quick else ["marker_occluded"]
    for name in paced:
        for pace in ("live", "flat-out"):
            q = measure_paced(name, pace)
            plain = f"{plain_ms[name]:.1f}" if name in plain_ms else "-"
            out.append(f"| {name} | {'test' if name in TEST else 'tuning'} | {pace} | {q['m'].tracked_fraction:.1%} "
                       f"| {q['m'].ate_rmse_m * 1000:.2f} | {q['max_err'] * 1000:.1f} | {q['ms']:.1f} | {q['p95']:.1f} "
                       f"| {plain} |")
    out.append("")
    out += _held_section(HELD_QUICK if quick else HELD_TUNING + HELD_TEST)
    out += _headon_section(HEADON_QUICK if quick else HEADON_TUNING + HEADON_TEST)
    return "\n".join(out)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
