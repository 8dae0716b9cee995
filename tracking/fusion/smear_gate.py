"""Which flow frames of a fast pan may go without a marker detection pass (issue 29: CPU per frame).

A pan smears the markers past reading while they stay in view; the detector then reads nothing, frame after
frame, at the cost of a whole-frame pass (as much as the plain OpenCV peer spends on the frame). The rule
here needs no threshold on the smear itself (which depends on the exposure, the markers' cell size and the
direction of motion): once a detection pass has read none of the anchors while the motion model put them in
view, moving `smear_px` or more in the image since the frame before, the frames after it whose motion of the
anchors (predicted, and no more than over the last step) is at least as large (the smear no smaller) and whose view holds no more of them are
read no better, and skip it. A pass still runs on every `max_skip + 1`-th frame whatever the prediction
says (a marker moved in the room, or the exposure changed), and on every frame as the pan slows down.

Only frames the flow carries after a flow frame are gated (`Tracker._flow_again`): a still camera never
records a miss (its anchors do not move `smear_px`), and a frame the flow fails on detects as before.
"""

from __future__ import annotations

import numpy as np

from tracking.anchors.pose import project
from tracking.camera import Camera
from tracking.poses import invert

# the anchors' share of the view may grow this much (fraction of their outline's box inside the image) over
# the frame whose pass read nothing before a pass runs again: more of a board in view may bring readable markers
MORE_IN_VIEW = 0.2
IN_VIEW = 0.5   # least share of the anchors' outline box inside the image for a miss to say anything of the smear


def view_share(camera: Camera, px: np.ndarray) -> float:
    """The share (0..1) of the bounding box of pixels px (N,2) that lies inside the image."""
    lo, hi = px.min(axis=0), px.max(axis=0)
    area = float(np.prod(np.maximum(hi - lo, 1.0)))
    w, h = camera.size
    inside = np.maximum(np.minimum(hi, [w, h]) - np.maximum(lo, 0.0), 0.0)
    return float(np.prod(inside)) / area


class SmearGate:
    """The motion (`unread_px`, pixels a frame) and view share (`unread_share`) of the anchors on the last
    detection pass that read none of them in a fast pan (None: no such miss holds), and the frames skipped
    since the last pass (`skipped`)."""

    def __init__(self, camera: Camera, smear_px: float, max_skip: int = 2):
        self.camera = camera
        self.smear_px = float(smear_px)
        self.max_skip = int(max_skip)
        self.reset()

    def reset(self) -> None:
        """Forget the miss (a lost frame, anchors read)."""
        self.unread_px: float | None = None
        self.unread_share = 0.0
        self.skipped = 0

    def measure(self, outlines: np.ndarray, last: np.ndarray, predicted: np.ndarray,
                step: tuple[np.ndarray, float] | None = None, dt: float = 0.0) -> tuple[float, float]:
        """(how far the anchors move in the image this frame: the most any point of their outlines (N,3 world)
        moves from the pose `last` to `predicted` (world_from_camera), pixels, or, when less, as far as it did
        over the last step (`step` = (the pose before `last`, the seconds to it), scaled to this frame's `dt`
        seconds): a constant-velocity prediction lags behind a pan slowing down, and the markers may be read
        again a frame before it says so; the share of their box in view at `predicted`). (0, 0) when some
        point lies behind the camera."""
        a, za = project(self.camera, invert(last), outlines)
        b, zb = project(self.camera, invert(predicted), outlines)
        if np.any(za <= 0.01) or np.any(zb <= 0.01):
            return 0.0, 0.0
        px = float(np.linalg.norm(b - a, axis=1).max())
        if step is not None and step[1] > 0 and dt > 0:
            c, zc = project(self.camera, invert(step[0]), outlines)
            if np.all(zc > 0.01):
                px = min(px, float(np.linalg.norm(a - c, axis=1).max()) * dt / step[1])
        return px, view_share(self.camera, b)

    def skip(self, motion: tuple[float, float] | None) -> bool:
        """Whether this frame, whose anchors move `motion` = (pixels, view share) (`measure`; None: unknown),
        skips its detection pass (counted)."""
        if motion is None or self.unread_px is None or self.skipped >= self.max_skip:
            return False
        px, share = motion
        if px < self.unread_px or share > self.unread_share + MORE_IN_VIEW:
            return False
        self.skipped += 1
        return True

    def passed(self, read: bool, motion: tuple[float, float] | None) -> None:
        """The anchors were measured this frame: `read` whether any of them were; `motion` how they move
        (`measure`; None: unknown)."""
        self.skipped = 0
        if read or motion is None or motion[0] < self.smear_px or motion[1] < IN_VIEW:
            self.unread_px = None
        else:
            self.unread_px, self.unread_share = motion
