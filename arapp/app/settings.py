"""Where the app model keeps its settings: QSettings in the GUI, `MemorySettings` headless. No Qt."""

from __future__ import annotations


class MemorySettings:
    """Settings kept in a dict, with the two methods of QSettings the app model uses."""

    def __init__(self, values: dict | None = None):
        self.values = dict(values or {})

    def value(self, key: str, default=None, type=None):  # noqa: A002 - QSettings' name
        return self.values.get(key, default)

    def setValue(self, key: str, value) -> None:  # noqa: N802 - QSettings' name
        self.values[key] = value


def as_bool(value) -> bool:
    """A stored flag: QSettings' ini files give "true"/"false" strings."""
    return value if isinstance(value, bool) else str(value).strip().lower() in ("true", "1", "yes")
