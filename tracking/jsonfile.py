"""Reading JSON documents (models, printer profiles, anchor lists, scenes) with errors that name the file.

`read_json(path, what, error)` returns the parsed document or raises `error`
(a ValueError subclass) with one line: the file, what it should be, and the
line and column of a syntax error.
"""

from __future__ import annotations

import json
from pathlib import Path


def read_json(path, what: str, error: type[Exception] = ValueError, expect: type | None = dict):
    """The parsed JSON of `path`, a `what` (e.g. "printer profile"); `expect`: the top-level type wanted."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")   # (a byte-order mark, as Windows editors save UTF-8, is dropped)
    except FileNotFoundError:
        raise error(f"{p}: no such {what} file") from None
    except IsADirectoryError:
        raise error(f"{p}: is a folder, not a {what} file") from None
    except UnicodeDecodeError as exc:
        raise error(f"{p}: not a text file ({exc.reason}); a {what} is JSON") from None
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    if expect is not None and not isinstance(data, expect):
        raise error(f"{p}: a {what} must be a JSON {'object' if expect is dict else expect.__name__}, "
                    f"got {type(data).__name__}")
    return data
