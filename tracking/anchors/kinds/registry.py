"""The table of anchor kinds: name -> `AnchorKind` (tracking/anchors/kinds/base.py).

The built-in kinds are registered by tracking/anchors/kinds/__init__.py; a new kind is one
module plus one `register(...)` call there (or anywhere before its session is read).
"""

from __future__ import annotations

from tracking.errors import SessionError

KINDS: dict = {}


def register(kind):
    """Add an `AnchorKind` instance to the table under `kind.name`; returns it. Registering the same class
    again replaces it; another class under a taken name is refused (two kinds cannot share a name)."""
    if not getattr(kind, "name", ""):
        raise ValueError(f"{kind!r}: an anchor kind needs a name")
    old = KINDS.get(kind.name)
    if old is not None and type(old) is not type(kind):
        raise ValueError(f"anchor kind {kind.name!r} is already registered by {type(old).__qualname__}; "
                         f"choose another name")
    KINDS[kind.name] = kind
    return kind


def kind_names() -> tuple[str, ...]:
    """The registered kind names, in registration order."""
    return tuple(KINDS)


def kind_named(name: str, where: str = "kind"):
    """The `AnchorKind` registered as `name`; SessionError naming `where` when there is none."""
    kind = KINDS.get(name)
    if kind is None:
        raise SessionError(f"{where}: must be one of {', '.join(KINDS)}, got {name!r}")
    return kind
