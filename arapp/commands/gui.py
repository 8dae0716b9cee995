"""`arapp gui`: the desktop app (also what `arapp` with no arguments opens)."""

HELP = "open the desktop AR app (live view, replay, models, printing)"


def add_arguments(parser):
    parser.add_argument("--source", help="recording folder, video (file:PATH), v4l2:N or depthai[:id] to open")
    parser.add_argument("--model", help="model to show (NURBS JSON or STL/OBJ/PLY/3MF/GLB)")
    parser.add_argument("--frames", type=int, help="show this many frames, then exit (with --screenshot: save it)")
    parser.add_argument("--screenshot", metavar="OUT.png", help="with --frames: save a picture of the whole window")


def run(args):
    from arapp.gui.app import run_gui

    frames = getattr(args, "frames", None)
    screenshot = getattr(args, "screenshot", None)
    if screenshot and frames is None:
        raise ValueError("--screenshot needs --frames N (how many frames to show before the picture)")
    if frames is not None and frames < 1:
        raise ValueError(f"--frames must be at least 1, got {frames}")
    return run_gui(source=getattr(args, "source", None), model=getattr(args, "model", None),
                   frames=frames, screenshot=screenshot)
