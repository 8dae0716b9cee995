"""Printable anchor sheets at true scale: a page image (PNG and PDF at a stated DPI) plus the `anchors`
block a session needs for what is printed on it.

The pattern is drawn by the same code that renders test views
(tracking.anchors.render.draw_anchor), so what is printed is what the
tracker expects. A 100 mm ruler on the page lets the user check the printer
did not scale the page.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from tracking.anchors.model import build_models
from tracking.anchors.render import draw_anchor, plane_layout
from tracking.anchors.kinds import AnchorSpec

PAGES_MM = {"A4": (210.0, 297.0), "A3": (297.0, 420.0), "Letter": (215.9, 279.4), "A5": (148.0, 210.0)}


def page_size_mm(page: str) -> tuple[float, float]:
    """(width, height) in mm of a named page (A3, A4, A5, Letter) or 'WxH' in mm."""
    for name, size in PAGES_MM.items():
        if page.lower() == name.lower():
            return size
    try:
        w, h = (float(v) for v in page.lower().split("x"))
    except ValueError:
        raise ValueError(f"page {page!r}: use A3, A4, A5, Letter or WIDTHxHEIGHT in mm (e.g. 200x150)") from None
    if w <= 0 or h <= 0:
        raise ValueError(f"page {page!r}: width and height must be positive (mm)")
    return w, h


def describe(spec: AnchorSpec) -> str:
    """One line naming what is printed, with its sizes in mm (the kind's caption)."""
    return spec.anchor_kind.caption(spec)


def sheet(spec: AnchorSpec, dpi: float = 300.0, page: str = "A4") -> tuple[np.ndarray, dict]:
    """(page image, gray uint8 at `dpi`; the session `anchors` block) for one anchor centred on a page."""
    if not 50 <= dpi <= 2400:
        raise ValueError(f"--dpi {dpi}: use a printer resolution between 50 and 2400")
    w_mm, h_mm = page_size_mm(page)
    ppm = dpi / 0.0254  # pixels per metre
    W, H = int(round(w_mm / 1000 * ppm)), int(round(h_mm / 1000 * ppm))
    model = build_models([spec])[0]
    paper, _, _ = plane_layout(model)
    lo, hi = paper.min(axis=0), paper.max(axis=0)
    size = hi - lo
    margin = 0.01  # printers do not print to the edge; room below for the caption and ruler

    def fits(w, h):
        return size[0] <= w / 1000 - 2 * margin and size[1] <= h / 1000 - 2 * margin - 0.03

    if not fits(w_mm, h_mm) and fits(h_mm, w_mm):
        w_mm, h_mm = h_mm, w_mm  # landscape
        W, H = H, W
    if not fits(w_mm, h_mm):
        raise ValueError(f"{describe(spec)} ({size[0] * 1000:.0f} x {size[1] * 1000:.0f} mm with its white border) "
                         f"does not fit a {page} page; choose a larger --page or smaller lengths")
    img = np.full((H, W), 255, np.uint8)
    centre = (lo + hi) / 2
    flip = -spec.anchor_kind.face  # page y runs down: flipped when the printed side faces +z (y up on it)
    # page pixel of the plane point (x, y): the pattern centred a little above the page centre
    cx, cy = (W - 1) / 2, (H - 1) / 2 - 0.01 * ppm
    A = np.array([[ppm, 0, cx - ppm * centre[0]], [0, flip * ppm, cy - flip * ppm * centre[1]], [0, 0, 1.0]])
    draw_anchor(img, model, A, paper=False)
    # caption and a 100 mm ruler under the pattern
    y = int(cy + size[1] / 2 * ppm + 0.008 * ppm)
    scale = dpi / 300.0
    cv2.putText(img, describe(spec), (int(0.015 * ppm), y), cv2.FONT_HERSHEY_SIMPLEX, 0.9 * scale, 0,
                max(1, int(2 * scale)), cv2.LINE_AA)
    cv2.putText(img, "Print at 100 % (no fit-to-page). The ruler must measure 100 mm.",
                (int(0.015 * ppm), y + int(0.008 * ppm)), cv2.FONT_HERSHEY_SIMPLEX, 0.7 * scale, 0,
                max(1, int(2 * scale)), cv2.LINE_AA)
    ry = y + int(0.016 * ppm)
    x0 = int(0.015 * ppm)
    x1 = x0 + int(round(0.1 * ppm))
    if ry + int(0.006 * ppm) < H:
        cv2.line(img, (x0, ry), (x1, ry), 0, max(1, int(2 * scale)))
        for k in range(11):
            xk = x0 + int(round(k * 0.01 * ppm))
            cv2.line(img, (xk, ry), (xk, ry - int((0.004 if k % 5 == 0 else 0.002) * ppm)), 0, max(1, int(2 * scale)))
    return img, {"anchors": [spec.to_dict()]}


def write_sheet(spec: AnchorSpec, out_dir: str | Path, name: str, dpi: float = 300.0, page: str = "A4") -> list[Path]:
    """Write NAME.png and NAME.pdf (true scale at `dpi`) and NAME.anchors.json; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    img, block = sheet(spec, dpi, page)
    pil = Image.fromarray(img)
    png, pdf, js = out / f"{name}.png", out / f"{name}.pdf", out / f"{name}.anchors.json"
    pil.save(png, dpi=(dpi, dpi))
    pil.save(pdf, resolution=dpi)  # page size = pixels / dpi: the PDF page is the paper page
    js.write_text(json.dumps(block, indent=2) + "\n")
    return [png, pdf, js]
