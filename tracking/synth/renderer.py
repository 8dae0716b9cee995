"""Exact rendering of a planar desk scene, then the things real cameras do.

Each supersampled output pixel is traced as a ray through the distorted
camera model (`Camera.unproject`, so lens distortion is applied exactly) and
intersected with the desk plane (for one pose that intersection is a homography
of the rays, applied by cv2.perspectiveTransform in double; a rolling shutter's
pose per row is cast per pixel); the desk texture is sampled there and the
printed anchors are evaluated analytically from their bit cells, so the
ground-truth pose is exact to the renderer's sampling. Supersampled pixels are
averaged down with INTER_AREA, which keeps OpenCV's pixel-centre convention
(`Camera.scaled`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from tracking.camera import Camera
from tracking.poses import invert
from tracking.synth.camera_effects import (AutoExposure, chroma_subsample_422, defocus, frame_jpeg_quality,
                                           jpeg_roundtrip, luminance, row_times, sensor_noise, vignette_factor,
                                           white_balance_gains)
from tracking.synth.hand import hand_polygons, smooth_presence
from tracking.synth.patterns import pattern_for
from tracking.synth.texture import make_desk_texture
from tracking.synth.trajectory import make_trajectory

if TYPE_CHECKING:  # annotations only: scene.py imports held.py, which imports this module
    from tracking.synth.scene import Scene

PAPER_BGR = np.array([228.0, 232.0, 234.0], np.float32)
INK_BGR = np.array([26.0, 24.0, 24.0], np.float32)
FLOOR_BGR = np.array([40.0, 45.0, 50.0], np.float32)
SKIN_BGR = np.array([120.0, 150.0, 205.0], np.float32)


_CACHE: dict = {}


def _cached(key, make):
    """Keep the last few rays/textures: tests and `synth all` reuse cameras and desks."""
    if key not in _CACHE:
        if len(_CACHE) >= 4:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = make()
    return _CACHE[key]


def _pixel_rays(camera: Camera) -> np.ndarray:
    """Normalised rays (x/z, y/z), float32 (H, W, 2), of every (distorted) pixel of `camera`."""

    def make():
        xs, ys = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
        return camera.unproject(np.stack([xs, ys], axis=-1))[..., :2].astype(np.float32)

    key = ("rays", camera.width, camera.height, camera.K.tobytes(), camera.dist.tobytes())
    return _cached(key, make)


def _apply_homography(rays: np.ndarray, H: np.ndarray) -> np.ndarray:
    """H (3x3, float64) applied to rays (h, w, 2) float32 C-contiguous: (h, w, 2) float32 (0 where the
    homogeneous w is within FLT_EPSILON of 0)."""
    h, w = rays.shape[:2]
    return cv2.perspectiveTransform(rays.reshape(-1, 1, 2), H).reshape(h, w, 2)


def _texture(w, h, ppm, seed, x_min, y_max, style):
    return _cached(("tex", w, h, ppm, seed, x_min, y_max, style),
                   lambda: make_desk_texture(w, h, ppm, seed, x_min=x_min, y_max=y_max, style=style))


class SceneTrajectory:
    """A scene's ground-truth camera poses alone: what DeskRenderer moves its camera along, without the desk
    texture and pixel rays it builds to draw (a second or two per scene), for checks that need only the
    poses (a rolling shutter's per-row poses, say)."""

    def __init__(self, scene: Scene):
        self.pose_desk = make_trajectory(scene.trajectory, scene.duration, scene.seed)
        self.centre = scene.centre_desk
        self.world_from_desk = scene.world_from_desk

    def world_from_camera(self, t: float) -> np.ndarray:
        """Ground-truth world_from_camera (4x4) at time t (seconds)."""
        desk_from_cam = self.pose_desk(t).copy()
        desk_from_cam[:3, 3] += self.centre
        return self.world_from_desk @ desk_from_cam


class DeskRenderer:
    """Renders a `Scene`: `render(i)` -> (BGR uint8 frame, world_from_camera, t).

    Holds the desk texture, the per-pixel rays of the supersampled camera and
    the trajectory. Frames are deterministic for the scene's seed.
    """

    def __init__(self, scene: Scene):
        self.scene = scene
        cam = scene.camera
        s = scene.supersample
        self.camera_ss = cam.scaled(cam.width * s, cam.height * s)
        self.rays = _pixel_rays(self.camera_ss)
        self.world_from_desk = scene.world_from_desk
        self.desk_from_world = invert(self.world_from_desk)
        c = scene.centre_desk
        w, h = scene.desk_size
        self.texture = _texture(w, h, scene.desk_ppm, scene.desk_seed, float(c[0] - w / 2), float(c[1] + h / 2),
                                scene.desk_style)
        self.patterns = []
        for a in scene.anchors:
            # Desk (x, y) -> anchor (x, y): the in-plane part of anchor_from_desk.
            A = invert(a.world_from_anchor) @ self.world_from_desk
            self.patterns.append((pattern_for(a), A[:2, [0, 1, 3]].astype(np.float64)))
        # the anchors printed on the desk (none when the scene has them taken away: `desk.anchors_shown`)
        self.printed = self.patterns if scene.anchors_shown else []
        self.centre = c
        self.truth = SceneTrajectory(scene)
        self.pose_desk = self.truth.pose_desk
        self.rng = np.random.default_rng(scene.seed + 101)
        ae = scene.effects.get("auto_exposure")
        self.ae = AutoExposure(**ae) if ae else None
        self._next_index = 0

    # -- geometry ----------------------------------------------------------------
    def time_of(self, i: int) -> float:
        return i / self.scene.fps

    def world_from_camera(self, t: float) -> np.ndarray:
        """Ground-truth pose at time t (seconds)."""
        return self.truth.world_from_camera(t)

    # -- rendering ---------------------------------------------------------------
    def render_clean(self, world_from_camera: np.ndarray, region: tuple[slice, slice] | None = None) -> np.ndarray:
        """Noise-free supersampled float32 BGR image of the desk and anchors from this pose.

        `world_from_camera` is one 4x4 pose, or (H_ss, 4, 4): one pose per supersampled row (a rolling
        shutter, see `row_poses`). `region` (rows, cols slices of the supersampled image, one pose only)
        renders just that part.
        """
        P = np.asarray(world_from_camera, np.float64)
        if P.ndim == 3:
            if region is not None:
                raise ValueError("render_clean: a region needs one pose, not one per row")
            return self._render_rolling(P)
        rs, cs = region if region is not None else (slice(None), slice(None))
        rays = self.rays[rs, cs]
        if not rays.flags.c_contiguous:
            rays = np.ascontiguousarray(rays)
        Hd, valid = self.plane_homography(P)
        ok = valid(rays)
        all_ok = bool(ok.all())
        img = self._desk_image(rays, Hd, ok, all_ok)
        self._print_anchors(img, rays, Hd, ok)
        img *= self._lamp_light(rays, Hd, ok, all_ok)[..., None]
        return img

    def _desk_image(self, rays: np.ndarray, Hd: np.ndarray, ok: np.ndarray, all_ok: bool) -> np.ndarray:
        """float32 BGR of the desk's texture seen along `rays` (the floor's colour where `ok` is False)."""
        # the desk plane seen through a pinhole is a homography of the (undistorted) rays: texture pixels
        # (u, v) are one 3x3 matrix applied to them (cv2 works in double, exact to float32 rounding)
        tex = self.texture
        to_tex = np.array([[tex.ppm, 0.0, -tex.x_min * tex.ppm - 0.5],
                           [0.0, -tex.ppm, tex.y_max * tex.ppm - 0.5], [0.0, 0.0, 1.0]])
        uv = _apply_homography(rays, to_tex @ Hd)
        if not all_ok:
            uv[~ok] = -10
        return cv2.remap(tex.image, uv, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=FLOOR_BGR.tolist()).astype(np.float32)

    def _print_anchors(self, img: np.ndarray, rays: np.ndarray, Hd: np.ndarray, ok: np.ndarray) -> None:
        """Paint each printed anchor's paper and ink into `img` (in place) where `rays` see it."""
        step = 4  # find each anchor's paper on a coarse grid first, then evaluate cells only around it
        H, W = ok.shape
        for pat, A in self.printed:
            # desk (x, y) -> print (p, q): affine, so rays -> (p, q) is one homography too
            to_print = np.array([[pat.sx, 0.0, -pat.origin[0] * pat.sx], [0.0, pat.sy, -pat.origin[1] * pat.sy],
                                 [0.0, 0.0, 1.0]]) @ np.vstack([A, [0.0, 0.0, 1.0]]) @ Hd

            def paper_and_value(sr, sc, pat=pat, to_print=to_print):
                sub_rays = np.ascontiguousarray(rays[sr, sc])
                pq = _apply_homography(sub_rays, to_print).astype(np.float64)
                paper, value = pat.sample(pq[..., 0], pq[..., 1])
                return paper & ok[sr, sc], value

            coarse, _ = paper_and_value(slice(None, None, step), slice(None, None, step))
            if not coarse.any():
                continue
            rows, cols = np.nonzero(coarse.any(axis=1))[0], np.nonzero(coarse.any(axis=0))[0]
            sr = slice(max(0, (rows[0] - 1) * step), min(H, (rows[-1] + 2) * step))
            sc = slice(max(0, (cols[0] - 1) * step), min(W, (cols[-1] + 2) * step))
            paper, value = paper_and_value(sr, sc)
            ink = paper & (value == 0)
            sub = img[sr, sc]
            sub[paper & ~ink] = PAPER_BGR
            sub[ink] = INK_BGR

    def _lamp_light(self, rays: np.ndarray, Hd: np.ndarray, ok: np.ndarray, all_ok: bool) -> np.ndarray:
        """float32 gain of the desk lamp along `rays` (1 where `ok` is False)."""
        # Soft desk lamp: brighter near one side, in desk coordinates so it moves with the scene:
        # 0.88 + 0.2 exp(-|(x, y) - lamp|^2 / 0.5), the offset scaled by 1/sqrt(0.5) by one more homography.
        k = 1.0 / np.sqrt(0.5)
        lx, ly, strength, ambient = self.scene.lamp
        to_lamp = np.array([[k, 0.0, -k * (self.centre[0] + lx)], [0.0, k, -k * (self.centre[1] + ly)],
                            [0.0, 0.0, 1.0]])
        d = _apply_homography(rays, to_lamp @ Hd)
        r2 = cv2.transform(d * d, np.ones((1, 2)))
        lamp = cv2.exp(-r2) * np.float32(strength) + np.float32(ambient)
        if not all_ok:
            lamp[~ok] = 1.0
        return lamp

    def plane_homography(self, world_from_camera: np.ndarray):
        """(Hd, valid): Hd (3x3) maps a ray (x/z, y/z, 1) of the camera at this pose to homogeneous desk
        (x, y, 1) metres where it meets the desk plane; valid(rays (h, w, 2)) -> (h, w) bool: the ray meets
        the plane in front of the camera (and not at its horizon, where cv2 gives 0)."""
        T = self.desk_from_world @ np.asarray(world_from_camera, np.float64)
        R, c = T[:3, :3], T[:3, 3]
        # point = c + s R r with s = -c_z / (R r)_z: x = (c_x (R r)_z - c_z (R r)_x) / (R r)_z
        Hd = np.array([c[0] * R[2] - c[2] * R[0], c[1] * R[2] - c[2] * R[1], R[2]])
        sign = -1.0 if c[2] > 0 else 1.0   # s > 0: (R r)_z has the sign of -c_z

        def valid(rays):
            dz = cv2.transform(rays, (sign * R[2]).reshape(1, 3))
            return dz > np.float32(np.finfo(np.float32).eps)

        return Hd, valid

    def _render_rolling(self, world_from_camera: np.ndarray) -> np.ndarray:
        """`render_clean` with one pose per supersampled row (H_ss, 4, 4): per-pixel ray casting."""
        P = np.asarray(world_from_camera, np.float64)
        if P.ndim == 2:
            T = self.desk_from_world @ P
            R, c = T[:3, :3].astype(np.float32), T[:3, 3].astype(np.float32)
        else:
            T = np.einsum("ij,rjk->rik", self.desk_from_world, P)
            # per row: (H, 1) columns broadcast over the row's pixels
            R = T[:, :3, :3].astype(np.float32)[:, :, :, None]
            c = T[:, :3, 3].astype(np.float32)[:, :, None]
        rx, ry = self.rays[..., 0], self.rays[..., 1]
        dz = R[2, 0] * rx + R[2, 1] * ry + R[2, 2] if P.ndim == 2 else R[:, 2, 0] * rx + R[:, 2, 1] * ry + R[:, 2, 2]
        cz = np.float32(-c[2]) if P.ndim == 2 else -c[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = cz / dz
        valid = s > 0
        s = np.where(valid, s, np.float32(0))
        if P.ndim == 2:
            x = np.float32(c[0]) + s * (R[0, 0] * rx + R[0, 1] * ry + R[0, 2])
            y = np.float32(c[1]) + s * (R[1, 0] * rx + R[1, 1] * ry + R[1, 2])
        else:
            x = c[:, 0] + s * (R[:, 0, 0] * rx + R[:, 0, 1] * ry + R[:, 0, 2])
            y = c[:, 1] + s * (R[:, 1, 0] * rx + R[:, 1, 1] * ry + R[:, 1, 2])
        tex = self.texture
        u, v = tex.pixel_of(x, y)
        u = np.where(valid, u, -10).astype(np.float32)
        v = np.where(valid, v, -10).astype(np.float32)
        img = cv2.remap(tex.image, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=FLOOR_BGR.tolist()).astype(np.float32)
        step = 4  # find each anchor's paper on a coarse grid first, then evaluate cells only around it
        H, W = valid.shape
        for pat, A in self.printed:
            def paper_and_value(rs, cs):
                xd, yd = x[rs, cs].astype(np.float64), y[rs, cs].astype(np.float64)
                p, q = pat.print_coords(A[0, 0] * xd + A[0, 1] * yd + A[0, 2], A[1, 0] * xd + A[1, 1] * yd + A[1, 2])
                paper, value = pat.sample(p, q)
                return paper & valid[rs, cs], value

            coarse, _ = paper_and_value(slice(None, None, step), slice(None, None, step))
            if not coarse.any():
                continue
            rows, cols = np.nonzero(coarse.any(axis=1))[0], np.nonzero(coarse.any(axis=0))[0]
            rs = slice(max(0, (rows[0] - 1) * step), min(H, (rows[-1] + 2) * step))
            cs = slice(max(0, (cols[0] - 1) * step), min(W, (cols[-1] + 2) * step))
            paper, value = paper_and_value(rs, cs)
            ink = paper & (value == 0)
            sub = img[rs, cs]
            sub[paper & ~ink] = PAPER_BGR
            sub[ink] = INK_BGR
        # Soft desk lamp: brighter near one side, in desk coordinates so it moves with the scene.
        lx, ly, strength, ambient = self.scene.lamp
        lamp = ambient + strength * np.exp(-((x - self.centre[0] - lx) ** 2 + (y - self.centre[1] - ly) ** 2) / 0.5)
        img *= np.where(valid, lamp, 1.0)[..., None]
        return img

    def anchor_pixel_extent(self, world_from_camera: np.ndarray, anchor_index: int) -> tuple[np.ndarray, float]:
        """Projected centre (x, y) and half-diagonal in pixels of an anchor's paper (margin included)."""
        a = self.scene.anchors[anchor_index]
        pat, _ = self.patterns[anchor_index]
        w, h = pat.extent
        m = pat.margin
        pts = []
        for p, q in ((-m, -m), (w + m, -m), (w + m, h + m), (-m, h + m), (w / 2, h / 2)):
            pts.append(a.world_from_anchor @ [pat.origin[0] + p * pat.sx, pat.origin[1] + q * pat.sy, 0, 1])
        px = self.scene.camera.project_world(np.array(pts)[:, :3], world_from_camera)
        size = float(np.max(np.linalg.norm(px[:4] - px[4], axis=1)))
        return px[4], size

    def row_poses(self, t: float) -> np.ndarray:
        """world_from_camera at time t: one 4x4 pose for a global shutter, or (H_ss, 4, 4), one per
        supersampled row, with effects.rolling_shutter = readout seconds (camera_effects.row_times;
        the frame's ground truth is its centre row's pose)."""
        readout = float(self.scene.effects.get("rolling_shutter") or 0.0)
        if readout <= 0:
            return self.world_from_camera(t)
        times = row_times(t, self.rays.shape[0], readout)
        # exact poses at 33 knots across the readout, interpolated between (slerp, lerp): over ~1 ms a
        # hand-held trajectory is a straight line to far below a micrometre
        knots = np.linspace(times[0], times[-1], 33)
        P = np.array([self.world_from_camera(float(k)) for k in knots])
        R = Slerp(knots, Rotation.from_matrix(P[:, :3, :3]))(times).as_matrix()
        out = np.zeros((len(times), 4, 4))
        out[:, :3, :3] = R
        for j in range(3):
            out[:, j, 3] = np.interp(times, knots, P[:, j, 3])
        out[:, 3, 3] = 1.0
        return out

    def render(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Frame i with all effects: (BGR uint8 image, world_from_camera, t seconds).

        Frames with auto-exposure are meant to be rendered in order (its gain depends on the frames
        before); rendering another frame than the next one restarts the auto-exposure.
        """
        sc, fx = self.scene, self.scene.effects
        t = self.time_of(i)
        pose = self.world_from_camera(t)
        blur = float(fx.get("motion_blur") or 0.0)
        if blur > 0:
            n = max(2, int(fx.get("blur_samples", 7)))
            offsets = (np.arange(n) + 0.5) / n - 0.5  # exposure centred on the frame time
            acc = None
            for o in offsets:
                img = self.render_clean(self.row_poses(t + o * blur / sc.fps))
                acc = img if acc is None else acc + img
            img = acc / n
        else:
            img = self.render_clean(self.row_poses(t))
        occ = fx.get("occluder")
        if occ and occ.get("start", 0) <= t <= occ.get("end", 0):
            if occ.get("style", "cover") == "border":
                self._draw_border_hand(img, t, occ)
            else:
                self._draw_hand(img, pose, t, occ)
        img = cv2.resize(img, (sc.camera.width, sc.camera.height), interpolation=cv2.INTER_AREA)
        if self.ae is not None and i != self._next_index:
            self.ae.reset()
        self._next_index = i + 1
        img = self._camera_response(img, t)
        return img, pose, t

    def _camera_response(self, img: np.ndarray, t: float) -> np.ndarray:
        """Optics, exposure, sensor, white balance, quantisation, link and codec (camera_effects)."""
        fx = self.scene.effects
        gain = 1.0
        exp = fx.get("exposure")
        if exp:
            gain = 1.0 + float(exp.get("amplitude", 0.2)) * np.sin(2 * np.pi * t / float(exp.get("period", 2.0)))
        vig = float(fx.get("vignette") or 0.0)
        if vig:
            cam = self.scene.camera
            img = img * vignette_factor(cam.width, cam.height, cam.cx, cam.cy, vig)[..., None]
        ae_gain = 1.0
        if self.ae is not None:
            ae_gain = self.ae.gain
            # the camera meters this frame (as exposed) and sets the next frame's gain
            self.ae.update(luminance(img) * gain * ae_gain)
        img = img * (gain * ae_gain)
        psf = float(fx.get("optics_blur") or 0.0)
        if psf > 0:
            img = cv2.GaussianBlur(img, (0, 0), psf)
        dfc = fx.get("defocus")
        if dfc:
            img = defocus(img, self.defocus_radius(t))
        sigma = float(fx.get("noise") or 0.0)
        if sigma > 0:
            # Read noise plus shot noise growing with brightness (sigma given at mid-grey).
            std = sigma * np.sqrt(0.3 + 0.7 * np.clip(img, 0, 255) / 128.0)
            img = img + self.rng.standard_normal(img.shape).astype(np.float32) * std
        sensor = fx.get("sensor")
        if sensor:
            img = sensor_noise(img, self.rng, float(sensor.get("full_well", 4000.0)),
                               float(sensor.get("read_noise", 1.5)), gain=gain * ae_gain)
        wb = fx.get("white_balance")
        if wb:
            img = img * white_balance_gains(t, float(wb.get("amplitude", 0.05)), float(wb.get("period", 3.0)),
                                            float(wb.get("phase", 0.0)))
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if fx.get("chroma_422"):
            out = chroma_subsample_422(out)
        q = frame_jpeg_quality(fx.get("jpeg_quality"), self.rng)
        if q:
            out = jpeg_roundtrip(out, q)
        return out

    def defocus_radius(self, t: float) -> float:
        """Pillbox radius (output pixels) at time t: effects.defocus = radius, or {"radius", "swing",
        "period"} for a lens hunting focus (radius + swing * sin(2 pi t / period), never below 0)."""
        d = self.scene.effects.get("defocus")
        if not d:
            return 0.0
        if isinstance(d, (int, float)):
            return float(d)
        r = float(d.get("radius", 1.0)) + float(d.get("swing", 0.0)) * np.sin(2 * np.pi * t / float(d.get("period", 2.0)))
        return max(0.0, float(r))

    def hand_pixels(self, t: float, occ: dict) -> list[np.ndarray]:
        """Projected outlines (supersampled pixels, each (N, 2)) of the border hand at time t (hand.py)."""
        a = self.scene.anchors[int(occ.get("anchor", 0))]
        pat, _ = self.patterns[int(occ.get("anchor", 0))]
        w, h = pat.extent
        m = pat.margin
        paper = np.array([[pat.origin[0] + p * pat.sx, pat.origin[1] + q * pat.sy]
                          for p, q in ((-m, -m), (w + m, -m), (w + m, h + m), (-m, h + m))])
        k = smooth_presence(t, float(occ.get("start", 0)), float(occ.get("end", 0)), float(occ.get("ramp", 0.4)))
        polys = hand_polygons(paper, float(occ.get("approach_deg", -60.0)), float(occ.get("reach", m)), k,
                              offset=float(occ.get("offset", 0.0)))
        poses = self.row_poses(t)
        out = []
        for poly in polys:
            local = poly.copy()
            local[:, 2] *= pat.normal_sign  # heights above the paper, toward the camera
            world = (a.world_from_anchor @ np.column_stack([local, np.ones(len(local))]).T).T[:, :3]
            if poses.ndim == 2:
                out.append(self.camera_ss.project_world(world, poses))
                continue
            # rolling shutter: each point seen at the time of the row it falls on (two fixed-point steps)
            rows = self.camera_ss.project_world(world, poses[len(poses) // 2])[:, 1]
            for _ in range(2):
                r = np.clip(np.rint(rows).astype(int), 0, len(poses) - 1)
                px = np.array([self.camera_ss.project_world(world[j], poses[r[j]]) for j in range(len(world))])
                rows = px[:, 1]
            out.append(px)
        return out

    def _draw_border_hand(self, img: np.ndarray, t: float, occ: dict) -> None:
        """A skin-coloured hand with rounded fingers whose fingertips slide onto an anchor's white
        border and off again (occluder style "border"), with a soft shadow on the desk."""
        polys = self.hand_pixels(t, occ)
        H, W = img.shape[:2]
        mask = np.zeros((H, W), np.uint8)
        for p in polys:
            if np.all(np.isfinite(p)):
                cv2.fillPoly(mask, [np.round(p * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
        if not mask.any():
            return
        s = self.scene.supersample
        # shadow: the hand's silhouette, shifted and blurred (a lamp above and behind the camera)
        shadow = cv2.GaussianBlur(np.roll(mask, (int(6 * s), int(4 * s)), axis=(0, 1)).astype(np.float32) / 255.0,
                                  (0, 0), 4.0 * s)
        img *= (1.0 - 0.35 * shadow)[..., None]
        alpha = (mask.astype(np.float32) / 255.0)[..., None]
        # skin: darker toward the silhouette's edge, as light falls off round a finger
        dist = cv2.distanceTransform((mask > 127).astype(np.uint8), cv2.DIST_L2, 3)
        shade = 0.72 + 0.28 * np.clip(dist / (5.0 * s), 0.0, 1.0)
        img *= 1.0 - alpha
        img += alpha * (SKIN_BGR * shade[..., None])

    def _draw_hand(self, img: np.ndarray, pose: np.ndarray, t: float, occ: dict) -> None:
        """A skin-coloured hand with fingers and forearm, sliding in over an anchor, in front of the desk."""
        s = self.scene.supersample
        start, end = float(occ.get("start", 0)), float(occ.get("end", 0))
        ramp = float(occ.get("ramp", 0.35))
        k = min(1.0, (t - start) / ramp, (end - t) / ramp)
        centre, size = self.anchor_pixel_extent(pose, int(occ.get("anchor", 0)))
        cam = self.scene.camera
        r = max(size * 1.05, 30.0)  # palm radius: covers the anchor's whole sheet
        come_from = np.array([0.55, 1.0]) / np.hypot(0.55, 1.0)  # arm enters from the lower right
        travel = r * 3.0 + np.hypot(cam.width, cam.height) * 0.6
        palm = centre + come_from * travel * (1.0 - k) ** 2
        mask = np.zeros(img.shape[:2], np.uint8)
        P = lambda p: (int(round((p[0] + 0.5) * s - 0.5)), int(round((p[1] + 0.5) * s - 0.5)))  # noqa: E731
        far = palm + come_from * (cam.width + cam.height) * 2
        cv2.line(mask, P(palm), P(far), 255, int(r * 1.5 * s), cv2.LINE_AA)
        cv2.ellipse(mask, P(palm), (int(r * s), int(r * 0.85 * s)), float(np.degrees(np.arctan2(come_from[1], come_from[0]))),
                    0, 360, 255, -1, cv2.LINE_AA)
        point = -come_from
        for j, ang in enumerate((-32, -12, 8, 26)):
            a = np.radians(ang)
            d = np.array([point[0] * np.cos(a) - point[1] * np.sin(a), point[0] * np.sin(a) + point[1] * np.cos(a)])
            base = palm + d * r * 0.7
            tip = base + d * r * (0.95 if j in (1, 2) else 0.75)
            cv2.line(mask, P(base), P(tip), 255, max(1, int(r * 0.34 * s)), cv2.LINE_AA)
            cv2.circle(mask, P(tip), max(1, int(r * 0.17 * s)), 255, -1, cv2.LINE_AA)
        a = np.radians(75)
        d = np.array([point[0] * np.cos(a) - point[1] * np.sin(a), point[0] * np.sin(a) + point[1] * np.cos(a)])
        cv2.line(mask, P(palm + d * r * 0.6), P(palm + d * r * 1.3), 255, max(1, int(r * 0.36 * s)), cv2.LINE_AA)
        bx, by, bw, bh = cv2.boundingRect(mask)  # shade only where the hand is
        if bw == 0 or bh == 0:
            return
        alpha = (mask[by:by + bh, bx:bx + bw].astype(np.float32) / 255.0)[..., None]
        yy, xx = np.mgrid[by:by + bh, bx:bx + bw].astype(np.float32)
        shade = 0.85 + 0.15 * np.cos((xx - P(palm)[0]) / (r * s * 1.5)) * np.cos((yy - P(palm)[1]) / (r * s * 1.7))
        sub = img[by:by + bh, bx:bx + bw]
        sub *= 1.0 - alpha
        sub += alpha * (SKIN_BGR * shade[..., None])


def render_frames(scene: Scene):
    """Iterate (index, t, BGR uint8 image, world_from_camera) over the whole scene."""
    r = DeskRenderer(scene)
    for i in range(scene.frame_count):
        img, pose, t = r.render(i)
        yield i, t, img, pose
