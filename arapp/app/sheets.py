"""Printable marker sheets for the anchors in use: one PNG + PDF page per anchor at true scale
(tracking.printables draws them, as `arapp markers` does)."""

from __future__ import annotations

from pathlib import Path

from tracking.printables import write_sheet
from tracking.anchors.kinds import AnchorSpec
from tracking.recording.schema import parse_anchors


def sheet_name(index: int, spec) -> str:
    """File stem for anchor `index`: anchor<index>_ and the kind's own stem, e.g.
    anchor0_board_DICT_4X4_50_4x3_40mm (tracking.anchors.kinds)."""
    return f"anchor{index}_{spec.anchor_kind.file_stem(spec)}"


def save_sheets(anchors, folder: str | Path, dpi: float = 300.0, page: str = "A4") -> list[Path]:
    """Write the sheets of `anchors` (AnchorSpecs or session.json blocks) into `folder`; return the files."""
    specs = anchors if anchors and isinstance(anchors[0], AnchorSpec) else parse_anchors(list(anchors))
    out: list[Path] = []
    for k, spec in enumerate(specs):
        out += write_sheet(spec, folder, sheet_name(k, spec), dpi, page)
    return out
