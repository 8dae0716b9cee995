"""Printable marker sheets for the anchors in use (PNG at 300 dpi, true size), drawn by tracking.anchors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

DPI = 300.0


def save_sheets(anchors, folder: str | Path) -> list[Path]:
    """One PNG per anchor in `folder`; anchors are AnchorSpecs or session.json blocks. Returns the paths."""
    from tracking.anchors.model import build_models
    from tracking.anchors.render import draw_anchor, plane_layout
    from tracking.session import AnchorSpec, parse_anchors

    specs = anchors if anchors and isinstance(anchors[0], AnchorSpec) else parse_anchors(list(anchors))
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    px_per_m = DPI / 0.0254
    out = []
    for k, model in enumerate(build_models(specs)):
        paper, _, _ = plane_layout(model)
        lo, hi = paper.min(axis=0), paper.max(axis=0)
        w, h = int(np.ceil((hi[0] - lo[0]) * px_per_m)), int(np.ceil((hi[1] - lo[1]) * px_per_m))
        if model.spec.kind in ("aruco_board", "charuco"):
            # OpenCV's board frame: x right, y down the board as printed
            pixel_from_plane = np.array([[px_per_m, 0, -lo[0] * px_per_m], [0, px_per_m, -lo[1] * px_per_m], [0, 0, 1]])
        else:
            # marker frame: x right, y up as printed
            pixel_from_plane = np.array([[px_per_m, 0, -lo[0] * px_per_m], [0, -px_per_m, hi[1] * px_per_m], [0, 0, 1]])
        canvas = np.full((h, w), 255, np.uint8)
        draw_anchor(canvas, model, pixel_from_plane)
        spec = model.spec
        name = f"anchor{k}_{spec.kind}" + (f"_{spec.id}" if spec.id is not None else "") + ".png"
        path = folder / name
        if not cv2.imwrite(str(path), canvas):
            raise OSError(f"cannot write {path}")
        out.append(path)
    return out
