"""The card a lone marker is printed on, as the judge of its tilt while the card is moved before the camera
(issue 25.2: a marker card held up to a still webcam).

A lone 6 cm marker at 0.4 m seen nearly head-on has its tilt fixed only by the perspective of its four
corners: a few tenths of a pixel of corner noise tilt it by degrees, and the camera's position swings by
centimetres about the marker from frame to frame (the orbit mode; measured on tune_held_marker: 2 to 57 mm
while the card drifts, its corners 0.3 to 0.6 px from the truth). The card around the marker is on the same
plane and spans more of the image. `CardPoints` keeps keypoints of it in the marker's own frame (on its plane
z = 0): each is followed by optical flow from frame to frame, and its place on the plane is the weighted
mean of where every frame's own marker pose puts it (the pose from the four corners alone, weighted by the
inverse square of its expected position error, `slam.frame_pose.position_spread` at `corner_px`): each
frame's tilt error is its own, so the mean converges where no single frame does. This frame's pose is then
fitted to the marker's corners and those points together (`slam.frame_pose.refine_pose`): the points follow
the card's real turns from frame to frame, their mean place carries the tilt of many frames.

Only points on the card: they are seeded within `grow` marker sides around the marker, and dropped once
they leave the marker's own homography since they were seeded by more than `follow_px` pixels (the still
background behind a moving card does), or the fitted pose by more than `fit_px`. Frames whose marker moved
`smear_px` or more since the last one are smeared (their corners are off by pixels): they are fitted, but
neither seed points nor move their places (the first frame after a loss, whose smear cannot be told, seeds).

Poses are 4x4 camera_from_world (world = the anchors' world, the marker's plane z = 0 in it, metres);
pixels are distorted image pixels as `camera` says.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.poses import invert
from tracking.pose_fit import position_spread, refine_pose

_LK = dict(winSize=(15, 15), maxLevel=2, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01))
_CROP_PX = 40   # pixels of image kept around the points for the flow: its window and pyramid need ~30


class CardPoints:
    """Keypoints of the card around a lone marker, in the marker's world frame; see the module docstring.

    grow: marker sides around the marker (each way, on its plane) where points are seeded; max_points /
    min_points: points seeded at most / below which more are seeded; corner_px / point_px: pixel noise taken
    for the marker's corners and for a followed point; min_lifts: frames a point's place must rest on before
    it counts in the fit; follow_px / fit_px: see the module docstring; smear_px: marker motion (pixels since
    the last frame, median over its corners) from which a frame counts as smeared (the tracker's `smear_px`).
    Chosen on tune_held_marker: grow 1.0 to 1.5, follow_px 2 to 5 and min_lifts 2 to 5 alike (its worst frame
    once the card moves 2 to 2.5 cm); grow 0.5, the card's own edge there, left too few points (3.3 cm).
    max_points 50 / min_points 20 place tune_held_marker as 100 / 40 do (110 frames, none over 3 cm, worst
    29.7 mm) at a third of the flow's cost: the points are followed on every lone-marker frame, so their cost
    falls on every lone-marker session (tracking 3 ms a frame less on test_hand_border)."""

    def __init__(self, camera: Camera, grow: float = 1.0, max_points: int = 50, min_points: int = 20,
                 corner_px: float = 0.5, point_px: float = 0.5, min_lifts: int = 3, follow_px: float = 3.0,
                 fit_px: float = 2.0, smear_px: float = 10.0):
        self.camera = camera
        self.grow = float(grow)
        self.max_points, self.min_points = int(max_points), int(min_points)
        self.corner_px, self.point_px = float(corner_px), float(point_px)
        self.min_lifts = int(min_lifts)
        self.follow_px, self.fit_px, self.smear_px = float(follow_px), float(fit_px), float(smear_px)
        # whether the fit is the marker's measurement (its caller's choice: once the card is seen to move in
        # the room); until then the points are only followed and placed, so that their places rest on many
        # frames when it begins to carry
        self.carries = False
        self.reset()

    def reset(self) -> None:
        """Forget every point (the card was lost: a swing past reading); `carries` stays as it is."""
        self._gray: np.ndarray | None = None       # the last frame's grey image
        self._corners: np.ndarray | None = None    # ... and the marker's corners in it (4,2 px)
        self.px = np.zeros((0, 2), np.float32)     # the points in the last frame (N,2 px)
        self.X = np.zeros((0, 3))                  # their places on the marker's plane (N,3 world metres)
        self.weight = np.zeros(0)                  # the summed weight of their places (1/m^2)
        self.lifts = np.zeros(0, int)              # frames their places rest on
        self.seed_px = np.zeros((0, 2))            # where they were seeded (px) ...
        self.seed_of = np.zeros(0, int)            # ... in which seeding (a key of _seed_corners)
        self._seed_corners: dict[int, np.ndarray] = {}   # seeding -> the marker's corners then (4,2 px)
        self._seedings = 0

    def update(self, gray: np.ndarray, world: np.ndarray, img: np.ndarray, camera_from_world: np.ndarray,
               lone: bool = True, spread_px: float | None = None) -> tuple[np.ndarray, float] | None:
        """One frame (grey image `gray`) of the lone marker: its corners `world` (4,3 metres) seen at `img`
        (4,2 px) and the pose fitted to them alone (`camera_from_world`). Returns (world_from_camera fitted to
        the corners and the card's points, the spread of its camera position (metres,
        `slam.frame_pose.position_spread`) with every point measured to `spread_px` pixels, `point_px` when
        None) or None while the card does not carry (`carries`) or too few points are known yet (the corners'
        own pose is then the frame's). `lone` False: the pose does not rest on a lone marker's four corners
        this frame (several anchors, a board): the points are forgotten and None is returned."""
        if not lone:
            self.reset()
            return None
        world, img = np.asarray(world, float), np.asarray(img, float)
        if self._gray is not None and self._gray.shape == gray.shape and len(self.px):
            self._follow(gray, img)
        # (the first frame after the card was lost has no last frame to tell its smear by: it seeds, and after
        # a swing its points hold its tilt across the smeared frames that follow, see `_used`)
        smeared = (self._corners is not None
                   and float(np.median(np.linalg.norm(img - self._corners, axis=1))) >= self.smear_px)
        use = self._used()
        out = None
        if self.carries and int(use.sum()) >= 8:
            X = np.vstack([world, self.X[use]])
            uv = self.camera.undistort_points(np.vstack([img, self.px[use]]))
            w = np.concatenate([np.full(len(world), self.corner_px ** -2), np.full(int(use.sum()), self.point_px ** -2)])
            wfc, _, _ = refine_pose(self.camera.K, invert(camera_from_world), X, uv, weights=w)
            out = (wfc, position_spread(self.camera.K, wfc, X, self.point_px if spread_px is None else spread_px))
        self._prune(camera_from_world if out is None else invert(out[0]))
        if not smeared:
            wfc = invert(camera_from_world)
            weight = position_spread(self.camera.K, wfc, world, self.corner_px) ** -2
            self._lift(wfc, weight)
            if len(self.px) < self.min_points:
                self._seed(gray, world, img, wfc, weight)
        self._gray, self._corners = gray, img
        return out

    def _used(self) -> np.ndarray:
        """(N,) bool: the points that count in the fit: those placed on `min_lifts` frames or more, or, while
        fewer than 8 are, every point (after a swing: the points of its first reading, placed once, hold that
        reading's tilt while the smeared frames after it neither place points nor hold the tilt themselves:
        their corners are off by a pixel along the smear; measured on tune_held_marker, 33.8 and 25.5 mm on
        their own corners, 20 mm with the first reading's points)."""
        use = self.lifts >= self.min_lifts
        return use if int(use.sum()) >= 8 else self.lifts >= 1

    def _follow(self, gray: np.ndarray, img: np.ndarray) -> None:
        """The points followed from the last frame into `gray` (forward-backward checked), those that left the
        marker's homography since their seeding by more than `follow_px` dropped (not on the card)."""
        # on the images cropped around the points, where they were and where the marker's motion takes them
        # (the pyramids of the whole image cost several times the flow itself; the motion only widens the crop:
        # taken as the flow's start it follows points across the smear that the fit is better without)
        guess = (self.px + np.median(img - self._corners, axis=0)).astype(np.float32)
        both = np.vstack([self.px, guess])
        h, w = gray.shape
        x0, y0 = np.clip(np.floor(both.min(axis=0)).astype(int) - _CROP_PX, 0, [w, h])
        x1, y1 = np.clip(np.ceil(both.max(axis=0)).astype(int) + _CROP_PX, 0, [w, h])
        o = np.float32([x0, y0])
        a, b = self._gray[y0:y1, x0:x1], gray[y0:y1, x0:x1]
        nxt, st, _ = cv2.calcOpticalFlowPyrLK(a, b, self.px - o, None, **_LK)
        ok = st.ravel() == 1
        if self.carries:   # (the backward check only once the points carry: until then a slip is pruned later)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, nxt, None, **_LK)
            ok &= (st2.ravel() == 1) & (np.linalg.norm(back + o - self.px, axis=1) < 0.5)
        nxt = nxt + o
        self.px = nxt
        for s in np.unique(self.seed_of[ok]):
            m = ok & (self.seed_of == s)
            H = cv2.getPerspectiveTransform(self._seed_corners[int(s)].astype(np.float32), img.astype(np.float32))
            moved = cv2.perspectiveTransform(self.seed_px[m].reshape(-1, 1, 2), H).reshape(-1, 2)
            ok[m] = np.linalg.norm(moved - nxt[m], axis=1) <= self.follow_px
        self._keep(ok)

    def _prune(self, camera_from_world: np.ndarray) -> None:
        """Drop the points that the pose (camera_from_world) puts more than `fit_px` from where they are seen."""
        if len(self.px):
            seen = self.camera.project_world(self.X, invert(camera_from_world))
            self._keep(np.linalg.norm(seen - self.px, axis=1) <= self.fit_px)

    def _lift(self, world_from_camera: np.ndarray, weight: float) -> None:
        """Every point's place moved toward where the pose (world_from_camera) puts it on the plane, as a
        running weighted mean (`weight` this frame's)."""
        if not len(self.px):
            return
        L, ok = self._on_plane(world_from_camera, self.px)
        self.weight = self.weight + np.where(ok, weight, 0.0)
        self.X = self.X + np.where(ok[:, None], (L - self.X) * (weight / np.maximum(self.weight, 1e-12))[:, None], 0.0)
        self.lifts = self.lifts + ok

    def _seed(self, gray: np.ndarray, world: np.ndarray, img: np.ndarray, world_from_camera: np.ndarray,
              weight: float) -> None:
        """New points (Shi-Tomasi corners) within `grow` marker sides around the marker, away from the points
        kept, placed on its plane from the pose (world_from_camera)."""
        H, _ = cv2.findHomography(world[:, :2], img)
        if H is None:
            return
        mid = world[:, :2].mean(axis=0)
        grown = (mid + (world[:, :2] - mid) * (1.0 + 2.0 * self.grow)).reshape(-1, 1, 2)
        poly = np.round(cv2.perspectiveTransform(grown, H).reshape(-1, 2)).astype(np.int32)
        # (the corner measure only within the region's bounding box: a tenth of the image's cost)
        h, w = gray.shape
        x0, y0 = np.clip(poly.min(axis=0) - 4, 0, [w, h])
        x1, y1 = np.clip(poly.max(axis=0) + 5, 0, [w, h])
        if x1 - x0 < 8 or y1 - y0 < 8:
            return
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, poly - [x0, y0], 255)
        for x, y in self.px:
            cv2.circle(mask, (int(round(x)) - x0, int(round(y)) - y0), 6, 0, -1)
        new = cv2.goodFeaturesToTrack(np.ascontiguousarray(gray[y0:y1, x0:x1]), self.max_points - len(self.px), 0.01,
                                      6, blockSize=5, mask=mask)
        if new is None:
            return
        new = new.reshape(-1, 2).astype(np.float32) + np.float32([x0, y0])
        X, ok = self._on_plane(world_from_camera, new)
        new, X = new[ok], X[ok]
        s = self._seedings
        self._seedings += 1
        self._seed_corners[s] = img.copy()
        self.px = np.vstack([self.px, new])
        self.X = np.vstack([self.X, X])
        self.weight = np.concatenate([self.weight, np.full(len(new), weight)])
        self.lifts = np.concatenate([self.lifts, np.ones(len(new), int)])
        self.seed_px = np.vstack([self.seed_px, new.astype(float)])
        self.seed_of = np.concatenate([self.seed_of, np.full(len(new), s)])

    def _on_plane(self, world_from_camera: np.ndarray, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(world points (N,3) on the plane z = 0 seen at distorted pixels `px` (N,2), whether the ray meets it
        in front of the camera (N,))."""
        d = self.camera.unproject(np.asarray(px, float)) @ world_from_camera[:3, :3].T
        c = world_from_camera[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = -c[2] / d[:, 2]
        ok = np.isfinite(lam) & (lam > 0)
        return c + np.where(ok, lam, 0.0)[:, None] * d, ok

    def _keep(self, ok: np.ndarray) -> None:
        self.px, self.X, self.weight, self.lifts = self.px[ok], self.X[ok], self.weight[ok], self.lifts[ok]
        self.seed_px, self.seed_of = self.seed_px[ok], self.seed_of[ok]
        live = set(np.unique(self.seed_of).tolist())
        self._seed_corners = {k: v for k, v in self._seed_corners.items() if k in live}
