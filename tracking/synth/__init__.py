"""Synthetic recordings with exact ground truth: a textured desk, printed anchors, camera effects.

`synthesize(scene, out)` renders a `Scene` (tracking.synth.scene) into a
recording folder (docs/recording-format.md) with `groundtruth.tum`.
Presets: tracking.synth.presets; CLI: `arapp synth`.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Callable

from tracking.recording.schema import Session

__all__ = ["synthesize", "scene_from_arg"]


def scene_from_arg(arg: str):
    """A Scene from a preset name or a scene JSON file path."""
    # the scene tables: only when asked (keeps `import tracking.synth` light)
    from tracking.synth.presets import is_preset, preset
    from tracking.synth.revisits import revisit_by_name
    from tracking.synth.scene import load_scene, parse_scene

    if is_preset(arg):   # any group of presets (tracking.synth.presets.GROUPS)
        return parse_scene(preset(arg), f"preset {arg}")
    if (revisit := revisit_by_name(arg)) is not None:   # scene revisits (tracking.synth.revisits)
        return parse_scene(revisit, f"revisit scene {arg}")
    if arg.endswith(".json") or Path(arg).exists():
        return load_scene(arg)
    return parse_scene(preset(arg))  # raises the "no preset" error listing the presets


def synthesize(scene, out: str | Path, force: bool = False, max_frames: int | None = None,
               progress: Callable[[int, int], None] | None = None) -> Session:
    """Render `scene` into the recording folder `out`; returns the validated Session.

    Writes video (the scene's codec), frames.csv (t = i / fps), session.json
    (source kind `synthetic` with the scene itself) and groundtruth.tum
    (world_from_camera of every frame, OpenCV camera axes). A scene with an `occlusion` block also gets
    depth/ (the simulated depth camera), occlusion/ (ground-truth masks) and occlusion.json
    (tracking.synth.occlusion).
    """
    from tracking.recording.writer import RecordingWriter  # the writer and the renderer (scipy, the scene code)
    from tracking.synth.held import make_renderer  # load only when a recording is made, not for `arapp --help`

    if getattr(scene, "occlusion", None):
        from tracking.synth.occlusion import OcclusionRenderer, write_extras, write_mask

        renderer = OcclusionRenderer(scene)
    else:
        renderer = make_renderer(scene)
    n = scene.frame_count if max_frames is None else min(max_frames, scene.frame_count)
    source = {"kind": "synthetic", "generator": "arapp synth", "scene": json.loads(json.dumps(scene.to_dict()))}
    # the camera that "recorded" it states its rolling-shutter readout, as a calibration that measured it would
    camera = scene.camera
    readout = float(scene.effects.get("rolling_shutter") or 0.0)
    if readout > 0:
        camera = dataclasses.replace(camera, readout=readout)
    with RecordingWriter(out, camera, scene.fps, scene.anchor_blocks, source, scene.fourcc, scene.quality,
                         force) as writer:
        for i in range(n):
            if getattr(scene, "occlusion", None):
                f = renderer.render_full(i)
                writer.write(f.image, f.t, f.pose, depth=f.depth)
                write_mask(writer.folder, i, f.mask)
            else:
                img, pose, t = renderer.render(i)
                writer.write(img, t, pose)
            if progress:
                progress(i + 1, n)
        if getattr(scene, "occlusion", None):
            write_extras(writer.folder, renderer)
    return writer.close()
