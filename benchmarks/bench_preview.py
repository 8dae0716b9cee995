"""The AR print preview's full toolpath stack at 640x480: renderer time per frame with every layer drawn and
with the layers a line's width hides left out (modes.LAYER_PX_PER_WIDTH), over recordings/printer_bed's
true poses, and how alike the two pictures are. The vase at 40 mm, 0.2 mm layers (the built-in slicer).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "recordings" / "printer_bed"
GOAL_MS = 1000.0 / 29 - 15.0  # what a 29 fps view leaves the toolpaths beside tracking and the model (~15 ms)


def run(quick: bool = False) -> str:
    import arapp.render.modes as modes
    from arapp.geometry import load_model
    from arapp.printing import SliceSettings, load_profile, placed_solid, slice_mesh
    from arapp.printing.bed_anchor import bed_from_anchor_measured, save_bed_anchor
    from arapp.printing.gcode import parse_gcode
    from arapp.render import OverlayRenderer
    from arapp.engine.toolpath_overlay import toolpath_line_sets, world_from_bed
    from tracking.poses import invert, read_tum
    from tracking.recording.schema import load_session

    with tempfile.TemporaryDirectory() as tmp:
        profile = load_profile(save_bed_anchor(Path(tmp) / "p.json", {"kind": "aruco", "dictionary": "DICT_4X4_50",
                                                                       "id": 42, "length": 0.04},
                                               bed_from_anchor_measured((65.0, 45.0))))
    model = load_model(ROOT / "models" / "vase.json")
    model.placement = type(model.placement)(size_mm=40.0)
    result = slice_mesh(placed_solid(model, profile=profile),
                        SliceSettings(layer_height=0.2, infill=20), profile)
    layers = parse_gcode(result.gcode)
    sets = toolpath_line_sets(layers, (profile.bed.width, profile.bed.depth, profile.bed.height))
    session = load_session(RECORDING)
    cam = session.camera
    _, gt = read_tum(RECORDING / "groundtruth.tum")
    wfb = world_from_bed(np.eye(4), profile.bed_from_anchor)
    frame = cv2.VideoCapture(str(RECORDING / "video.avi")).read()[1]
    n = 20 if quick else len(gt)
    rows, pics = {}, {}
    old = modes.LAYER_PX_PER_WIDTH
    try:
        for name, lod in (("every layer", 0.0), ("layers a line hides left out", old)):
            modes.LAYER_PX_PER_WIDTH = lod
            with OverlayRenderer(cam.K, cam.dist, cam.width, cam.height) as r:
                pics[name] = r.render(None, invert(gt[0]) @ wfb, line_sets=sets)
                times = []
                for i in range(n):
                    t = time.perf_counter()
                    r.draw(frame, None, invert(gt[i % len(gt)]) @ wfb, line_sets=sets)
                    times.append((time.perf_counter() - t) * 1e3)
                rows[name] = (float(np.median(times)), r.gl_renderer)
    finally:
        modes.LAYER_PX_PER_WIDTH = old
    a, b = (p[..., 3] > 100 for p in pics.values())
    iou = (a & b).sum() / max(1, (a | b).sum())
    segs = sum(len(s.segments()) // 2 for s in sets)
    out = ["## Print preview: the full toolpath stack", "",
           f"{len(layers)} layers, {segs:,} segments, 640x480, {n} frames of printer_bed, "
           f"renderer {rows['every layer'][1]}. Goal: at most {GOAL_MS:.0f} ms (a 29 fps view).", "",
           "| drawing | median ms / frame | goal |", "|---|---|---|"]
    for name, (ms, _) in rows.items():
        out.append(f"| {name} | {ms:.1f} | {'met' if ms <= GOAL_MS else 'not met'} |")
    out += ["", f"Same picture: coverage IoU {iou:.3f} between the two (frame 0).", ""]
    return "\n".join(out)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
