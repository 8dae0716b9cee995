"""`arapp gui`: the desktop app (also what `arapp` with no arguments opens)."""

HELP = "open the desktop AR app (live view, replay, models, printing)"


def add_arguments(parser):
    parser.add_argument("--source", help="recording folder, video (file:PATH), v4l2:N or depthai[:id] to open")
    parser.add_argument("--calibration", help="calibration file for --source (a video or V4L2 camera; OpenCV FileStorage "
                        "or ROS camera_info YAML); the same as SPEC?calibration=FILE")
    parser.add_argument("--anchors", help="JSON file with the anchors to track (a list as in session.json, e.g. what "
                        "`arapp markers` wrote); remembered, as Tracking > Anchors does; a recording keeps its own")
    parser.add_argument("--model", help="model to show (NURBS JSON or STL/OBJ/PLY/3MF/GLB, or a library model's "
                        "name: vase)")
    parser.add_argument("--frames", type=int, help="show this many frames, then exit (with --screenshot: save it)")
    parser.add_argument("--screenshot", metavar="OUT.png", help="with --frames: save a picture of the whole window")
    parser.add_argument("--toolpaths", metavar="GCODE", help="print preview: draw this G-code's toolpaths on the "
                        "printer bed (the source's first anchor is the bed anchor)")
    parser.add_argument("--printer", metavar="PROFILE", help="printer profile placing the bed (with --toolpaths)")
    parser.add_argument("--layer", type=int, help="with --toolpaths: show layers up to N (0-based), N highlighted")
    parser.add_argument("--scene", metavar="S.arscene", help="saved scene to track against: relocalises on its map, "
                        "shows its model where it was left (File > Save scene writes one; docs/scene-format.md)")


def no_display() -> bool:
    """Linux with neither an X nor a Wayland display, and no Qt platform chosen (QT_QPA_PLATFORM)."""
    import os
    import sys

    env = os.environ
    return (sys.platform.startswith("linux") and not env.get("DISPLAY") and not env.get("WAYLAND_DISPLAY")
            and not env.get("QT_QPA_PLATFORM"))


def run(args):
    from arapp.gui.app import run_gui

    frames = getattr(args, "frames", None)
    screenshot = getattr(args, "screenshot", None)
    if screenshot and frames is None:
        raise ValueError("--screenshot needs --frames N (how many frames to show before the picture)")
    if frames is not None and frames < 1:
        raise ValueError(f"--frames must be at least 1, got {frames}")
    if frames is None and no_display():
        # (a window on Qt's offscreen platform would run unseen until killed: `arapp` over ssh without X)
        raise RuntimeError("no display to show the window on (DISPLAY and WAYLAND_DISPLAY are unset): run arapp on "
                           "a desktop or with ssh -X, or take a picture headless with --frames N --screenshot OUT.png")
    toolpaths, printer, layer = (getattr(args, k, None) for k in ("toolpaths", "printer", "layer"))
    source = getattr(args, "source", None)
    calibration, anchors = getattr(args, "calibration", None), None
    if calibration:
        from tracking.calibration_file import read_calibration_file
        from tracking.sources.registry import format_spec, parse_spec

        if not source:
            raise ValueError("--calibration goes with --source (the video or camera it calibrates)")
        read_calibration_file(calibration)  # a bad file: one line now, not a dialog
        spec = parse_spec(source)
        if spec.calibration and spec.calibration != calibration:
            raise ValueError(f"two calibrations: {spec.calibration} in --source and --calibration {calibration}; give one")
        source = format_spec(spec.scheme, spec.target, calibration)
    if getattr(args, "anchors", None):
        from tracking.recording.schema import parse_anchors, read_anchor_blocks

        anchors = read_anchor_blocks(args.anchors)
        parse_anchors(anchors, where=f"{args.anchors}: anchors")  # refused here, in one line
    if (printer is not None or layer is not None) and not toolpaths:
        raise ValueError("--printer and --layer go with --toolpaths GCODE (the G-code to preview on the bed)")
    if layer is not None and layer < 0:
        raise ValueError(f"--layer counts from 0, got {layer}")
    if toolpaths:
        from pathlib import Path

        if not Path(toolpaths).is_file():
            raise ValueError(f"--toolpaths {toolpaths}: no such file; slice a model first (arapp slice MODEL -o FILE)")
        from arapp.engine.toolpaths import ToolpathBuilder

        ToolpathBuilder().profile(printer)  # a missing profile or bed anchor: say so now, not in a dialog
    scene = getattr(args, "scene", None)
    if scene:
        from arapp.exchange.scene import read_scene_models

        read_scene_models(scene)   # a missing, corrupt or newer file: one line now, not a dialog
    return run_gui(source=source, model=getattr(args, "model", None), frames=frames, screenshot=screenshot,
                   toolpaths=toolpaths, printer=printer, layer=layer, anchors=anchors, scene=scene)
