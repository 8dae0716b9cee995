"""Keypoints followed from frame to frame by pyramidal Lucas-Kanade optical flow, and the pose they give.

Flow holds where descriptors do not. On a motion-blurred frame FAST finds few
corners and the ORB descriptor of a smeared patch matches nothing of the sharp
keyframes, but consecutive frames are blurred almost alike, so a patch followed
from one frame to the next still lands on the same surface point. Each followed
point keeps the world point it images, and the pose is a robust fit to them.

Where the followed points come from:
- map points matched in the last full frame (triangulated, bundle-adjusted);
- points seeded in the last tracked image and placed where their ray meets the
  anchors' plane (world z = 0): the markers lie on a table, a wall or a printer
  bed, and what surrounds them mostly lies in that plane too. This is what
  carries the pose when the map has no points yet (a camera that only turns
  triangulates nothing). Seeds off the plane disagree with the others as soon
  as the camera moves sideways and are dropped by the robust fit.

Seeds are Shi-Tomasi corners found on the half-resolution image (a quarter of
the full image's cost; where exactly a seed sits does not matter, the flow
follows the patch around it and the plane gives its world point). Plane seeds
stay marked (`Tracks.planar`): followed into a frame whose pose the anchors
measured, they can be placed on the plane again from that pose (`relift`)
instead of being seeded afresh.

Rolling shutter: a camera that reads its rows out over `camera.readout` seconds
sees each point at its row's time, not the frame's (the centre row's). In a fast
pan that shears the image by pixels, which a pose fit reads as tilt and shift,
and which, lifted onto the plane, moves the seeds themselves. Each followed
point's own image velocity (its motion since the last frame) moves it to the
centre row's time before it is fitted or placed on the plane (`deskew`); new
seeds, which have no motion yet, take it from the points around them or, with
none, from the motion model's next pose.

Pixels: `xy` are distorted image pixels (what the flow measures); the pose fit
works on undistorted pixels. World points in metres, poses `world_from_camera`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.slam.frame_pose import pnp_ransac, refine_pose

WINDOW = (19, 19)       # pixels: big enough to hold a smeared corner (21 cost a fifth more, same accuracy)
LEVELS = 3              # pyramid levels above the image: with a predicted start, 30+ px/frame is fine
MAX_PATCH_ERROR = 30.0  # mean absolute grey difference of a followed patch; above it the point was lost
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03)
HALF_RES_FROM = 320     # pixels of image width from which seeds are found on the half-resolution image
SEED_QUALITY = 0.01     # Shi-Tomasi quality level of a seed, relative to the image's strongest corner


@dataclass
class Tracks:
    """Points followed by flow. `image` the grey frame they were measured in; `xy` their distorted
    pixels there (N,2) float32; `X` the world points they image (N,3) metres; `moved` how far each
    moved from the frame before, pixels (N,2), when they were followed into this one; `planar` (N,) bool,
    which of them were placed on the anchors' plane from a pose (seeds; the others are map points), None
    for none; `velocity` (N,2) their measured image velocity in pixels/s as used to move them to the centre
    row's time (see `deskew`), None when not measured (fresh seeds placed with the motion model's guess,
    no rolling shutter); `path_velocity` (N,2) pixels/s, their displacement over
    the last frame interval divided by it (NaN rows where not followed), None when not known."""

    image: np.ndarray
    xy: np.ndarray
    X: np.ndarray
    moved: np.ndarray | None = None
    planar: np.ndarray | None = None
    velocity: np.ndarray | None = None
    path_velocity: np.ndarray | None = None

    def planar_mask(self) -> np.ndarray:
        """`planar` as a bool array (N,) (all False when None)."""
        return np.zeros(len(self), bool) if self.planar is None else np.asarray(self.planar, bool)

    def image_motion(self) -> np.ndarray | None:
        """The median motion (2,) of the points from the frame before, pixels; None if not followed."""
        return None if self.moved is None or len(self.moved) == 0 else np.median(self.moved, axis=0)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def subset(self, keep: np.ndarray) -> Tracks:
        """These tracks, only the rows `keep` (N,) bool."""
        pick = lambda a: None if a is None else a[keep]  # noqa: E731
        return Tracks(self.image, np.ascontiguousarray(self.xy[keep]), self.X[keep], pick(self.moved),
                      pick(self.planar), pick(self.velocity), pick(self.path_velocity))


def deskew(camera: Camera, xy: np.ndarray, velocity: np.ndarray | None) -> np.ndarray:
    """Distorted pixels xy (N,2) moved to where they would be at the frame's centre-row time, given
    their image velocity (N,2) pixels/s (first order); xy as they are without a rolling shutter or a
    velocity."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    if camera.readout <= 0 or velocity is None:
        return xy
    return xy - np.asarray(velocity, float).reshape(-1, 2) * camera.row_offsets(xy[:, 1])[:, None]


