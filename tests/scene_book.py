"""The synthetic scenes the tests render themselves, each under a name, rendered once per machine.

A test that needs a sequence no preset gives (a hand over a marker, a board panned past reading) names its
scene here (`SCENES`, a registry: one function returning the scene's JSON) and asks `book_frames(name)`
for its frames. The frames are rendered the first time any process asks, into the recordings cache
(tracking.synth.cache: `.cache/recordings/scenes/NAME-KEY`, KEY a hash of the scene's JSON and of the
renderer) as lossless PNG files beside the true poses, so later runs read exactly the pixels a fresh render
gives; several pytest-xdist workers asking at once render it once (a file lock), and a half-written folder
is never seen (written under another name, then renamed). `make recordings` renders every scene here
beforehand (`python tests/scene_book.py --jobs N`), so a test run only reads them.

The scan tests' vase recordings (tests/scan_scene.py) are cached the same way: `vase_recording`.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:   # run as a script by `make recordings`
    sys.path.insert(0, str(HERE.parent))

from scenes import board_scene_dict, render_sequence, scene_dict  # noqa: E402
from tracking.synth.cache import cache_root, file_lock, scene_key  # noqa: E402

# name -> function returning the scene's JSON (tracking.synth.scene)
SCENES: dict[str, Callable[[], dict]] = {}

# the lone marker of the anchor-rejection scenes (metres)
MARKER = 0.06


def scene(name: str):
    """Register the decorated function as the builder of scene `name`."""
    def register(build: Callable[[], dict]) -> Callable[[], dict]:
        SCENES[name] = build
        return build
    return register


@scene("finger_flick")
def _finger_flick() -> dict:
    """2.5 s at 0.45 m from a lone 6 cm marker (tests/test_anchor_rejection.py paints the fingers)."""
    keys = [{"t": 0.0, "eye": [-0.06, -0.20, 0.40], "target": [0, 0, 0]},
            {"t": 2.5, "eye": [0.04, -0.18, 0.41], "target": [0.01, 0, 0]}]
    return scene_dict("hand", keys, marker_length=MARKER, seed=11, noise=1.5, supersample=3)


LOOKALIKE_AT = [0.16, 0.02]   # where the look-alike of anchor id 17 lies on the desk (metres)


@scene("lookalike")
def _lookalike() -> dict:
    """The camera pans from marker id 3 (the world) until only a look-alike of anchor id 17 is in view."""
    keys = [{"t": 0.0, "eye": [-0.16, -0.25, 0.40], "target": [-0.12, 0, 0]},
            {"t": 1.5, "eye": [-0.06, -0.25, 0.40], "target": [-0.04, 0, 0]},
            {"t": 2.5, "eye": [0.08, -0.25, 0.40], "target": [0.10, 0.0, 0]},
            {"t": 3.5, "eye": [0.20, -0.22, 0.40], "target": [0.32, 0.02, 0]}]
    sj = scene_dict("lookalike", keys, marker_length=MARKER, seed=7, noise=1.5, supersample=2)
    sj["anchors"].append({"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 17, "length": MARKER,
                          "world_from_anchor": desk_point(LOOKALIKE_AT)})
    return sj


def desk_point(xy) -> list[list[float]]:
    """The 4x4 pose (nested lists) of a point `xy` (metres) on the desk, axes the desk's."""
    T = np.eye(4)
    T[:2, 3] = xy
    return T.tolist()


@scene("resting_hand")
def _resting_hand() -> dict:
    """3 s at ~0.44 m from a lone 5.8 cm marker, the camera orbiting slowly with a hand's shake
    (tests/test_anchor_border_jitter.py paints the hand)."""
    keys = [{"t": 0.0, "eye": [-0.07, -0.21, 0.38], "target": [0.0, 0.0, 0.0]},
            {"t": 1.0, "eye": [-0.035, -0.215, 0.383], "target": [0.002, 0.001, 0.0]},
            {"t": 2.0, "eye": [0.0, -0.212, 0.386], "target": [0.003, -0.001, 0.0]},
            {"t": 3.0, "eye": [0.035, -0.205, 0.384], "target": [0.006, 0.0, 0.0]}]
    sj = scene_dict("resting_hand", keys, marker_length=0.058, seed=23, noise=2.0, supersample=2)
    sj["trajectory"]["shake"] = {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.6}
    sj["effects"]["defocus"] = 0.6
    return sj


@scene("pan_blur")
def _pan_blur() -> dict:
    """A 5x3 GridBoard at ~0.5 m, the camera panning across it and back in a second, motion blur over 60 %
    of each frame."""
    keys = [{"t": 0.0, "eye": [-0.02, -0.26, 0.42], "target": [0.02, 0.05, 0.0]},
            {"t": 0.5, "eye": [0.06, -0.25, 0.42], "target": [0.12, 0.06, 0.0]},
            {"t": 1.0, "eye": [0.0, -0.26, 0.42], "target": [0.02, 0.05, 0.0]}]
    return board_scene_dict("pan_blur", keys, seed=21, motion_blur=0.6, blur_samples=7)


@scene("partial_return")
def _partial_return() -> dict:
    """A board, the camera panning off it and back until two of its markers show at the image edge."""
    centre = [0.09, 0.05, 0.0]
    keys = [{"t": 0.0, "eye": [0.09, -0.22, 0.40], "target": centre},
            {"t": 0.3, "eye": [0.09, -0.22, 0.40], "target": centre},
            {"t": 0.7, "eye": [0.20, -0.22, 0.40], "target": [0.55, 0.05, 0.0]},
            {"t": 1.0, "eye": [0.18, -0.22, 0.40], "target": [0.36, 0.05, 0.0]},
            {"t": 1.3, "eye": [0.09, -0.22, 0.40], "target": centre}]
    return board_scene_dict("partial_return", keys, seed=41)


