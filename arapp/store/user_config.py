"""The per-user configuration folder: stored camera calibrations, printer secrets, remembered choices.

The folder is platformdirs' user config dir for "arapp" (~/.config/arapp on
Linux), or $ARAPP_CONFIG_DIR when set (tests and portable installs).
Secrets (an OctoPrint API key) are files created with mode 600; remembered
choices live in `state.json` (a flat JSON object).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import platformdirs

STATE_FILE = "state.json"


def config_dir() -> Path:
    """The per-user config folder (created on first use)."""
    env = os.environ.get("ARAPP_CONFIG_DIR")
    path = Path(env).expanduser() if env else Path(platformdirs.user_config_dir("arapp", appauthor=False))
    path.mkdir(parents=True, exist_ok=True)
    return path


def slug(text: str) -> str:
    """A file-name-safe version of `text` (letters, digits, '-', '_', '.'), never empty."""
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", text.strip()).strip("._")
    return s[:80] or "unnamed"


def read_state() -> dict:
    """Remembered choices ({} when none, or when the file is unreadable: a lost preference is not an error)."""
    path = config_dir() / STATE_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def remember(key: str, value) -> None:
    """Store one remembered choice (JSON value) under `key`."""
    state = read_state()
    state[key] = value
    path = config_dir() / STATE_FILE
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(state, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)


def recall(key: str, default=None):
    return read_state().get(key, default)


def secret_path(name: str) -> Path:
    """Where the secret `name` (e.g. an OctoPrint URL's API key) is stored: secrets/<slug>.key."""
    return config_dir() / "secrets" / f"{slug(name)}.key"


def jobs_dir(default: Path) -> Path:
    """Where print jobs (sliced G-code and their saved states) are kept: `default` (the GUI's app data
    folder), or print-jobs/ in $ARAPP_CONFIG_DIR when that is set, so tests and portable installs keep
    their stopped prints to themselves."""
    env = os.environ.get("ARAPP_CONFIG_DIR")
    return (Path(env).expanduser() / "print-jobs") if env else Path(default)
