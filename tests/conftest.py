"""Test-wide settings: headless GL and Qt, and paths to the bundled data."""

import os
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT


@pytest.fixture()
def config_dir(tmp_path, monkeypatch) -> Path:
    """The app's config folder (ARAPP_CONFIG_DIR) in tmp_path, so no test reads or writes the user's."""
    d = tmp_path / "config"
    monkeypatch.setenv("ARAPP_CONFIG_DIR", str(d))
    return d
