"""`arapp synth`: render a synthetic recording with exact ground truth."""

HELP = "render a synthetic recording (textured desk, anchors, ground truth) from a preset or scene JSON"


def add_arguments(parser):
    parser.add_argument("scene", nargs="?", help="preset name, a scene .json file, or 'all' for every preset "
                        "(then --out is the parent folder)")
    parser.add_argument("--out", help="recording folder to write (for 'all': the folder holding one per preset)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing recording")
    parser.add_argument("--frames", type=int, help="render only the first N frames (quick previews)")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    parser.add_argument("--cached", action="store_true",
                        help="print the preset's recording folder: the bundled recordings/NAME, else the preset "
                        "rendered into the cache (.cache/recordings/, or $ARAPP_RECORDINGS_CACHE) the first time; "
                        "'all': every preset the tests and benchmarks use (the held cards' too)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="with --cached: render up to this many recordings at once (one process each)")


def run(args):
    import sys
    from pathlib import Path

    from arapp.exchange.staging import staged_folder
    from tracking.synth import scene_from_arg, synthesize
    from tracking.synth.presets import PRESETS, all_presets, preset_kind

    if args.list or not args.scene:
        for name, p in all_presets().items():
            cam = p["camera"]
            print(f"{name:18s} {preset_kind(name):6s} {cam['width']}x{cam['height']} "
                  f"{p['duration']:.1f} s  {', '.join(a['kind'] for a in p['anchors'])}  {p['trajectory']['kind']}")
        from tracking.synth.revisits import SETS, VARIANTS

        print(f"scene revisits (tracking.synth.revisits): SET_map, SET_revisit_N_VARIANT; sets {', '.join(SETS)} "
              f"(tune_scene: tuning, test_scene: test); variants {', '.join(VARIANTS)}")
        return 0
    if args.jobs < 1:
        raise ValueError(f"--jobs must be 1 or more (recordings rendered at once), got {args.jobs}")
    if args.cached:
        return _cached(args.scene, sys.stderr, args.jobs)
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


def _cached(scene: str, progress_to, jobs: int = 1) -> int:
    """`--cached`: print the folder of each preset named (bundled, or rendered into the cache on first use);
    with jobs > 1 the missing ones are rendered in that many processes at once."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    from tracking.synth.cache import bundled_folder, cached_recording
    from tracking.synth.presets import HELD, PRESETS, preset

    names = [*PRESETS, *HELD] if scene == "all" else [scene]
    for name in names:
        preset(name)  # an unknown name is refused before anything is rendered
    if jobs > 1:
        missing = [n for n in names if bundled_folder(n) is None]
        start = time.perf_counter()
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for name, _ in zip(missing, pool.map(cached_recording, missing)):
                print(f"{name} ready ({time.perf_counter() - start:.0f} s)", file=progress_to, flush=True)
    for name in names:
        folder = bundled_folder(name)
        if folder is None:
            def progress(i, n, name=name):
                if i % 10 == 0 or i == n:
                    print(f"\rrendering {name}: frame {i}/{n}", end="" if i < n else "\n", file=progress_to,
                          flush=True)

            folder = cached_recording(name, progress=progress)
        print(folder)
    return 0
