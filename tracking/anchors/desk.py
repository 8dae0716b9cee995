"""The textured surface around a lone marker as the judge of its tilt (issue 25.4, the planar ambiguity).

A small marker seen nearly head-on has two poses that fit its four corners almost equally (IPPE's two
minima, `pose.planar_solutions`), and even the better one is tilted by degrees with a tenth of a pixel of
corner noise: the corners span too few pixels to show perspective. The desk the marker lies on spans the
whole image, and it is the same plane. Its keypoints, followed by optical flow from a reference frame,
move between two views by the homography that plane induces; that homography holds the camera's motion
and, once the camera has moved sideways a little, the plane's normal: the tilt the marker cannot show.

`DeskPlane.update` fits, by Levenberg-Marquardt on normalised image coordinates, the reference frame's pose
and this frame's pose together to the marker's corners in both frames and to the desk points' transfer
between them (every desk point lifted onto the marker's plane z = 0 from the reference view, and
projected into this one). The fit starts from both IPPE branches; the tilt's standard deviation comes
from the fit's Jacobian. Once the other minimum is excluded, frames spread over the camera's path are kept
and the reference pose is fitted to all of them at once (desk_bundle.py: one pair's tilt is a third to half
a degree off with a hand's baseline, several pairs average it). This frame's pose is then fitted with the
reference held there (the desk points are then a map on the marker's plane): its precision no longer falls
when the camera comes back toward where the reference was taken. Until the tilt is known to `decide_deg`
and the other minimum fits clearly worse, the result says undecided (the caller shows the marker's own pose
and asks the user to tilt the camera).

The desk points are followed frame to frame by optical flow and then matched again against the reference
image warped onto this frame (desk_match.py): plain flow matched each point's patch a few tenths of a pixel
off as the view scaled, turned and brightened, the same way in every frame, and that, not the flow's
noise, was what kept the tilt half a degree off.

Poses are 4x4 camera_from_world (world = the marker's anchor world, metres); pixels are distorted image
pixels as `camera` says.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from tracking.anchors.desk_bundle import Keys, refine
from tracking.anchors.desk_geometry import lift as _lift
from tracking.anchors.desk_geometry import params as _params
from tracking.anchors.desk_geometry import pose as _pose
from tracking.anchors.desk_geometry import project as _project
from tracking.anchors.desk_geometry import rot as _rot
from tracking.anchors.desk_match import match_to_reference
from tracking.camera import Camera
from tracking.poses import rotation_angle

_LK = dict(winSize=(15, 15), maxLevel=2, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01))


@dataclass
class DeskFit:
    """One frame's outcome: `camera_from_world` this frame's pose from the marker and the desk together,
    `sigma` its tilt's standard deviation (radians), `decided` whether that settles the marker's pose
    (tilt known to `decide_deg`, the other minimum excluded), `points` desk points used, `noise` the part
    of `sigma` that changes from frame to frame (radians: this frame's fit with the reference held; the
    reference's own error is common to every frame until it is refined, a bias no smoothing removes)."""

    camera_from_world: np.ndarray
    sigma: float
    decided: bool
    points: int
    noise: float = 0.0


class DeskPlane:
    """Keypoints of the surface a lone marker lies on, followed from a reference frame; see the module docstring.

    camera: intrinsics of the images; max_points: desk keypoints seeded (goodFeaturesToTrack); min_points:
    fewer followed points than this and the reference is taken anew; marker_px / desk_px: the pixel noise
    taken for the marker's corners and for the desk points (0.1: matched against the reference, their residual
    at the true poses is 0.07 px on the tuning recordings); decide_deg: the tilt's standard deviation
    (degrees) under which it counts as decided; exclude_chi2: how much worse (in squared standard deviations)
    the other minimum must fit to be excluded; rigid_sigmas: the marker's corners off by more than this
    (RMS, in `marker_px`) from this frame's fit with the reference held, and the marker is taken to move
    against the desk (`loose`: the desk is not followed until `reset`; the tuning head-on recordings reach
    0.3 px, a card waved before a wall, tune_held_marker, 0.7 px a quarter second in). `max_keys`: frames
    kept for the reference's bundle (0: none, the best single pair's reference is kept); `refine_gap`: frames
    between bundles once `max_keys` are kept (run every `free_every` frames the bundle took a third of the
    desk's time; the tuning recordings' figures moved within their noise from one to the other)."""

    def __init__(self, camera: Camera, max_points: int = 250, min_points: int = 40, marker_px: float = 0.3,
                 desk_px: float = 0.1, decide_deg: float = 1.0, exclude_chi2: float = 25.0,
                 rigid_sigmas: float = 2.0):
        self.camera = camera
        self.max_points, self.min_points = int(max_points), int(min_points)
        self.marker_px, self.desk_px = float(marker_px), float(desk_px)
        self.decide = np.radians(decide_deg)
        self.exclude_chi2 = float(exclude_chi2)
        self.rigid_sigmas = float(rigid_sigmas)
        self.f = float(np.sqrt(camera.fx * camera.fy))
        self.free_every = 5
        self.max_keys = 6
        self.refine_gap = 15
        self.reset()

    def reset(self) -> None:
        """Forget the reference frame, its points and what was decided."""
        self._prev_gray: np.ndarray | None = None
        self._prev_px: np.ndarray | None = None     # the desk points in the last frame (N,2 pixels)
        self._ref_x: np.ndarray | None = None       # ... in the reference frame (N,2 normalised)
        self._ref_marker: tuple | None = None       # (world corners (4,3), normalised corners (4,2))
        self._ref_branches: list[np.ndarray] = []   # the reference frame's IPPE poses
        self._ref_best: np.ndarray | None = None    # best-determined reference pose so far (params, 6)
        self._ref_sigma = np.inf                    # its tilt's standard deviation, radians
        self._last: np.ndarray | None = None        # last frame's fitted pose (params, 6)
        self._excluded = False                      # the other minimum was seen to fit clearly worse
        self._seeded = 0
        self._ref_px: np.ndarray | None = None     # the desk points in the reference frame (pixels, as seen)
        self._ref_gray: np.ndarray | None = None    # the reference frame's image
        self._ref_deskewed = False                  # ... moved to the reference's centre-row time yet
        self._prev_t: float | None = None
        self._prev2_px: np.ndarray | None = None    # the desk points two frames back (pixels, as seen)
        self._prev_dt: float | None = None
        self._ref_second = False                    # the reference's points deskewed with a second-order difference
        self._followed = 0                          # frames followed since the reference
        self._frames = 0                            # frames fitted since the reference was taken
        self._keys: list[tuple] = []                # frames kept for the reference's refinement: (xr, xc, marker, pose)
        self._bundled = False                       # the reference is the refinement's (not one pair's)
        self.decided = False
        self.loose = False                          # the marker was seen to move against the desk

    @property
    def active(self) -> bool:
        """Whether a reference frame is held (the desk is being followed)."""
        return self._ref_x is not None

    def _normalised(self, px: np.ndarray) -> np.ndarray:
        return cv2.undistortPoints(np.asarray(px, np.float64).reshape(-1, 1, 2), self.camera.K,
                                   self.camera.dist).reshape(-1, 2)

    def _seed(self, gray: np.ndarray, t: float, world: np.ndarray, img: np.ndarray, branches: list[np.ndarray],
              ref: np.ndarray | None, ref_sigma: float) -> None:
        pts = cv2.goodFeaturesToTrack(gray, self.max_points, 0.01, 12, blockSize=7)
        if pts is None or len(pts) < self.min_points:
            self._ref_x = None
            return
        pts = pts.reshape(-1, 2).astype(np.float32)
        self._prev_gray, self._prev_px, self._prev_t = gray, pts, t
        self._ref_gray = gray
        self._ref_px, self._ref_deskewed, self._frames = pts, self.camera.readout <= 0, 0
        self._prev2_px, self._prev_dt, self._ref_second, self._followed = None, None, False, 0
        self._ref_x = self._normalised(pts)
        self._ref_marker = (np.asarray(world, float), self._normalised(img))
        self._ref_branches = list(branches)
        self._ref_best = None if ref is None else _params(ref)
        self._ref_sigma = ref_sigma if ref is not None else np.inf
        self._seeded = len(pts)
        self._keys, self._bundled, self._refined_at = [], False, 0

    def _follow(self, gray: np.ndarray, t: float) -> np.ndarray:
        """The desk points followed into `gray` (forward-backward checked, then matched again against the
        reference image: desk_match); keeps only those. Their pixels, moved
        to the frame's centre-row time for a rolling shutter (`camera.readout`): each point by the image
        velocity at this frame's time times its row's offset. The velocity is the backward difference over the
        last two frames (second order, exact for a steady acceleration: the one-frame difference is the
        velocity half a frame earlier, and a hand's shake changes it by a tenth of a pixel over a readout),
        smoothed by a quadratic field over all points (`_smooth`); over the first frame alone, the one-frame
        difference. The differences are of positions each read at its row's time, so the velocity is the one
        at the row's time, d after the frame's: the move back over d is v d - a d^2 / 2, with the acceleration
        a from the second difference (as smoothed; up to 0.1 px at the top and bottom rows for a hand's
        shake). The reference frame's points likewise, with the forward difference: of first order on the
        frame after it, then of second order on the frame after that."""
        nxt, st, _ = cv2.calcOpticalFlowPyrLK(self._prev_gray, gray, self._prev_px, None, **_LK)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(gray, self._prev_gray, nxt, None, **_LK)
        ok = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm(back - self._prev_px, axis=1) < 0.5)
        # each point matched again against the reference image warped onto this frame (desk_match)
        nxt, ok = match_to_reference(self._ref_gray, self._ref_px, gray, nxt, ok)
        h, w = gray.shape
        ok &= (nxt[:, 0] >= 0) & (nxt[:, 0] < w) & (nxt[:, 1] >= 0) & (nxt[:, 1] < h)
        prev = self._prev_px[ok]
        prev2 = None if self._prev2_px is None else self._prev2_px[ok]
        self._prev2_px = prev
        self._prev_px, self._ref_x, self._ref_px = nxt[ok], self._ref_x[ok], self._ref_px[ok]
        self._prev_gray = gray
        dt = t - self._prev_t if self._prev_t is not None else 0.0
        dt_before, self._prev_dt = self._prev_dt, dt
        self._prev_t = t
        self._followed += 1
        if self.camera.readout <= 0 or not 0 < dt <= 0.2:
            return self._prev_px
        cur = self._prev_px
        # the second-order difference wants evenly spaced frames (a dropped frame: the first-order one)
        second = prev2 is not None and dt_before is not None and abs(dt_before - dt) < 0.2 * dt
        vel = (3.0 * cur - 4.0 * prev + prev2) / (2.0 * dt) if second else (cur - prev) / dt
        vel = self._smooth(cur, vel)
        acc = self._smooth(cur, (cur - 2.0 * prev + prev2) / (dt * dt)) if second else np.zeros_like(vel)
        second_ref = second and self._followed == 2   # prev2: the reference's own points, prev: the next frame's
        if not self._ref_deskewed or (second_ref and not self._ref_second):
            x0 = self._ref_px
            v0 = (-3.0 * x0 + 4.0 * prev - cur) / (2.0 * dt) if second_ref else (cur - prev) / dt
            d0 = self.camera.row_offsets(x0[:, 1])[:, None]
            ref = x0 - self._smooth(x0, v0) * d0 + (0.5 * acc * d0 * d0 if second_ref else 0.0)
            self._ref_x, self._ref_deskewed, self._ref_second = self._normalised(ref), True, second_ref
        d = self.camera.row_offsets(cur[:, 1])[:, None]
        return cur - vel * d + 0.5 * acc * d * d

    def _smooth(self, px: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """The image velocities `vel` (N,2 pixels/s) at pixels `px` (N,2) replaced by a quadratic field in the
        image coordinates fitted to them all (a plane's motion field nearly is one): less noise than each
        point's own."""
        if len(px) < 12:
            return vel
        u = 2.0 * px[:, 0] / self.camera.width - 1.0
        v = 2.0 * px[:, 1] / self.camera.height - 1.0
        A = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
        return A @ np.linalg.lstsq(A, vel, rcond=None)[0]

    def _residuals(self, p: np.ndarray, marker_c, xr: np.ndarray, xc: np.ndarray, fixed_ref: np.ndarray | None):
        """Normalised residuals (in standard deviations) of the joint fit: p = [reference pose, this pose]
        (or this pose alone with the reference held at `fixed_ref`)."""
        pr = fixed_ref if fixed_ref is not None else p[:6]
        pc = p[-6:]
        Rr, tr = _rot(pr)
        Rc, tc = _rot(pc)
        wc, mc = marker_c
        out = [((_project(Rc, tc, wc) - mc) * (self.f / self.marker_px)).ravel()]
        if fixed_ref is None:
            wr, mr = self._ref_marker
            out.append(((_project(Rr, tr, wr) - mr) * (self.f / self.marker_px)).ravel())
        X = _lift(Rr, tr, xr)
        out.append(((_project(Rc, tc, X) - xc) * (self.f / self.desk_px)).ravel())
        return np.concatenate(out)

    def _fit(self, start: np.ndarray, marker_c, xr, xc, fixed_ref=None):
        """(params, cost in squared standard deviations, tilt sigma of this pose (rad), of the reference's)."""
        try:
            r = least_squares(self._residuals, start, method="lm", args=(marker_c, xr, xc, fixed_ref),
                              x_scale="jac", max_nfev=60)
        except (ValueError, np.linalg.LinAlgError):
            return None
        try:
            cov = np.linalg.inv(r.jac.T @ r.jac)
        except np.linalg.LinAlgError:
            return None
        sig = lambda k: float(np.sqrt(max(np.linalg.eigvalsh(cov[k:k + 3, k:k + 3]).max(), 0.0)))  # noqa: E731
        n = len(start)
        return r.x, 2.0 * float(r.cost), sig(n - 6), (sig(0) if n == 12 else np.inf)

    def update(self, gray: np.ndarray, t: float, world: np.ndarray, img: np.ndarray,
               branches: list[np.ndarray]) -> DeskFit | None:
        """One frame (grey image `gray` taken at `t` seconds) with a lone marker: its corners `world` (4,3
        metres) at `img` (4,2 pixels) and its IPPE poses `branches` (camera_from_world). None while there is
        no fit yet (the first frame, too few desk points, a fit that failed)."""
        if len(branches) == 0 or len(world) < 4:
            self.reset()
            return None
        if self.loose:
            return None
        if not self.active or self._prev_gray is None or self._prev_gray.shape != gray.shape:
            self._seed(gray, t, world, img, branches, None, np.inf)
            return None
        px = self._follow(gray, t)
        if len(px) < max(self.min_points, self._seeded // 3):
            ref = None if self._last is None else _pose(self._last)
            sigma = self._ref_sigma if self.decided else np.inf
            self._seed(gray, t, world, img, branches, ref, sigma)
            return None
        xc = self._normalised(px)
        xr = self._ref_x
        # the plane's transfer as one homography first: points off it (a tracking slip, an object on the desk) go
        _, inl = cv2.findHomography(xr * self.f, xc * self.f, cv2.RANSAC, 2.0)
        if inl is None or inl.sum() < self.min_points:
            return None
        inl = inl.ravel().astype(bool)
        xr, xc = xr[inl], xc[inl]
        marker_c = (np.asarray(world, float), self._normalised(img))
        self._frames += 1
        best = self._free(branches, marker_c, xr, xc)
        if best is None and self._ref_best is None:
            return None
        start = best[0][6:] if self._last is None else self._last
        held = self._fit(start, marker_c, xr, xc, fixed_ref=self._ref_best)
        if held is None:
            return None
        corners = self._residuals(held[0], marker_c, xr, xc, self._ref_best)[:8]
        if float(np.sqrt(np.mean(corners ** 2))) > self.rigid_sigmas:
            # the marker's corners do not follow the desk: it moves against it (a card held before a wall),
            # and the desk says nothing of its tilt until the marker is lost and found again
            self.reset()
            self.loose = True
            return None
        if best is None and self._frames % self.free_every == 0:
            self._refine(xr, xc, marker_c, held[0])
        self._last = held[0]
        sigma = float(np.hypot(held[2], self._ref_sigma))
        self.decided = self.decided or (self._excluded and sigma < self.decide)
        return DeskFit(_pose(held[0]), sigma, self.decided, int(len(xr)), float(held[2]))

    def _free(self, branches: list[np.ndarray], marker_c, xr: np.ndarray, xc: np.ndarray) -> tuple | None:
        """The joint fit with the reference pose free (`_fit`, from each of `_starts`), the best of them or None:
        every frame until decided, then every `free_every` frames until the kept frames' bundle takes the
        reference over (it only improves as the camera moves further). It judges the other minimum, keeps
        the best-determined reference, and adds this frame to the bundle once the other minimum is out."""
        if self.decided and (self._bundled or self._frames % self.free_every != 0):
            return None
        fits = [f for f in (self._fit(s, marker_c, xr, xc) for s in self._starts(branches)) if f is not None]
        if not fits:
            return None
        fits.sort(key=lambda f: f[1])
        best = fits[0]
        self._judge(fits)
        if best[3] < self._ref_sigma:
            self._ref_best, self._ref_sigma = best[0][:6].copy(), best[3]
        if self._excluded:
            self._refine(xr, xc, marker_c, best[0][6:])
        return best

    def _judge(self, fits: list[tuple]) -> None:
        """Whether the other minimum is excluded, from this frame's joint fits (best first)."""
        best = fits[0]
        if self._excluded:
            return
        if len(fits) > 1:
            other = next((f for f in fits[1:] if rotation_angle(_rot(f[0][6:])[0] @ _rot(best[0][6:])[0].T)
                          > 3 * max(best[2], np.radians(0.3))), None)
            # the other minimum fits clearly worse (or is no minimum: the fit from it came to this one)
            self._excluded = (other is None or other[1] - best[1] > self.exclude_chi2) and best[2] < 2 * self.decide
        else:
            self._excluded = best[2] < 2 * self.decide and len(self._ref_branches) < 2

    def _refine(self, xr: np.ndarray, xc: np.ndarray, marker_c, pose: np.ndarray) -> None:
        """This frame kept (`_keep`) and, when that changed the kept frames, the reference pose fitted anew to
        all of them at once (desk_bundle.refine): the tilt from one pair of frames is as noisy as that pair's
        flow, from several pairs spread over the camera's path it averages. Taken once it is better
        determined than the best single pair's."""
        full = len(self._keys) >= self.max_keys
        if full and self._frames - self._refined_at < self.refine_gap:
            return
        if self.max_keys <= 0 or not self._keep(xr, xc, marker_c, pose) or len(self._keys) < 2:
            return
        self._refined_at = self._frames
        start = np.concatenate([self._ref_best] + [k[3] for k in self._keys])
        out = refine(start, self._ref_marker, Keys.pack([k[:3] for k in self._keys]), self.f / self.marker_px,
                     self.f / self.desk_px)
        if out is None:
            return
        x, sigma = out
        if sigma < self._ref_sigma or self._bundled:
            self._ref_best, self._ref_sigma, self._bundled = x[:6].copy(), sigma, True
            self._keys = [k[:3] + (x[6 + 6 * i:12 + 6 * i].copy(),) for i, k in enumerate(self._keys)]

    def _keep(self, xr: np.ndarray, xc: np.ndarray, marker_c, pose: np.ndarray) -> bool:
        """Add this frame to the kept ones (at most `max_keys`): when there are too many, the one whose camera
        is nearest another's (or the reference's) goes, so that those kept span the camera's path. Whether
        this frame stayed (False: the kept frames are as they were)."""
        keys = self._keys + [(xr, xc, marker_c, np.asarray(pose, float).copy())]
        if len(keys) > self.max_keys:
            c = np.array([-_rot(p)[0].T @ _rot(p)[1] for p in [self._ref_best] + [k[3] for k in keys]])
            d = np.linalg.norm(c[:, None] - c[None], axis=2) + np.diag(np.full(len(c), np.inf))
            drop = int(np.argmin(d[1:].min(axis=1)))
            if drop == len(keys) - 1:
                return False
            keys.pop(drop)
        self._keys = keys
        return True

    def _starts(self, branches: list[np.ndarray]) -> list[np.ndarray]:
        """Starting points [reference pose, this pose] of the joint fit: the last fit (once there is one) and,
        until the other minimum is excluded, each reference branch paired with this frame's branch closest
        to it in rotation."""
        out = []
        if self._ref_best is not None and self._last is not None:
            out.append(np.concatenate([self._ref_best, self._last]))
        if not self._excluded or not out:
            for rb in self._ref_branches:
                cb = min(branches, key=lambda b: rotation_angle(b[:3, :3] @ rb[:3, :3].T))
                out.append(np.concatenate([_params(rb), _params(cb)]))
        return out
