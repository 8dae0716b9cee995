"""The printers a user can slice and print for, named one way everywhere (no Qt).

A printer key is "preset:KEY" (arapp.printing.presets), the name of a profile
shipped with arapp ("generic"), or a profile file's path (the user's own,
e.g. `<config>/printers/<preset>.json` that Printer set-up's Bed marker
writes). Printer set-up stores its choice as such a key
(arapp.gui.print.printer_setup.saved_choice()["profile"]); the print panel lists
`printer_choices()` and slices for `resolve_profile(key)`.
"""

from __future__ import annotations

import json
from pathlib import Path

from arapp.store import user_config
from arapp.printing import load_profile
from arapp.printing.presets import PRESETS, preset_profile
from arapp.printing.profile import shipped_profiles

PRESET = "preset:"


def user_profiles() -> list[Path]:
    """The user's own profile files: `<config>/printers/*.json`, by name."""
    folder = user_config.config_dir() / "printers"
    return sorted(folder.glob("*.json")) if folder.is_dir() else []


def _file_label(path: Path) -> str:
    try:
        name = json.loads(path.read_text()).get("name") or path.stem
    except (OSError, ValueError, AttributeError):
        name = path.stem
    return f"{name} (your profile: {path.name})"


def printer_choices(extra: list[str] = ()) -> list[tuple[str, str]]:
    """(label, key) of every printer to offer: the user's own profiles first (they carry the bed marker),
    then the presets, the shipped profiles, and `extra` keys (e.g. the set-up's file elsewhere)."""
    out = [(_file_label(p), str(p)) for p in user_profiles()]
    out += [(data["name"], f"{PRESET}{key}") for key, data in PRESETS.items()]
    out += [(f"{name} (shipped profile)", name) for name in shipped_profiles()]
    known = {k for _, k in out}
    out += [(_file_label(Path(k)), k) for k in extra if k and k not in known]
    return out


def resolve_profile(key: str | None):
    """The PrinterProfile for a printer key (see the module doc); ProfileError/OSError when it cannot be read."""
    if key and str(key).startswith(PRESET):
        return preset_profile(str(key)[len(PRESET):])
    return load_profile(key)
