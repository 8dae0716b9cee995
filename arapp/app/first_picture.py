"""Giving up on a source that shows no picture: the time limit, the watch over it and what the user is told.

A camera held by another program, or a driver that hangs, can leave the engine waiting for a first frame
forever while the window says "Opening...". The session starts this watch when it opens a source, stops it
at the first picture, and asks it a few times a second (`Session.tick`) whether the limit has passed.
No Qt; times in seconds on a monotonic clock.
"""

from __future__ import annotations

import time
from typing import Callable

from arapp.engine.sourcespec import is_live_spec

# From opening to the first picture: the process engine's cold start measured 2-2.5 s on a loaded 2-core
# machine (a camera adds its own opening, an OAK device boots in a few seconds), so a source still silent
# after 15 s is not coming; shorter would give up on a slow machine's first start.
FIRST_PICTURE_TIMEOUT_S = 15.0


def no_picture_message(name: str, spec: str, seconds: float) -> tuple[str, str]:
    """(title, one line: what failed and what to do) for a source that gave no picture in `seconds`."""
    if is_live_spec(spec):
        return ("Camera not answering",
                f"No picture from {name} after {seconds:g} s: is another program using the camera? "
                "Close it, or choose another source (File > Open source).")
    return ("Source not answering",
            f"No picture from {name} after {seconds:g} s: open it again, or choose another source "
            "(File > Open source).")


class FirstPictureWatch:
    """A deadline for a source's first picture. `timeout_s` may be changed (tests use a short one);
    `clock()` gives the time in seconds."""

    def __init__(self, timeout_s: float = FIRST_PICTURE_TIMEOUT_S, clock: Callable[[], float] = time.monotonic):
        self.timeout_s = float(timeout_s)
        self.clock = clock
        self.deadline: float | None = None

    @property
    def waiting(self) -> bool:
        return self.deadline is not None

    def start(self) -> None:
        """A source is opening: the limit counts from now."""
        self.deadline = self.clock() + self.timeout_s

    def stop(self) -> None:
        """The first picture came, or the source was closed."""
        self.deadline = None

    def expired(self) -> bool:
        """Whether the limit passed with no picture (stays True until stop or start)."""
        return self.deadline is not None and self.clock() >= self.deadline
