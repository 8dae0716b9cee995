"""Rolling-shutter deskew of one anchor's detected points (the anchor tracker's `_deskew` step).

Row y of a rolling-shutter frame is read `camera.row_offsets(y)` seconds after the frame time; a point moving
across the image at u' pixels/s was seen `u' d` from where the centre row would have seen it. u' comes from the
point's own detections in this frame and the last, fitted as an affine field over the anchor's points.
"""

from __future__ import annotations

import numpy as np

from tracking.anchors.detect import Observation
from tracking.camera import Camera


def deskew_observation(camera: Camera, ob: Observation, keys: list, prev: dict, dt: float,
                       before: tuple | None, extrapolate_min: int) -> tuple[Observation, tuple | None]:
    """`ob` with its image points (px) moved to the frame's centre-row time, and its velocity field
    `(A (3,2) affine px/s, dt)` to remember; `ob` unchanged and None when fewer than 3 of its points (`keys`)
    were seen in the last frame (`prev`: key -> px, `dt` seconds ago). `before`: the anchor's field of the last
    frame; with it and at least `extrapolate_min` points, the change between the two fields carries the
    velocity on to the middle of the stretch each point is moved over."""
    seen = np.array([k in prev for k in keys])
    if seen.sum() < 3:
        return ob, None
    img = np.asarray(ob.img, float)
    vel = (img[seen] - np.array([prev[k] for k, s in zip(keys, seen) if s])) / dt
    X = np.column_stack([img[seen], np.ones(int(seen.sum()))])
    A, *_ = np.linalg.lstsq(X, vel, rcond=None)
    img1 = np.column_stack([img, np.ones(len(img))])
    vel_all = img1 @ A
    d = camera.row_offsets(img[:, 1])
    if before is not None and seen.sum() >= extrapolate_min:
        # the difference is the velocity at t - dt/2 + d (both detections were read at the point's
        # row, d after their frame time); the stretch the point is moved back over, from t + d to
        # t, needs it at its middle, t + d/2: (dt - d)/2 later. The change from the last frame's
        # difference, (dt + dt_before)/2 earlier, carries it on there.
        vel_before = img1 @ before[0]
        vel_all = vel_all + ((dt - d) / (dt + before[1]))[:, None] * (vel_all - vel_before)
    moved = Observation(ob.anchor, ob.obj, img - vel_all * d[:, None], ob.groups, ob.markers, square=ob.square)
    return moved, (A, dt)
