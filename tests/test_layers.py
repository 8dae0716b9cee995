"""Every package and module directly under arapp/ and tracking/ sits in a layer of pyproject.toml's
import-linter contracts (lint-imports checks the arrows; this checks that nothing is left outside)."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _layers(name: str) -> tuple[set[str], list[str]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    (contract,) = [c for c in config["tool"]["importlinter"]["contracts"] if c["name"].startswith(name)]
    names = set()
    for layer in contract["layers"]:
        for part in layer.replace(":", "|").split("|"):
            names.add(part.strip().strip("()"))
    return names, contract.get("containers", [])


def _children(package: str) -> set[str]:
    folder = ROOT / package
    modules = {p.stem for p in folder.glob("*.py") if p.stem != "__init__"}
    packages = {p.name for p in folder.iterdir() if (p / "__init__.py").is_file()}
    return modules | packages


def test_every_arapp_package_is_in_a_layer():
    names, _ = _layers("Layers of arapp")
    expected = {f"arapp.{c}" for c in _children("arapp")} | {"tracking"}
    assert names == expected


def test_every_tracking_module_is_in_a_layer():
    names, containers = _layers("Layers inside tracking")
    assert containers == ["tracking"]
    optional = {"fusion", "tracker"}  # the tracker's split (issue 28): either may be absent
    assert names - optional == _children("tracking") - optional
