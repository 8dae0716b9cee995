"""Synthetic scene revisits: one desk mapped in a first session, then visited again along other paths,
at another time of day (exposure and colour changed), with the marker taken away.

    scenes = revisit_set("test_scene")   # {name: scene dict}: "<set>_map", "<set>_revisit_<i>_<variant>"
    scene = revisit_by_name("test_scene_revisit_2_bare")   # one of them (`arapp synth NAME`), or None

Every session of a set shares the desk (texture seed, size) and the anchor's place, so their ground
truths are in one world frame: the first session's anchor frame. The sets' seeds are kept apart:
`tune_scene` is for choosing parameters, `test_scene` is only measured (recordings/README.md's rule). Short
(a 3 s mapping pass, 1.2 s revisits at 640x480), generated when a test or benchmark needs them.
"""

from __future__ import annotations


import numpy as np


MILD_DIST = [-0.08, 0.04, 0.0005, -0.0005, 0.0]
# bare: the marker removed; wide: from views beyond the mapped ones (azimuth up to 20 degrees past the first
# session's sweep, nearer or farther), the marker removed
VARIANTS = ("path", "evening", "bare", "bare_evening", "bare_wide")

# per set: scene seed base, desk seed, marker id, marker length (m)
SETS = {
    "tune_scene": {"seed": 600, "desk": 610, "id": 17, "length": 0.06},
    "test_scene": {"seed": 700, "desk": 710, "id": 21, "length": 0.055},
}


def _base(name: str, seed: int, s: dict, duration: float) -> dict:
    return {
        "name": name, "seed": seed, "fps": 30, "duration": duration,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": s["id"], "length": s["length"]}],
        "desk": {"size": [1.6, 1.2], "ppm": 1800, "seed": s["desk"]},
        "effects": {"noise": 0.8, "sensor": {"full_well": 3000, "read_noise": 1.5}, "vignette": 0.15},
        "video": {"fourcc": "MJPG", "quality": 85},
        "supersample": 2,
    }


def _eye(azimuth: float, distance: float, elevation: float) -> list[float]:
    az, el = np.radians(azimuth), np.radians(elevation)
    return [float(distance * np.cos(el) * np.cos(az)), float(distance * np.cos(el) * np.sin(az)),
            float(distance * np.sin(el))]


def mapping_scene(set_name: str) -> dict:
    """The first session: a slow sweep over the desk around the marker, 3 s."""
    s = SETS[set_name]
    keys = []
    for t, az, el, d, tx, ty in ((0.0, -135, 52, 0.45, -0.04, 0.0), (1.0, -110, 58, 0.42, 0.0, 0.03),
                                 (2.0, -80, 60, 0.44, 0.02, 0.02), (3.0, -48, 54, 0.46, 0.05, -0.01)):
        keys.append({"t": t, "eye": _eye(az, d, el), "target": [tx, ty, 0.0]})
    scene = _base(f"{set_name}_map", s["seed"], s, 3.0)
    scene["trajectory"] = {"kind": "keyframes", "keys": keys,
                           "shake": {"pos_mm": 1.0, "rot_deg": 0.2, "freq_hz": 1.5}}
    return scene


def revisit_scene(set_name: str, index: int, variant: str) -> dict:
    """Revisit `index` of a set: a random short path within the mapped views (its own seed), 1.2 s."""
    if variant not in VARIANTS:
        raise ValueError(f"revisit variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
    s = SETS[set_name]
    # (the first four variants' seeds interleave; bare_wide, added later, has a range of its own)
    seed = s["seed"] + (10 + 4 * index + VARIANTS.index(variant) if variant != "bare_wide" else 70 + index)
    rng = np.random.default_rng(seed)
    if variant == "bare_wide":
        side = rng.choice([-1.0, 1.0])
        az0 = float(-91.5 + side * rng.uniform(45, 63))   # the sweep covers -135..-48: 0-20 degrees past its ends
        el0, d0 = rng.uniform(42, 66), rng.uniform(0.34, 0.58)
    else:
        az0 = rng.uniform(-125, -60)
        el0, d0 = rng.uniform(50, 60), rng.uniform(0.40, 0.48)
    az1 = az0 + rng.uniform(-12, 12)
    t0 = rng.uniform(-0.03, 0.03, 2)
    t1 = t0 + rng.uniform(-0.02, 0.02, 2)
    scene = _base(f"{set_name}_revisit_{index}_{variant}", seed, s, 1.2)
    scene["trajectory"] = {"kind": "keyframes", "keys": [
        {"t": 0.0, "eye": _eye(az0, d0, el0), "target": [*map(float, t0), 0.0]},
        {"t": 1.2, "eye": _eye(az1, d0 + rng.uniform(-0.03, 0.03), el0 + rng.uniform(-4, 4)),
         "target": [*map(float, t1), 0.0]}],
        "shake": {"pos_mm": 1.0, "rot_deg": 0.2, "freq_hz": 1.5}}
    if "evening" in variant:
        # another time of day: the lamp on the other side of the desk and the room dimmer (a brightness
        # gradient across the desk the first session did not have), a warmer white balance, a fixed
        # exposure that no longer matches, and the noise of a darker image
        scene["desk"]["lamp"] = {"at": [-0.35, 0.3], "strength": 0.5, "ambient": 0.6}
        scene["effects"] = {"noise": 1.2, "sensor": {"full_well": 1500, "read_noise": 2.5}, "vignette": 0.3,
                            "auto_exposure": {"target": 60, "speed": 0.05, "initial_gain": 0.8,
                                              "min_gain": 0.75, "max_gain": 0.85},
                            "white_balance": {"amplitude": 0.12, "period": 40.0, "phase": 1.2}}
    if "bare" in variant:
        scene["desk"]["anchors_shown"] = False
    return scene


def revisit_set(set_name: str, revisits: int = 3, variants=VARIANTS) -> dict[str, dict]:
    """The mapping scene and `revisits` revisits of each variant, by name."""
    out = {f"{set_name}_map": mapping_scene(set_name)}
    for i in range(revisits):
        for v in variants:
            sc = revisit_scene(set_name, i, v)
            out[sc["name"]] = sc
    return out


def revisit_by_name(name: str) -> dict | None:
    """The scene dict of a set's mapping session or revisit by its name, or None for other names."""
    for set_name in SETS:
        if name == f"{set_name}_map":
            return mapping_scene(set_name)
        prefix = f"{set_name}_revisit_"
        if name.startswith(prefix):
            index, _, variant = name[len(prefix):].partition("_")
            if index.isdigit() and variant in VARIANTS:
                return revisit_scene(set_name, int(index), variant)
    return None
