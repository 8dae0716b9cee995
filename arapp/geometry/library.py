"""The model library: the NURBS models (JSON) of a `models/` folder, by file or by name (`vase` for
models/vase.json), for the GUI's library list and every command's `--model`."""

from __future__ import annotations

from pathlib import Path

from .errors import ModelError


def library_folder() -> Path:
    """models/ in the working directory when there is one, else the one of the source checkout arapp runs from."""
    here = Path.cwd() / "models"
    if here.is_dir():
        return here
    return Path(__file__).resolve().parents[2] / "models"


def library_files(folder: Path | None = None) -> list[Path]:
    """The library's model files (models/*.json), sorted by name."""
    folder = folder or library_folder()
    return sorted(folder.glob("*.json")) if folder.is_dir() else []


def library_model(name: str | Path) -> Path | None:
    """The library's file for a bare model name (`vase`: models/vase.json), or None when `name` is a path (it
    has a folder or a suffix) or the library has no such model."""
    p = Path(name)
    if p.suffix or p.parent != Path("."):
        return None
    match = [f for f in library_files() if f.stem == p.name]
    return match[0] if match else None


def model_path(name: str | Path) -> Path:
    """The file `name` names: itself when it exists, else the library's model of that bare name; ModelError (one
    line listing the library's names) when neither."""
    path = Path(name)
    if path.exists():
        return path
    found = library_model(path)
    if found is None:
        names = ", ".join(f.stem for f in library_files())
        raise ModelError(str(path), "no such file" + (f" (the library's models, by name: {names})" if names else ""))
    return found
