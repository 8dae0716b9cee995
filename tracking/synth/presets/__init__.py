"""Built-in synthetic scenes (the recordings in recordings/ and in the recordings cache are these presets).

Each preset is a scene dict in the JSON format of tracking.synth.scene.
Some are bundled in recordings/, the others rendered on demand into the recordings cache
(tracking/synth/cache.py, `arapp synth NAME --cached`; recordings/README.md says which).

TUNING presets are the recordings the tracker's parameters were chosen on; TEST presets (names
starting with test_) were made later, from seeds never used for tuning, with webcam effects
(sensor noise, auto-exposure, white-balance drift, rolling shutter, defocus, chroma subsampling,
MJPEG rate control), and are only ever measured: no parameter is chosen by looking at them
(recordings/README.md).

The presets come in groups, one table each (recordings, extra fast pans, held cards, occlusion,
head-on), kept in GROUPS: `preset()`, `is_preset()`, `all_presets()` and `preset_kind()` look a name up
in all of them, in that order.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from tracking.errors import SessionError
from tracking.synth.presets.fast_pans import EXTRA_TUNING
from tracking.synth.presets.headon import HEADON, HEADON_TEST, HEADON_TUNING
from tracking.synth.presets.held import HELD, HELD_TEST, HELD_TUNING
from tracking.synth.presets.occlusion import OCCLUSION, OCCLUSION_TEST, OCCLUSION_TUNING, occlusion_scene
from tracking.synth.presets.parts import BOARD, MILD_DIST
from tracking.synth.presets.recordings import PRESETS, TEST, TEST_PRESETS, TUNING, TUNING_TWINS

__all__ = ["BOARD", "MILD_DIST", "PRESETS", "TUNING_TWINS", "TEST_PRESETS", "TUNING", "TEST", "EXTRA_TUNING",
           "HELD", "HELD_TUNING", "HELD_TEST", "OCCLUSION", "OCCLUSION_TUNING", "OCCLUSION_TEST", "occlusion_scene",
           "HEADON", "HEADON_TUNING", "HEADON_TEST", "PresetGroup", "GROUPS", "preset", "preset_names",
           "is_preset", "all_presets", "preset_kind"]


@dataclass(frozen=True)
class PresetGroup:
    """One table of presets: `scenes` (name -> scene dict, the table itself: a name added to it is a preset),
    `test` the names in it that are only ever measured, `label` what `arapp synth --list` calls the others
    ("tuning": the tuning recordings; "extra": rendered on demand for their own tests and benchmarks)."""

    name: str
    scenes: dict[str, dict]
    test: list[str]
    label: str


GROUPS: list[PresetGroup] = [
    PresetGroup("recordings", PRESETS, TEST, "tuning"),
    PresetGroup("extra fast pans", EXTRA_TUNING, [], "extra"),
    PresetGroup("held cards", HELD, HELD_TEST, "extra"),
    PresetGroup("occlusion", OCCLUSION, OCCLUSION_TEST, "extra"),
    PresetGroup("head-on", HEADON, HEADON_TEST, "extra"),
]


def _group_of(name: str) -> PresetGroup | None:
    """The first group holding preset `name`, or None."""
    return next((g for g in GROUPS if name in g.scenes), None)


def preset_names() -> list[str]:
    return list(PRESETS)


def is_preset(name: str) -> bool:
    """Whether `name` is a preset of any group."""
    return _group_of(name) is not None


def all_presets() -> dict[str, dict]:
    """Every preset of every group, name -> scene dict (the tables' own dicts, not copies), in GROUPS' order."""
    return {name: scene for g in GROUPS for name, scene in g.scenes.items() if _group_of(name) is g}


def preset_kind(name: str) -> str:
    """The kind of preset `name`: "test" (only ever measured), else its group's label ("tuning", "extra")."""
    group = _group_of(name)
    if group is None:
        raise SessionError(f"no synthetic preset {name!r}")
    return "test" if name in group.test else group.label


def preset(name: str) -> dict:
    """A copy of the named preset's scene dict (a bundled recording's, or an extra tuning scene's)."""
    group = _group_of(name)
    if group is None:
        raise SessionError(f"no synthetic preset {name!r}; presets: "
                           f"{', '.join(all_presets())} "
                           "(or a scene JSON file)")
    return copy.deepcopy(group.scenes[name])
