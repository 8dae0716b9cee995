"""The live engine's anchor discovery stage: what the picture shows when the configured anchors give no pose.

While the tracker has reported no anchor pose for `after_s` seconds, the processing thread hands the newest
frame (a reference, no copy) to this stage's own thread at most `rate_hz` times a second; that thread runs
tracking.anchors.discover.Discovery.feed on it (a couple of dictionary-family passes per frame, round-robin)
and publishes what it found as a plain dict (`offer_dict`) into the engine's per-frame state
(`LiveEngine.state["discovery"]`), which reaches the app model with every frame in both engine hosts (the
thread engine and the child process). The stage stops for good once the anchors give a pose or the offer
is answered (commands.EndDiscovery). A recording that ends before discovery looked at anything (a clip
shorter than `after_s`, a few photos) and never gave a pose has its last frame looked at with every pass
(`at_end`), so the user learns why, as `arapp replay` says it. No Qt.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

import cv2

from arapp.engine.slots import LatestSlot
from tracking.anchors.diagnose import why_line
from tracking.anchors.discover import DEFAULT_MARKER_M, Discovery, Suggestion

LOST_BEFORE_S = 1.0   # no pose this long (wall-clock seconds) before discovery starts looking
RATE_HZ = 4.0         # frames looked at per second at most (each: 2 of the 21 dictionary/polarity passes)


def offer_dict(s: Suggestion | None, why: str) -> dict:
    """What crosses to the app model (plain data, picklable): the top suggestion's `summary`, `block`
    (anchor JSON, metres, marker size DEFAULT_MARKER_M), `size_field` and `size_mm` (the size assumed),
    and `why` (diagnose.why_line: why the configured anchors gave nothing). `summary` None: nothing found yet."""
    if s is None:
        return {"summary": None, "block": None, "size_field": None, "size_mm": None, "why": why}
    size_m = float(s.block.get(s.size_field, DEFAULT_MARKER_M))
    return {"summary": s.summary, "block": dict(s.block), "size_field": s.size_field,
            "size_mm": round(size_m * 1000.0, 3), "why": why}


class DiscoveryStage:
    """Feeds `Discovery` from processed frames while the anchors give no pose (see module doc).

    anchors: the AnchorSpecs tracked (worded in the why line); publish(dict): called from the stage's
    thread with each new finding (offer_dict); default_anchors: the anchors are the app's default (the why
    line says so); offer: False for a source that names its own anchors (a recording's session.json, which
    wins over any other), where only the why is published; clock: wall-clock seconds (tests pass a fake one)."""

    def __init__(self, anchors: list, publish: Callable[[dict], None], *, default_anchors: bool = False,
                 offer: bool = True,
                 after_s: float | None = None, rate_hz: float | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.anchors = list(anchors)
        self.publish = publish
        self.default_anchors = default_anchors
        self.offer = offer
        # the module's values when not given, read now (tests shorten them)
        self.after_s = float(LOST_BEFORE_S if after_s is None else after_s)
        self.rate_hz = float(RATE_HZ if rate_hz is None else rate_hz)
        self.clock = clock
        self.discovery = Discovery(rate_hz=self.rate_hz)
        self._inbox = LatestSlot()
        self._lost_since: float | None = None
        self._last_fed: float | None = None
        self._last: tuple | None = None
        self.done = threading.Event()
        self.fed = 0
        self._newest = None   # the last frame observed without a pose (a reference), for `at_end`
        self._thread: threading.Thread | None = None

    # -- processing thread -------------------------------------------------------------------------
    def observe(self, image, world_from_camera) -> None:
        """One processed frame (BGR or gray `image`, the pose found or None). Cheap: at most a slot put."""
        if self.done.is_set():
            return
        if world_from_camera is not None:
            self.finish()   # the anchors are in view: nothing to discover
            return
        self._newest = image
        now = self.clock()
        if self._lost_since is None:
            self._lost_since = now
        if now - self._lost_since < self.after_s:
            return
        if self._last_fed is not None and now - self._last_fed < 1.0 / self.rate_hz:
            return
        self._last_fed = now
        self._hand_over(image, now, every_pass=False)

    def at_end(self) -> None:
        """The recording reached its end (capture thread): if nothing was looked at yet and no pose was found,
        look at the last frame observed with every pass (`Discovery.look_all`)."""
        if self.done.is_set() or self._newest is None or self._last_fed is not None:
            return
        self._last_fed = self.clock()
        self._hand_over(self._newest, self._last_fed, every_pass=True)

    def _hand_over(self, image, now: float, every_pass: bool) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="arapp-discovery", daemon=True)
            self._thread.start()
        self._inbox.put((image, now, every_pass))

    def finish(self) -> None:
        """Stop looking for good (anchors tracked, offer answered, engine stopping)."""
        self.done.set()
        self._inbox.wake()

    @property
    def stopped(self) -> bool:
        """Whether the stage looks at no frame now or later: finished and its thread ended (a look under way
        when `finish` came runs to its end first), or never started."""
        return self.done.is_set() and (self._thread is None or not self._thread.is_alive())

    # -- the stage's thread ------------------------------------------------------------------------
    def _run(self) -> None:
        while not self.done.is_set():
            got = self._inbox.take(timeout=0.5)
            if got is None or self.done.is_set():
                continue
            image, t, every_pass = got
            try:
                self.look(image, t, every_pass)
            except cv2.error:
                self.finish()   # a frame OpenCV cannot read: no offer, and the view goes on as it was

    def look(self, image, t: float, every_pass: bool = False) -> None:
        """Feed one frame to Discovery (`every_pass`: all its passes at once, else its rate and round-robin)
        and publish when the finding changed (the stage's thread; tests call it directly)."""
        gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if every_pass:
            self.discovery.look_all(gray)
        elif not self.discovery.feed(gray, t):
            return
        self.fed += 1
        found = self.discovery.suggestions() if self.offer else []
        top = found[0] if found else None
        if top is None and self.discovery.rounds < 1.0 and not self.discovery.markers_seen:
            return   # nothing yet, and not every dictionary looked at: no why to tell
        why = why_line(self.anchors, self.discovery, self.default_anchors)
        key = (None if top is None else (top.summary, tuple(sorted(top.block.items(), key=str))), why)
        if key != self._last:
            self._last = key
            self.publish(offer_dict(top, why))
