"""`arapp gui`: the desktop app (also what `arapp` with no arguments opens)."""

HELP = "open the desktop AR app (live view, replay, models, printing)"


def add_arguments(parser):
    parser.add_argument("--source", help="recording folder, video (file:PATH), v4l2:N or depthai[:id] to open")
    parser.add_argument("--model", help="model to show (NURBS JSON or STL/OBJ/PLY/3MF/GLB)")
    parser.add_argument("--frames", type=int, help="show this many frames, then exit (with --screenshot: save it)")
    parser.add_argument("--screenshot", metavar="OUT.png", help="with --frames: save a picture of the whole window")
    parser.add_argument("--toolpaths", metavar="GCODE", help="print preview: draw this G-code's toolpaths on the "
                        "printer bed (the source's first anchor is the bed anchor)")
    parser.add_argument("--printer", metavar="PROFILE", help="printer profile placing the bed (with --toolpaths)")
    parser.add_argument("--layer", type=int, help="with --toolpaths: show layers up to N (0-based), N highlighted")


def run(args):
    from arapp.gui.app import run_gui

    frames = getattr(args, "frames", None)
    screenshot = getattr(args, "screenshot", None)
    if screenshot and frames is None:
        raise ValueError("--screenshot needs --frames N (how many frames to show before the picture)")
    if frames is not None and frames < 1:
        raise ValueError(f"--frames must be at least 1, got {frames}")
    toolpaths, printer, layer = (getattr(args, k, None) for k in ("toolpaths", "printer", "layer"))
    if (printer is not None or layer is not None) and not toolpaths:
        raise ValueError("--printer and --layer go with --toolpaths GCODE (the G-code to preview on the bed)")
    if layer is not None and layer < 0:
        raise ValueError(f"--layer counts from 0, got {layer}")
    if toolpaths:
        from pathlib import Path

        if not Path(toolpaths).is_file():
            raise ValueError(f"--toolpaths {toolpaths}: no such file; slice a model first (arapp slice MODEL -o FILE)")
        from arapp.app.toolpaths import ToolpathBuilder

        ToolpathBuilder().profile(printer)  # a missing profile or bed anchor: say so now, not in a dialog
    return run_gui(source=getattr(args, "source", None), model=getattr(args, "model", None),
                   frames=frames, screenshot=screenshot, toolpaths=toolpaths, printer=printer, layer=layer)
