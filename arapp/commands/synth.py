"""`arapp synth`: render a synthetic recording with exact ground truth."""

HELP = "render a synthetic recording (textured desk, anchors, ground truth) from a preset or scene JSON"


def add_arguments(parser):
    parser.add_argument("scene", nargs="?", help="preset name, a scene .json file, or 'all' for every preset "
                        "(then --out is the parent folder)")
    parser.add_argument("--out", help="recording folder to write (for 'all': the folder holding one per preset)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing recording")
    parser.add_argument("--frames", type=int, help="render only the first N frames (quick previews)")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")


def run(args):
    import sys
    from pathlib import Path

    from arapp.exchange.staging import staged_folder
    from tracking.synth import scene_from_arg, synthesize
    from tracking.synth.presets import (EXTRA_TUNING, HEADON, HEADON_TEST, HELD, HELD_TEST, OCCLUSION, OCCLUSION_TEST,
                                        PRESETS, TEST)

    if args.list or not args.scene:
        for name, p in {**PRESETS, **EXTRA_TUNING, **HELD, **OCCLUSION, **HEADON}.items():
            cam = p["camera"]
            kind = ("test  " if name in TEST or name in HELD_TEST or name in OCCLUSION_TEST or name in HEADON_TEST
                    else "extra " if name in EXTRA_TUNING or name in HELD or name in OCCLUSION or name in HEADON
                    else "tuning")
            print(f"{name:18s} {kind} {cam['width']}x{cam['height']} "
                  f"{p['duration']:.1f} s  {', '.join(a['kind'] for a in p['anchors'])}  {p['trajectory']['kind']}")
        from tracking.synth.revisits import SETS, VARIANTS

        print(f"scene revisits (tracking.synth.revisits): SET_map, SET_revisit_N_VARIANT; sets {', '.join(SETS)} "
              f"(tune_scene: tuning, test_scene: test); variants {', '.join(VARIANTS)}")
        return 0
    if not args.out:
        raise ValueError("--out is required: the recording folder to write (e.g. recordings/my_scene)")
    if args.frames is not None and args.frames < 1:
        raise ValueError(f"--frames must be 1 or more (frames to render), got {args.frames}")
    names = list(PRESETS) if args.scene == "all" else [args.scene]
    for name in names:
        scene = scene_from_arg(name)
        out = Path(args.out) / name if args.scene == "all" else Path(args.out)

        def progress(i, n, out=out):
            if i % 10 == 0 or i == n:
                print(f"\r{out}: frame {i}/{n}", end="", file=sys.stderr, flush=True)

        if out.is_dir() and any(out.iterdir()) and not args.force:
            raise FileExistsError(f"{out}: already holds files (a recording?); use --force to overwrite it")
        # Rendered into a temporary folder that replaces `out` at the end: a failure leaves nothing behind.
        with staged_folder(out, replace=True) as tmp:
            session = synthesize(scene, tmp, force=True, max_frames=args.frames, progress=progress)
        size = sum(p.stat().st_size for p in out.iterdir()) / 1e6
        print(f"\rwrote {out}: {session.camera.width}x{session.camera.height}, "
              f"{scene.frame_count if args.frames is None else min(args.frames, scene.frame_count)} frames, "
              f"{size:.1f} MB", file=sys.stderr)
    return 0
