"""`arapp demo`: the main job on a bundled recording and model (what `make demo` runs)."""

from pathlib import Path

HELP = "replay a bundled recording with a bundled model on the marker and say where the outputs went"

ROOT = Path(__file__).resolve().parents[2]
RECORDING = ROOT / "recordings" / "board_orbit"
MODEL = ROOT / "models" / "vase.json"


def add_arguments(parser):
    parser.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    parser.add_argument("--recording", default=str(RECORDING), help="recording folder to replay")
    parser.add_argument("--model", default=str(MODEL), help="model to draw on the anchor")


def run(args):
    from arapp.engine.replay import ReplayOptions, replay, terminal_progress

    print(f"demo: replaying {args.recording} with {args.model}")
    report = replay(args.recording, args.out, ReplayOptions(model=args.model), progress=terminal_progress())
    out = Path(args.out).resolve()
    print(f"demo: tracked {report['tracked_fraction']:.1%} of {report['frames']} frames at {report['fps']:.1f} fps")
    if "ate_rmse_m" in report and report["ate_rmse_m"] is not None:
        print(f"demo: position error against ground truth: RMSE {report['ate_rmse_m'] * 1000:.2f} mm")
    print(f"demo: overlay video  {out / 'overlay.mp4'}")
    print(f"demo: poses          {out / 'poses.tum'}")
    print(f"demo: per-frame log  {out / 'tracking.csv'}")
    print(f"demo: report         {out / 'report.json'} and {out / 'trajectory.png'}")
    return 0