@scene("still_board")
def _still_board() -> dict:
    """A 5x3 GridBoard before a nearly still camera, half a second."""
    keys = [{"t": 0.0, "eye": [0.06, -0.24, 0.42], "target": [0.10, 0.06, 0.0]},
            {"t": 0.5, "eye": [0.065, -0.24, 0.42], "target": [0.10, 0.06, 0.0]}]
    return board_scene_dict("still_board", keys, seed=33)


@scene("tiles")
def _tiles() -> dict:
    """Away from the marker and back over a floor of identical tiles (every keypoint has look-alikes)."""
    from scenes import away_and_back_keys

    return scene_dict("tiles", away_and_back_keys(away_s=3.0), fps=15.0, desk_style="tiles")


@scene("away")
def _away() -> dict:
    """Five seconds away from the marker over a textured desk, then back."""
    from scenes import away_and_back_keys

    return scene_dict("away", away_and_back_keys(away_s=5.0), fps=15.0)


def scene_json(name: str) -> dict:
    """The JSON of the book's scene `name`."""
    if name not in SCENES:
        raise KeyError(f"no scene {name!r} in tests/scene_book.py; there are: {', '.join(sorted(SCENES))}")
    return SCENES[name]()


def cached_folder(name: str, key: str, build: Callable[[Path], object]) -> Path:
    """`scenes/NAME-KEY` in the recordings cache, made by `build(folder)` the first time any process asks
    (under a lock; built under another name and renamed when complete). Older keys of `name` are removed."""
    root = cache_root() / "scenes"
    folder = root / f"{name}-{key}"
    with file_lock(root / f".{name}.lock"):
        if not (folder / "complete").is_file():
            tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".partial", dir=root))
            try:
                build(tmp / "out")
                (tmp / "out" / "complete").touch()
                shutil.rmtree(folder, ignore_errors=True)
                os.replace(tmp / "out", folder)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
            for stale in root.glob(f"{name}-*"):
                if stale != folder and stale.is_dir() and len(stale.name) == len(folder.name):
                    shutil.rmtree(stale, ignore_errors=True)
    return folder


def _write_frames(sj: dict, folder: Path) -> None:
    frames, _ = render_sequence(sj)
    folder.mkdir(parents=True)
    for i, (_, img, _) in enumerate(frames):
        if not cv2.imwrite(str(folder / f"{i:05d}.png"), img, [cv2.IMWRITE_PNG_COMPRESSION, 1]):
            raise OSError(f"{folder}: cannot write frame {i}")
    np.savez(folder / "truth.npz", t=np.array([f[0] for f in frames]), pose=np.array([f[2] for f in frames]))


def book_frames(name: str, frames: slice | None = None):
    """The book's scene `name` as `scenes.render_sequence` gives it: [(t, BGR image, true world_from_camera)]
    and the parsed scene; read from the cache (rendered there on first use), the same pixels."""
    from tracking.synth.scene import parse_scene

    sj = scene_json(name)
    folder = cached_folder(name, scene_key(sj), lambda out: _write_frames(sj, out))
    with np.load(folder / "truth.npz") as truth:
        times, poses = truth["t"], truth["pose"]
    idx = range(len(times))
    if frames is not None:
        idx = idx[frames]
    out = [(float(times[i]), cv2.imread(str(folder / f"{i:05d}.png"), cv2.IMREAD_COLOR), poses[i]) for i in idx]
    return out, parse_scene(sj)


def vase_recording(n_frames: int, seed: int, with_depth: bool = False) -> Path:
    """The folder of tests/scan_scene.py's vase orbit (`write_vase_recording` with these arguments), cached
    under a key of the arguments and of scan_scene.py's and the renderer's source."""
    import scan_scene

    h = hashlib.sha256(inspect.getsource(scan_scene).encode())
    h.update(f"{n_frames} {seed} {with_depth}".encode())
    h.update(scene_key({}).encode())   # the renderer's fingerprint (recording writer, OpenCV's version)
    name = f"scan_vase_{n_frames}_{seed}{'_depth' if with_depth else ''}"
    return cached_folder(name, h.hexdigest()[:12],
                         lambda out: scan_scene.write_vase_recording(out, n_frames=n_frames, seed=seed,
                                                                     with_depth=with_depth))


# the vase recordings the scan tests read: (frames, seed, with depth)
VASES = [(44, 11, False), (36, 11, True), (40, 5, False)]


def _render(job: str) -> str:
    if job.startswith("vase:"):
        n, seed, depth = VASES[int(job[5:])]
        vase_recording(n, seed, depth)
    else:
        book_frames(job, slice(0, 0))
    return job


def main(argv: list[str] | None = None) -> int:
    """Render every scene of the book (and the scan vases) that the cache lacks."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1, help="processes rendering at once")
    args = ap.parse_args(argv)
    jobs = sorted(SCENES) + [f"vase:{i}" for i in range(len(VASES))]
    if args.jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(args.jobs) as pool:
            list(pool.map(_render, jobs))
    else:
        for job in jobs:
            _render(job)
    return 0


if __name__ == "__main__":
    sys.exit(main())
