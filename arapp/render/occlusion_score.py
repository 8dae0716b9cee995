"""Scoring occlusion against a synthetic recording's ground truth (tracking.synth.occlusion): the model box
drawn by the product's renderer at the true pose, occluded by `arapp.render.occlusion`, compared per pixel
with the masks the synthesiser ray cast. Used by tests/test_occlusion.py and benchmarks/bench_occlusion.py."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from arapp.render import occlusion
from tracking.poses import invert, read_tum
from tracking.recording.schema import load_session
from tracking.sources.recording import RecordingSource
from tracking.synth.occlusion import MASK_HIDDEN, MASK_VISIBLE, edge_error_px, iou, read_truth


@dataclass
class OcclusionScore:
    """Pooled over the frames where the model is hidden in part (truth or prediction): `iou_hidden` (the
    hidden part of the model), `iou_visible` (the drawn part), `edge_px` (mean symmetric boundary distance of
    the hidden part), `frames` scored, and the added time per frame in ms (`ms_added`: drawing with
    occlusion minus without, best of three per frame, median over frames; `ms_occlusion`: the occlusion
    step alone)."""

    iou_hidden: float
    iou_visible: float
    edge_px: float
    frames: int
    ms_added: float = float("nan")
    ms_occlusion: float = float("nan")
    per_frame: list = field(default_factory=list)


def score_recording(recording: str | Path, mode: str = "depth",
                    params: occlusion.OcclusionParams = occlusion.DEFAULT_PARAMS,
                    timing: bool = False) -> OcclusionScore:
    """Score `mode` ("depth" or "plane") on an occlusion recording (see the module docstring)."""
    from arapp.render import OverlayRenderer   # PyOpenGL binds its platform on import: only when scoring

    rec = Path(recording)
    session = load_session(rec)
    cam = session.camera
    world_from_model, size, masks = read_truth(rec)
    _, gt = read_tum(rec / "groundtruth.tum")
    box = trimesh.creation.box(tuple(size))
    plane = occlusion.PlaneDepth(cam) if mode == "plane" else None
    counts = np.zeros(4, np.int64)  # hidden intersection, hidden union, visible intersection, visible union
    edges, per_frame, added, alone = [], [], [], []
    src = RecordingSource(rec)
    with OverlayRenderer(cam.K, cam.dist, cam.width, cam.height) as r:
        try:
            for frame in src:
                i = frame.index
                camera_from_world = invert(gt[i])
                T = camera_from_world @ world_from_model
                occ = occlusion.Occluder(mode, depth=frame.depth, plane=plane, camera_from_world=camera_from_world,
                                         params=params)
                r.draw(frame.image, box, T, occlusion=occ)
                if timing:
                    a, b = _time_frame(r, frame.image, box, T, occ)
                    added.append(a)
                    alone.append(b)
                pred_hidden, pred_visible = _predicted(r, box, T, occ)
                gt_hidden, gt_visible = masks[i] == MASK_HIDDEN, masks[i] == MASK_VISIBLE
                if not (gt_hidden.any() or pred_hidden.any()):
                    continue
                counts += [np.count_nonzero(pred_hidden & gt_hidden), np.count_nonzero(pred_hidden | gt_hidden),
                           np.count_nonzero(pred_visible & gt_visible), np.count_nonzero(pred_visible | gt_visible)]
                e = edge_error_px(pred_hidden, gt_hidden)
                if e is not None:
                    edges.append(e)
                per_frame.append({"frame": i, "iou_hidden": iou(pred_hidden, gt_hidden),
                                  "hidden_px": int(gt_hidden.sum()), "edge_px": e})
        finally:
            src.close()
    inter_h, union_h, inter_v, union_v = counts
    ms = lambda v: float(np.median(v) * 1e3) if v else float("nan")  # noqa: E731
    return OcclusionScore(inter_h / union_h if union_h else float("nan"),
                          inter_v / union_v if union_v else float("nan"),
                          float(np.mean(edges)) if edges else float("nan"), len(per_frame),
                          ms(added), ms(alone), per_frame)


def _time_frame(r, image, box, T, occ) -> tuple[float, float]:
    """(seconds occlusion adds to a draw, seconds of the occluder's alpha step alone) on this frame.

    The same renderer and frame with and without occlusion, each drawn afresh (its memo of the last crop
    forgotten), best of three: one GL context, no switch, less noise."""
    plain_s, occ_s = [], []
    for _ in range(3):
        r._read_depth, r._memo = False, None
        t0 = time.perf_counter()
        r.draw(image, box, T)
        plain_s.append(time.perf_counter() - t0)
        r._memo = None
        t0 = time.perf_counter()
        r.draw(image, box, T, occlusion=occ)
        occ_s.append(time.perf_counter() - t0)
    z, x0, y0 = r._last_depth
    step = []
    for _ in range(3):
        t0 = time.perf_counter()
        occ.alpha(x0, y0, z)
        step.append(time.perf_counter() - t0)
    return min(occ_s) - min(plain_s), min(step)


def _predicted(r, box, T, occ):
    """(hidden, visible) boolean masks of the image: the model's pixels the occluder faded out, and the rest."""
    cover = r.render(box, T)[..., 3] >= 128
    alpha = np.ones(cover.shape, np.float32)
    if occ.last_alpha is not None:
        x0, y0 = occ.last_origin
        h, w = occ.last_alpha.shape
        alpha[y0:y0 + h, x0:x0 + w] = occ.last_alpha
    return cover & (alpha < 0.5), cover & (alpha >= 0.5)
