"""Output folders written whole or not at all.

`staged_folder(final)` gives a hidden temporary folder next to `final` to
write into. When the block ends normally its files are moved into `final`
(created if needed; files of the same name replaced, or, with
`replace=True`, the whole folder swapped, as for a recording); when it
raises, the temporary folder and any parent folders it had to create are
removed, so a failed command leaves no empty or half-written output behind.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


def _missing_parents(path: Path) -> list[Path]:
    """The folders above `path` that do not exist yet, deepest first."""
    out = []
    p = path.parent
    while not p.exists() and p != p.parent:
        out.append(p)
        p = p.parent
    return out


@contextmanager
def staged_folder(final, replace: bool = False) -> Iterator[Path]:
    """Yield a temporary folder to fill; publish it as `final` on success (see the module docstring)."""
    final = Path(final)
    if final.exists() and not final.is_dir():
        raise FileExistsError(f"{final}: exists and is not a folder; choose another output folder")
    created = _missing_parents(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for p in created:  # deepest first; only folders this call made, and only while empty
            try:
                p.rmdir()
            except OSError:
                break
        raise
    if replace and final.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".old", dir=final.parent))
        os.replace(final, old / final.name)
        os.replace(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
        return
    if not final.exists():
        os.replace(tmp, final)
        return
    for item in tmp.iterdir():
        target = final / item.name
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        os.replace(item, target)
    tmp.rmdir()
