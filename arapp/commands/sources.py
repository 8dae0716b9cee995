"""`arapp sources`: list the cameras attached (V4L2 devices, DepthAI devices)."""

HELP = "list attached cameras (V4L2 and DepthAI) and the source specs that open them"


def add_arguments(parser):
    parser.add_argument("--probe", action="store_true",
                        help="open each V4L2 device to report its default size and fps (slower)")


def run(args):
    from tracking.sources import SPEC_HELP, list_depthai, list_v4l2

    v4l2 = list_v4l2()
    try:
        import depthai  # noqa: F401
        have_dai = True
    except ImportError:
        have_dai = False
    dai = list_depthai() if have_dai else []
    print("V4L2 cameras:")
    if not v4l2:
        print("  none found (no /dev/video* devices)")
    for d in v4l2:
        line = f"  {d['spec']:24s} {d['name']}"
        if args.probe:
            line += "  " + _probe(d["device"])
        print(line)
    print("DepthAI (OAK) devices:")
    if not have_dai:
        print("  depthai is not installed")
    elif not dai:
        print("  none found")
    for d in dai:
        print(f"  {d['spec']:24s} {d['name']} ({d['state']})")
    if not v4l2 and not dai:
        print("No camera is attached. You can still replay recordings: arapp replay recordings/board_orbit")
    print(f"Source specs: {SPEC_HELP}")
    return 0


def _probe(device: str) -> str:
    from tracking.errors import SourceError
    from tracking.sources import V4L2Source

    try:
        with V4L2Source(device, read_timeout_s=2.0) as src:
            g = src.granted
            return f"{g['width']}x{g['height']} @ {g['fps']:.0f} fps {g['fourcc']}"
    except SourceError as e:
        return f"(cannot open: {e})"
