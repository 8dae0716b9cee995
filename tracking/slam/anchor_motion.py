"""Whether the anchors move in the room: a board or marker card held up to a still webcam, or waved before a
moving camera.

The keypoint map and the flow assume that what surrounds the anchors is rigid with them (a desk, a wall, a
printer bed). A card held in the hand breaks that: the room's map then carries the pose of the camera in
the *room*, and a model drawn from it stays where the card was. Two tests tell the cases apart:

- `disagrees`: the anchors' measured pose and the pose the map's points *off the anchors* give (fitted from
  the anchors' pose) are further apart than both are expected to err (`position_spread` of each fit,
  three sigma, and a floor for what neither spread holds: a young map's scale, a print's errors);
- `background_rigid`: the same without a map (a still camera triangulates nothing): ORB features off the
  anchors matched between two frames, each tested against the epipolar segment the anchors' two poses give
  it for indoor depths;
- `on_anchor`: which world points lie on the anchors' own card (their plane, within their outlines): only
  those move with the anchors, so only those may carry the pose once the anchors are seen to move.

World frame: the first anchor's (metres); the anchors' paper plane is world z = 0.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.camera import Camera

# metres: the least gap between the anchors' and the background map's camera positions that counts as the
# anchors having moved (a young map on the tuning recordings agrees with the anchors to a few mm)
MOVED_FLOOR_M = 0.015
# the gap must exceed this many times the two positions' summed expected errors (their spreads)
MOVED_SIGMAS = 3.0
# metres a point may lie off the anchors' plane and still count as on the card (plane seeds lie on it)
ON_PLANE_M = 0.004


def disagrees(anchor_pose: np.ndarray, map_pose: np.ndarray, anchor_spread: float, map_spread: float) -> bool:
    """Whether two world_from_camera poses of one frame, the anchors' and the background map's, hold camera
    positions further apart than `MOVED_SIGMAS` times their summed spreads (metres) and `MOVED_FLOOR_M`."""
    gap = float(np.linalg.norm(np.asarray(anchor_pose)[:3, 3] - np.asarray(map_pose)[:3, 3]))
    spread = anchor_spread + map_spread
    if not np.isfinite(spread):
        return False   # one of the fits holds the position nowhere: no verdict
    return gap > max(MOVED_FLOOR_M, MOVED_SIGMAS * spread)


def on_anchor(X: np.ndarray, outlines: list[np.ndarray], inset: float = 0.0) -> np.ndarray:
    """(N,) bool: which world points X (N,3) lie on the anchors' plane (within `ON_PLANE_M`) inside the
    bounding rectangle (world x, y) of one of the anchors' outlines (each (M,3) world corners), shrunk by
    `inset` metres."""
    X = np.asarray(X, float).reshape(-1, 3)
    ok = np.zeros(len(X), bool)
    flat = np.abs(X[:, 2]) <= ON_PLANE_M
    for o in outlines:
        lo, hi = o[:, :2].min(axis=0) + inset, o[:, :2].max(axis=0) - inset
        ok |= flat & np.all((X[:, :2] >= lo) & (X[:, :2] <= hi), axis=1)
    return ok


def outline_region(camera: Camera, world_from_camera: np.ndarray, outlines: list[np.ndarray]) -> np.ndarray | None:
    """The convex hull (M,2 distorted pixels) of the anchors' outlines as seen from `world_from_camera`, or
    None when part of them is behind the camera."""
    pts = np.concatenate([np.asarray(o, float).reshape(-1, 3) for o in outlines])
    Xc = (pts - world_from_camera[:3, 3]) @ world_from_camera[:3, :3]
    if np.any(Xc[:, 2] <= 0.01):
        return None
    px = camera.project_world(pts, world_from_camera)
    return cv2.convexHull(px.astype(np.float32)).reshape(-1, 2)


# the background's two-view test (`background_rigid`): inverse depths (1/m) a background point rigid with the
# anchors may have, from 5 m (a room's far wall) to 5 cm
INV_DEPTHS = np.linspace(1 / 5.0, 20.0, 200)
RIGID_PX = 3.0          # pixels: a background match further than this from every such depth's image is not rigid
MIN_BACKGROUND = 20     # background matches a verdict needs
RATIO = 0.8             # Lowe's ratio test on ORB distances
STILL_PX = 1.0          # pixels: a background match that moved less than this between two frames stands still


def _inside(px: np.ndarray, region: np.ndarray | None, grow: float) -> np.ndarray:
    """(N,) bool: pixels px (N,2) inside (or within `grow` px of) the polygon `region` (M,2): what
    cv2.pointPolygonTest(region, p, True) > -grow says of each, for all points at once (one call a point
    took 2 ms a frame's features)."""
    if region is None or len(px) == 0:
        return np.zeros(len(px), bool)
    poly = np.asarray(region, np.float32).reshape(-1, 2).astype(float)
    p = np.asarray(px, float).reshape(-1, 1, 2)
    a, b = poly, np.roll(poly, -1, axis=0)                      # the edges a -> b
    ab = b - a
    t = np.clip(((p - a) * ab).sum(2) / np.maximum((ab * ab).sum(1), 1e-12), 0.0, 1.0)
    near = np.sqrt((((a + t[..., None] * ab) - p) ** 2).sum(2)).min(axis=1) < grow
    # even-odd crossings of a ray to +x: inside a polygon of any shape
    y, x = p[..., 1], p[..., 0]
    straddle = (a[:, 1] > y) != (b[:, 1] > y)
    x_cross = a[:, 0] + (y - a[:, 1]) * ab[:, 0] / np.where(ab[:, 1] == 0, 1.0, ab[:, 1])
    inside = (straddle & (x < x_cross)).sum(axis=1) % 2 == 1
    return inside | near


def _background_matches(before: tuple, now: tuple, grow_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i1, i2) of the ORB features of two frames outside the anchors' outlines (grown by `grow_px`)
    matched by Lowe's ratio test (none when either frame has under MIN_BACKGROUND such features); `before`,
    `now`: (Features, world_from_camera, outline region) as `background_rigid` takes them."""
    (f1, _, r1), (f2, _, r2) = before, now
    a = np.nonzero(~_inside(f1.xy, r1, grow_px))[0]
    b = np.nonzero(~_inside(f2.xy, r2, grow_px))[0]
    if len(a) < MIN_BACKGROUND or len(b) < MIN_BACKGROUND:
        return np.zeros(0, int), np.zeros(0, int)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    knn = matcher.knnMatch(f1.desc[a], f2.desc[b], k=2)
    pairs = [(m[0].queryIdx, m[0].trainIdx) for m in knn
             if len(m) == 2 and m[0].distance < RATIO * m[1].distance and m[0].distance < 64]
    if not pairs:
        return np.zeros(0, int), np.zeros(0, int)
    return a[[q for q, _ in pairs]], b[[t for _, t in pairs]]


def background_shift(before: tuple, now: tuple, grow_px: float = 12.0) -> tuple[int, float, float]:
    """How far the background moves in the image between two frames, in pixels, without any pose:
    (background matches as `background_rigid` makes them, their median displacement (distorted pixels),
    the fraction of them that moved less than `STILL_PX`). A still camera sees its background stand still
    to a fraction of a pixel (ORB's own noise), whatever a card held before it does."""
    i1, i2 = _background_matches(before, now, grow_px)
    if len(i1) < MIN_BACKGROUND:
        return len(i1), float("nan"), 0.0
    d = np.linalg.norm(now[0].xy[i2] - before[0].xy[i1], axis=1)
    return len(i1), float(np.median(d)), float(np.mean(d < STILL_PX))


def background_rigid(K: np.ndarray, before: tuple, now: tuple, grow_px: float = 12.0) -> tuple[int, float]:
    """Whether the background moves with the anchors between two frames: (background matches, the fraction
    of them that no depth from 5 cm to 5 m explains). `before`, `now`: (Features, world_from_camera as the
    anchors measured it, the anchors' outline in the image as `outline_region` gives it, or None). ORB
    features of the two frames outside the outlines (by `grow_px`) are matched (mutual ratio test); a point
    rigid with the anchors, seen at undistorted pixel x1 before, lies now on the image of its ray at some
    depth (the epipolar segment). A still camera before a moving card sees its background stand still while
    the anchors' poses say the camera moved: no indoor depth explains that, nor a room that moves other than
    the anchors do (a camera and a card both moving)."""
    (f1, p1, _), (f2, p2, _) = before, now
    i1, i2 = _background_matches(before, now, grow_px)
    if len(i1) < MIN_BACKGROUND:
        return len(i1), 0.0
    T = np.linalg.inv(np.asarray(p2, float)) @ np.asarray(p1, float)   # cam2_from_cam1
    R, t = T[:3, :3], T[:3, 3]
    Kinv = np.linalg.inv(K)
    rays = np.c_[f1.und[i1], np.ones(len(i1))] @ Kinv.T            # (N,3), depth 1 in cam 1
    rot = rays @ R.T                                               # R r1 (N,3)
    # X2(rho) = R r1 + rho t (up to scale 1/rho): its image for every inverse depth
    X2 = rot[:, None, :] + INV_DEPTHS[None, :, None] * t[None, None, :]
    z = X2[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 0] * X2[..., 0] / z + K[0, 2]
        v = K[1, 1] * X2[..., 1] / z + K[1, 2]
    d = np.hypot(u - f2.und[i2, 0:1], v - f2.und[i2, 1:2])
    d = np.where(z > 0, d, np.inf)
    miss = np.nanmin(d, axis=1) > RIGID_PX
    return len(i1), float(miss.mean())
