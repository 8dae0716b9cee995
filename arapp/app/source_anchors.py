"""Anchors remembered per source: the ones the user accepted from anchor discovery for that video or camera.

Kept in the per-user config (arapp.store.user_config, state.json key `source_anchors`: {source key: [anchor JSON
blocks]}), keyed by `source_key`: a file's absolute path (so `clip.mp4`, `file:clip.mp4` and
`file:/abs/clip.mp4?calibration=cam.yaml` are one source), else the scheme and device (`v4l2:0`). The
session opens a source with its remembered anchors when it has some, else with the anchors setting.
"""

from __future__ import annotations

from pathlib import Path

from arapp.store import user_config
from tracking.errors import SourceError
from tracking.sources import parse_spec

KEY = "source_anchors"


def source_key(spec: str) -> str:
    """The key a source's anchors are remembered under (see module doc)."""
    try:
        s = parse_spec(spec)
    except SourceError:
        return str(spec).strip()
    target = Path(s.target).expanduser() if s.target else None
    if target is not None and target.exists():
        return str(target.resolve())
    return f"{s.scheme}:{s.target}"


def remembered(spec: str) -> list | None:
    """The anchor blocks remembered for the source `spec`, or None."""
    blocks = user_config.recall(KEY, {})
    found = blocks.get(source_key(spec)) if isinstance(blocks, dict) else None
    return found if isinstance(found, list) and found else None


def remember(spec: str, anchors: list) -> None:
    """Remember `anchors` (anchor JSON blocks, metres) for the source `spec`."""
    blocks = user_config.recall(KEY, {})
    blocks = dict(blocks) if isinstance(blocks, dict) else {}
    blocks[source_key(spec)] = list(anchors)
    user_config.remember(KEY, blocks)
