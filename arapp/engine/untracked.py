"""Why a replay or a recording shows none of its anchors, and what it shows instead (issues 25, 26.1).

`untracked_lines` samples a few frames spread over the video, runs anchor discovery on them
(tracking/anchors/discover.py: every dictionary family, both polarities, QR codes) and returns two
lines for the terminal: why nothing was tracked (tracking/anchors/diagnose.why_line) and, when
discovery found an anchor, the suggestion with the `--anchors` JSON to use. `arapp replay` calls it
when a replay tracked nothing, `arapp record` when its recording shows none of its anchors.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tracking.anchors.diagnose import suggestion_anchors, suggestion_line, why_line
from tracking.anchors.discover import Discovery
from tracking.sources.images import image_files, is_image

from arapp.engine.input_source import open_input
from arapp.exchange.meshes import write_atomic

SAMPLED_FRAMES = 8   # frames spread over the video: a board held up for a second of a minute is still met
ENOUGH_FRAMES = 3    # once something is found in this many, the other sampled frames are not looked at


def sample_frames(video: str | Path, count: int = SAMPLED_FRAMES) -> list[np.ndarray]:
    """Up to `count` gray frames spread evenly over a video file, a folder of images or an image (fewer when it
    has fewer or ends early)."""
    if Path(video).is_dir() or is_image(video):
        files = image_files(Path(video))
        picks = sorted({int((k + 0.5) * len(files) / count) for k in range(count)}) if files else []
        grays = (cv2.imread(str(files[i]), cv2.IMREAD_GRAYSCALE) for i in picks)
        return [g for g in grays if g is not None]
    cap = cv2.VideoCapture(str(video))
    try:
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        picks = sorted({int((k + 0.5) * n / count) for k in range(count)}) if n > 0 else []
        out = []
        for i in picks:
            cap.set(cv2.CAP_PROP_POS_FRAMES, i)
            ok, frame = cap.read()
            if ok:
                out.append(frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
        return out
    finally:
        cap.release()


def untracked_lines(video: str | Path, anchors, default_anchors: bool = False, camera=None,
                    found_file: str | Path | None = None) -> list[str]:
    """[why, suggestion] for a video in which `anchors` (AnchorSpecs) gave no pose; [] when they do give one
    in the sampled frames (only checked when `camera` is given: a recording, not a finished replay).
    `found_file`: where to write the suggested anchor list (an `--anchors` file), which the suggestion then
    names; None: the suggestion holds the JSON itself."""
    frames = sample_frames(video)
    if camera is not None and _anchors_give_a_pose(anchors, camera, frames):
        return []
    found = Discovery()
    for k, g in enumerate(frames):
        if k >= ENOUGH_FRAMES and found.suggestions():
            break   # something was found in frames across the video: the rest would only repeat it
        found.look_all(g)
    lines = [why_line(anchors, found, default_anchors)]
    suggestions = found.suggestions()
    if suggestions:
        written = None
        if found_file is not None:
            write_atomic(found_file, suggestion_anchors(suggestions[0]).encode())
            written = str(found_file)
        lines.append(suggestion_line(suggestions[0], written))
    return lines


def _anchors_give_a_pose(anchors, camera, frames) -> bool:
    from tracking.anchors.tracker import AnchorTracker   # the tracker is heavy; only a recording's check needs it

    tracker = AnchorTracker(anchors, camera, filter=False)
    for k, g in enumerate(frames):
        if g.shape == (camera.height, camera.width) and tracker.process(g, float(k)).world_from_camera is not None:
            return True
    return False


def untracked_lines_for(recording: str | Path, calibration: str | None = None, anchors_file: str | None = None,
                        found_file: str | Path | None = None) -> list[str]:
    """untracked_lines for what `arapp replay` was given: a recording folder or a plain video, with the anchors
    it tracked (arapp.engine.input_source.open_input: `anchors_file`, else a recording's own, else the default);
    `found_file` as there."""
    with open_input(recording, calibration=calibration, anchors=anchors_file, default_anchor_note=False) as opened:
        session = getattr(opened.source, "session", None)
        anchors, default = opened.anchors, opened.default_anchors
    video = session.video_path if session is not None else Path(recording)
    return untracked_lines(video, anchors, default_anchors=default, found_file=found_file)