MIN_FIELD_POINTS = 24   # points a quadratic image-velocity field (6 coefficients a component) is fitted to


def _quadratic_basis(xy: np.ndarray, centre: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The terms (N,6) 1, x, y, x^2, xy, y^2 of pixels xy (N,2) taken about `centre` in units of `scale`
    pixels, and their derivatives (N,6) by x and by y, per pixel."""
    x, y = ((np.asarray(xy, float).reshape(-1, 2) - centre) / scale).T
    zero, one = np.zeros_like(x), np.ones_like(x)
    return (np.column_stack((one, x, y, x * x, x * y, y * y)),
            np.column_stack((zero, one, zero, 2 * x, y, zero)) / scale,
            np.column_stack((zero, zero, one, zero, x, 2 * y)) / scale)


def velocity_field(xy: np.ndarray, velocity: np.ndarray, at: np.ndarray,
                   min_points: int = MIN_FIELD_POINTS) -> np.ndarray | None:
    """The image velocity (M,2) pixels/s at pixels `at` (M,2), from a quadratic field (what a camera
    turning and moving over a plane gives, to first order) fitted to the velocities (N,2) of points at
    xy (N,2); None with fewer than `min_points` points."""
    if len(xy) < min_points:
        return None
    xy = np.asarray(xy, float).reshape(-1, 2)
    centre, scale = xy.mean(axis=0), float(max(xy.std(), 1.0))
    coef, *_ = np.linalg.lstsq(_quadratic_basis(xy, centre, scale)[0], velocity, rcond=None)
    return _quadratic_basis(at, centre, scale)[0] @ coef


def _row_time_velocity(camera: Camera, before: np.ndarray, now: np.ndarray, ok: np.ndarray, dt: float,
                       before_velocity: np.ndarray | None = None) -> np.ndarray:
    """Image velocities (N,2) pixels/s of points followed from `before` to `now` (N,2 pixels, dt seconds
    apart), as they are over the stretch that moves each to the centre row's time. The displacement over
    dt is the velocity about halfway along the path; a pan's image velocity changes across the image
    (quadratically: faster towards the edges), so it is carried from there to the middle of the stretch
    the deskew covers by the gradient of a quadratic field (a camera moving over a plane gives one)
    fitted to the followed points (`ok`). Points that were followed into `before` too (their path
    velocity then, `before_velocity` (N,2), finite) are carried on by their own change of velocity
    instead, which holds the field's change across the image and in time alike (a pan turning round)."""
    v = (now - before) / dt
    if ok.sum() < MIN_FIELD_POINTS:
        return v
    centre, scale = camera.K[:2, 2], float(camera.K[0, 0])
    coef, *_ = np.linalg.lstsq(_quadratic_basis((now[ok] + before[ok]) / 2, centre, scale)[0], v[ok], rcond=None)
    _, dx, dy = _quadratic_basis(now, centre, scale)
    shift = v * ((dt - camera.row_offsets(now[:, 1])) / 2)[:, None]   # from halfway along the path
    out = v + shift[:, :1] * (dx @ coef) + shift[:, 1:] * (dy @ coef)
    if before_velocity is not None:
        # the two path velocities are dt apart (the frame interval taken as steady); from the last one's
        # time (halfway along the path, t - dt/2 + d) to the middle of the deskew stretch (t + d/2) is
        # (dt - d) / 2
        had = np.isfinite(before_velocity).all(axis=1)
        d = camera.row_offsets(now[had, 1])
        out[had] = v[had] + (v[had] - before_velocity[had]) * ((dt - d) / (2 * dt))[:, None]
    return out


def lift_to_plane(camera: Camera, world_from_camera: np.ndarray, xy: np.ndarray,
                  max_depth_ratio: float = 6.0, min_grazing_deg: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """World points (N,3) where the rays through distorted pixels xy (N,2) meet the plane z = 0, and a
    mask (N,) of those that are usable: in front of the camera, not at a grazing angle, and no deeper
    than `max_depth_ratio` times the camera's height above the plane."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    if xy.shape[0] == 0:
        return np.zeros((0, 3)), np.zeros(0, bool)
    und = camera.undistort_points(xy) if camera.has_distortion else xy
    K = camera.K
    rays = np.c_[(und[:, 0] - K[0, 2]) / K[0, 0], (und[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(und))]
    d = rays @ world_from_camera[:3, :3].T          # world directions, camera depth 1
    c = world_from_camera[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -c[2] / d[:, 2]                      # camera depth of the intersection
    X = c + depth[:, None] * d
    height = abs(float(c[2]))
    sin_graze = np.abs(d[:, 2]) / np.linalg.norm(d, axis=1)
    ok = (np.isfinite(depth) & (depth > 0.02) & (depth < max_depth_ratio * max(height, 0.05))
          & (sin_graze > np.sin(np.radians(min_grazing_deg))))
    return X, ok


def _corners(gray: np.ndarray, n: int, min_distance: int, taken: np.ndarray,
             region: np.ndarray | None = None) -> np.ndarray:
    """Up to n Shi-Tomasi corners (N,2) float32 full-resolution pixels of `gray`, at least about
    min_distance pixels from each other and from the pixels `taken` (M,2), and inside the polygon `region`
    (M,2 pixels) when given; on the half-resolution image when the image is wide enough (a quarter of the
    cost: the corner measure is the whole cost)."""
    half = gray.shape[1] >= HALF_RES_FROM
    img = cv2.pyrDown(gray) if half else gray
    scale = 2.0 if half else 1.0
    radius = max(1, int(round(min_distance / scale)))
    mask = np.zeros(img.shape[:2], np.uint8)
    if len(taken):
        # the taken pixels widened to discs by one dilation (no drawing loop over the points)
        ij = np.rint(np.asarray(taken, float) / scale).astype(int)
        ij = ij[(ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < img.shape[1]) & (ij[:, 1] < img.shape[0])]
        mask[ij[:, 1], ij[:, 0]] = 255
        mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1)))
    allowed = 255 - mask
    if region is not None:
        inside = np.zeros(img.shape[:2], np.uint8)
        poly = np.asarray(region, float).reshape(-1, 2) / scale
        if np.all(np.isfinite(poly)):
            cv2.fillConvexPoly(inside, np.rint(poly).astype(np.int32), 255)
        allowed &= inside
        if not allowed.any():
            return np.zeros((0, 2), np.float32)
    got = cv2.goodFeaturesToTrack(img, n, SEED_QUALITY, min_distance / scale, mask=allowed,
                                  blockSize=3 if half else 5)
    # pyrDown keeps the even rows and columns: half-resolution pixel (x, y) is full pixel (2x, 2y)
    return np.zeros((0, 2), np.float32) if got is None else (scale * got.reshape(-1, 2)).astype(np.float32)


def _seed_velocity(camera: Camera, new: np.ndarray, keep: Tracks | None, world_from_camera: np.ndarray,
                   later: tuple[np.ndarray, float] | None) -> np.ndarray | None:
    """Image velocities (N,2) pixels/s for new seeds at distorted pixels `new`: the field of the kept
    points' measured velocities, else the motion `later` = (world_from_camera dt seconds on, dt)
    predicts for their plane points; None when neither is known."""
    if keep is not None and keep.velocity is not None:
        v = velocity_field(keep.xy, keep.velocity, new)
        if v is not None:
            return v
    if later is None or later[0] is None or not later[1] > 0:
        return None
    X, _ = lift_to_plane(camera, world_from_camera, new)
    return (camera.project_world(X, later[0]) - camera.project_world(X, world_from_camera)) / later[1]


def seed_on_plane(camera: Camera, gray: np.ndarray, world_from_camera: np.ndarray, n: int = 300,
                  keep: Tracks | None = None, min_distance: int = 10,
                  later: tuple[np.ndarray, float] | None = None, region: np.ndarray | None = None) -> Tracks:
    """Tracks for the grey image `gray` taken at `world_from_camera`: the points of `keep` (if any,
    measured in this same image) plus up to n - len(keep) new corners (Shi-Tomasi), away from those,
    placed on the anchors' plane (marked `planar`). With a rolling shutter the new corners are moved to
    the centre row's time first (see `_seed_velocity`; `later` = (the pose dt seconds on, dt)); a velocity
    only guessed from `later` is not kept (`follow` places such seeds again once it is measured). `region`
    (M,2 distorted pixels): new corners only inside this convex polygon (e.g. the anchors' outline)."""
    xy = np.zeros((0, 2), np.float32) if keep is None else keep.xy
    X = np.zeros((0, 3)) if keep is None else keep.X
    planar = np.zeros(0, bool) if keep is None else keep.planar_mask()
    velocity = None if keep is None else keep.velocity
    path_velocity = None if keep is None else keep.path_velocity
    want = n - xy.shape[0]
    if want > 0:
        new = _corners(gray, want, min_distance, xy, region)
        if len(new):
            v = _seed_velocity(camera, new, keep, world_from_camera, later) if camera.readout > 0 else None
            Xn, ok = lift_to_plane(camera, world_from_camera, deskew(camera, new, v))
            if velocity is not None:
                vn = np.zeros((len(new), 2)) if v is None else v
                velocity = np.vstack([velocity, vn[ok]])
            if path_velocity is not None:
                path_velocity = np.vstack([path_velocity, np.full((int(ok.sum()), 2), np.nan)])
            xy = np.vstack([xy, new[ok]])
            X = np.vstack([X, Xn[ok]])
            planar = np.concatenate([planar, np.ones(int(ok.sum()), bool)])
    return Tracks(gray, np.ascontiguousarray(xy, np.float32), X, planar=planar, velocity=velocity,
                  path_velocity=path_velocity)


def relift(camera: Camera, tracks: Tracks, world_from_camera: np.ndarray) -> Tracks:
    """`tracks` with their plane seeds placed on the anchors' plane again from `world_from_camera` (the pose
    of the image they were measured in, e.g. the anchors' measurement there): as if seeded in that image,
    without looking for corners again. Seeds no longer usable from there are dropped; map points stay."""
    planar = tracks.planar_mask()
    if not planar.any():
        return tracks
    X = tracks.X.copy()
    v = None if tracks.velocity is None else tracks.velocity[planar]
    Xn, ok = lift_to_plane(camera, world_from_camera, deskew(camera, tracks.xy[planar], v))
    X[planar] = Xn
    keep = ~planar
    keep[planar] = ok
    return Tracks(tracks.image, np.ascontiguousarray(tracks.xy[keep]), X[keep],
                  None if tracks.moved is None else tracks.moved[keep], planar[keep],
                  None if tracks.velocity is None else tracks.velocity[keep],
                  None if tracks.path_velocity is None else tracks.path_velocity[keep])


def _relift_first_followed(camera: Camera, tracks: Tracks, lifted_from: np.ndarray, path_velocity: np.ndarray,
                           ok: np.ndarray) -> np.ndarray:
    """World points (N,3) of `tracks`; when their image velocity was never measured (fresh seeds, placed
    on the plane with the motion model's guess of it), those of the plane seeds now followed (`ok`) are
    placed again from `lifted_from`, moved to the centre row's time by the path velocity (N,2) pixels/s
    now measured."""
    first = tracks.planar_mask() & ok
    if tracks.velocity is not None or not first.any():
        return tracks.X
    Xn, good = lift_to_plane(camera, lifted_from, deskew(camera, tracks.xy[first], path_velocity[first]))
    X = tracks.X.copy()
    rows = np.nonzero(first)[0][good]
    X[rows] = Xn[good]
    return X


def _step_velocity(camera: Camera, tracks: Tracks, lifted_from: np.ndarray,
                   before: tuple[np.ndarray, float] | None, after: np.ndarray, dt: float) -> np.ndarray | None:
    """Path velocities (N,2) pixels/s of `tracks` over the frame interval that ended in `tracks.image`, as
    a followed point's displacement over it gives them: the velocity halfway along that path at the
    point's row offset d (t - dt_before/2 + d). Their own (`path_velocity`) where they were followed
    into that image; for the others (seeds placed in it) from the motion of their world points between
    the poses `before` = (world_from_camera, dt_before seconds before `lifted_from`) and `lifted_from`,
    which is the velocity at t - dt_before/2, carried the d on toward `after` (N,2), their path velocity
    over the next interval of dt seconds (halfway along it, d + dt/2 after t): the two are a straight
    line in time. None when neither is known."""
    own = tracks.path_velocity
    if before is None or not before[1] > 0:
        return own
    need = np.ones(len(tracks), bool) if own is None else ~np.isfinite(own).all(axis=1)
    if not need.any():
        return own
    out = np.full((len(tracks), 2), np.nan) if own is None else own.copy()
    X = tracks.X[need]
    dtb = before[1]
    v = (camera.project_world(X, lifted_from) - camera.project_world(X, before[0])) / dtb
    d = camera.row_offsets(tracks.xy[need, 1])[:, None]
    # on the line through (t - dtb/2, v) and (t + dt/2 + d, after), at t - dtb/2 + d
    out[need] = v + (after[need] - v) * d / ((dtb + dt) / 2 + d)
    return out


def _seed_velocity_then(camera: Camera, xy: np.ndarray, after: np.ndarray, dt: float,
                        before_velocity: np.ndarray | None, dt_before: float) -> np.ndarray:
    """Image velocities (N,2) pixels/s of points at distorted pixels xy (N,2) in the image they were seeded
    in, at its rows' read times: their path velocity over the next interval (`after`, dt seconds)
    interpolated with the one over the interval before (`before_velocity`, dt_before seconds; NaN rows
    unknown). The two are the velocities halfway along each path (dt_before / 2 before the image, dt / 2
    after it, both at the point's row offset d); the deskew stretch's middle, d / 2 after the image time,
    is (dt_before - d) / 2 after the first. The path after alone (a camera starting to pan) is the
    velocity half a frame late."""
    if before_velocity is None or not dt_before > 0:
        return after
    out = after.copy()
    known = np.isfinite(before_velocity).all(axis=1)
    d = camera.row_offsets(np.asarray(xy, float)[known, 1])
    w = ((dt_before - d) / (dt_before + dt))[:, None]
    out[known] = before_velocity[known] + (after[known] - before_velocity[known]) * w
    return out


def _flow_into(camera: Camera, tracks: Tracks, gray: np.ndarray,
               predicted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pyramidal Lucas-Kanade from `tracks.image` into `gray`, each point started where `predicted` projects
    its world point (where it was, when that falls far outside the image): (the points in `gray` (n,2) px,
    the mask of those followed: found, a patch error under MAX_PATCH_ERROR, inside the image)."""
    h, w = gray.shape[:2]
    start = camera.project_world(tracks.X, predicted).astype(np.float32)
    inside = (start[:, 0] > -w) & (start[:, 0] < 2 * w) & (start[:, 1] > -h) & (start[:, 1] < 2 * h)
    start = np.where(inside[:, None], start, tracks.xy)
    nxt, st, err = cv2.calcOpticalFlowPyrLK(tracks.image, gray, tracks.xy.reshape(-1, 1, 2), start.reshape(-1, 1, 2).copy(),
                                          winSize=WINDOW, maxLevel=LEVELS, criteria=CRITERIA,
                                          flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    nxt = nxt.reshape(-1, 2)
    ok = ((st.ravel() == 1) & (err.ravel() < MAX_PATCH_ERROR) & (nxt[:, 0] >= 0) & (nxt[:, 1] >= 0)
          & (nxt[:, 0] <= w - 1) & (nxt[:, 1] <= h - 1))
    return nxt, ok


def _fit_pose(camera: Camera, predicted: np.ndarray, X: np.ndarray, und: np.ndarray,
              need: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(world_from_camera, inlier mask) fitted to world points X seen at undistorted pixels `und`, from
    `predicted`, else (a poor prediction) from a RANSAC solution; None when under `need` inliers."""
    pose, inl, _ = refine_pose(camera.K, predicted, X, und)
    if inl.sum() < need:
        # a poor prediction: start again from a RANSAC solution
        guess, mask = pnp_ransac(camera.K, X, und, guess=predicted)
        if guess is None:
            return None
        pose, inl, _ = refine_pose(camera.K, guess, X, und)
        if inl.sum() < need:
            return None
    return pose, inl


def follow(camera: Camera, tracks: Tracks, gray: np.ndarray, predicted: np.ndarray, min_inliers: int = 20,
           min_inlier_ratio: float = 0.6, dt: float = 0.0, lifted_from: np.ndarray | None = None,
           before: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, Tracks] | None:
    """Follow `tracks` into the grey image `gray` and fit the pose there.

    The flow starts each point where `predicted` (world_from_camera, e.g. constant velocity) projects
    its world point, so fast motion needs no wide search. Returns (world_from_camera, the inlier tracks
    now measured in `gray`), or None when too few points were followed or the fit does not hold them
    (fewer than `min_inliers`, or under `min_inlier_ratio` of the followed ones). `dt`: seconds since
    `tracks.image`; with it and a rolling shutter each point is fitted where it would be at the centre
    row's time, by its motion over those dt seconds. `lifted_from`: the pose (world_from_camera) of
    `tracks.image`; with it, plane seeds followed for the first time are placed on the plane again with
    the motion now measured (they were placed with a guess of it). `before`: (the pose of the frame
    before `tracks.image`, the seconds between the two); with it the seeds' velocity over that interval
    is known too, and a camera that speeds up (a pan starting) is deskewed by its velocity at each frame's
    row times, not by the mean over the last interval (half a frame late: a shear of a pixel or more).
    """
    if len(tracks) < min_inliers:
        return None
    nxt, ok = _flow_into(camera, tracks, gray, predicted)
    if ok.sum() < min_inliers:
        return None
    idx = np.nonzero(ok)[0]
    velocity = before_velocity = None
    if dt > 0 and camera.readout > 0:
        path = (nxt - tracks.xy) / dt
        # the points' velocity over the interval before: what carries their motion on through an acceleration
        before_velocity = (tracks.path_velocity if lifted_from is None
                           else _step_velocity(camera, tracks, lifted_from, before, path, dt))
        velocity = _row_time_velocity(camera, tracks.xy, nxt, ok, dt, before_velocity)
    X_all = tracks.X
    if velocity is not None and lifted_from is not None:
        seed_v = _seed_velocity_then(camera, tracks.xy, path, dt, before_velocity, 0.0 if before is None else before[1])
        X_all = _relift_first_followed(camera, tracks, lifted_from, seed_v, ok)
    X = X_all[idx]
    seen = deskew(camera, nxt[idx], None if velocity is None else velocity[idx])
    und = camera.undistort_points(seen) if camera.has_distortion else seen
    fit = _fit_pose(camera, predicted, X, und, max(min_inliers, min_inlier_ratio * idx.size))
    if fit is None:
        return None
    pose, inl = fit
    keep = idx[inl]
    moved = nxt[keep] - tracks.xy[keep]
    planar = None if tracks.planar is None else tracks.planar_mask()[keep]
    return pose, Tracks(gray, np.ascontiguousarray(nxt[keep], np.float32), X_all[keep], moved, planar,
                        None if velocity is None else velocity[keep],
                        None if velocity is None else (moved / dt))

