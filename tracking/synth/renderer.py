"""Exact rendering of a planar desk scene, then the things real cameras do.

Each supersampled output pixel is traced as a ray through the distorted
camera model (`Camera.unproject`, so lens distortion is applied exactly) and
intersected with the desk plane; the desk texture is sampled there and the
printed anchors are evaluated analytically from their bit cells, so the
ground-truth pose is exact to the renderer's sampling. Supersampled pixels are
averaged down with INTER_AREA, which keeps OpenCV's pixel-centre convention
(`Camera.scaled`).
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.camera import Camera
from tracking.poses import invert
from tracking.synth.patterns import pattern_for
from tracking.synth.scene import Scene
from tracking.synth.texture import make_desk_texture
from tracking.synth.trajectory import make_trajectory

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


def _texture(w, h, ppm, seed, x_min, y_max, style):
    return _cached(("tex", w, h, ppm, seed, x_min, y_max, style),
                   lambda: make_desk_texture(w, h, ppm, seed, x_min=x_min, y_max=y_max, style=style))


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
        self.centre = c
        self.pose_desk = make_trajectory(scene.trajectory, scene.duration, scene.seed)
        self.rng = np.random.default_rng(scene.seed + 101)

    # -- geometry ----------------------------------------------------------------
    def time_of(self, i: int) -> float:
        return i / self.scene.fps

    def world_from_camera(self, t: float) -> np.ndarray:
        """Ground-truth pose at time t (seconds)."""
        desk_from_cam = self.pose_desk(t).copy()
        desk_from_cam[:3, 3] += self.centre
        return self.world_from_desk @ desk_from_cam

    # -- rendering ---------------------------------------------------------------
    def render_clean(self, world_from_camera: np.ndarray) -> np.ndarray:
        """Noise-free supersampled float32 BGR image of the desk and anchors from this pose."""
        T = self.desk_from_world @ world_from_camera
        R, c = T[:3, :3].astype(np.float32), T[:3, 3]
        rx, ry = self.rays[..., 0], self.rays[..., 1]
        dz = R[2, 0] * rx + R[2, 1] * ry + R[2, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.float32(-c[2]) / dz
        valid = s > 0
        s = np.where(valid, s, np.float32(0))
        x = np.float32(c[0]) + s * (R[0, 0] * rx + R[0, 1] * ry + R[0, 2])
        y = np.float32(c[1]) + s * (R[1, 0] * rx + R[1, 1] * ry + R[1, 2])
        tex = self.texture
        u, v = tex.pixel_of(x, y)
        u = np.where(valid, u, -10).astype(np.float32)
        v = np.where(valid, v, -10).astype(np.float32)
        img = cv2.remap(tex.image, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=FLOOR_BGR.tolist()).astype(np.float32)
        step = 4  # find each anchor's paper on a coarse grid first, then evaluate cells only around it
        H, W = valid.shape
        for pat, A in self.patterns:
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
        lamp = 0.88 + 0.2 * np.exp(-((x - self.centre[0] - 0.3) ** 2 + (y - self.centre[1] - 0.2) ** 2) / 0.5)
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

    def render(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Frame i with all effects: (BGR uint8 image, world_from_camera, t seconds)."""
        sc, fx = self.scene, self.scene.effects
        t = self.time_of(i)
        pose = self.world_from_camera(t)
        blur = float(fx.get("motion_blur") or 0.0)
        if blur > 0:
            n = max(2, int(fx.get("blur_samples", 7)))
            offsets = (np.arange(n) + 0.5) / n - 0.5  # exposure centred on the frame time
            acc = None
            for o in offsets:
                img = self.render_clean(self.world_from_camera(t + o * blur / sc.fps))
                acc = img if acc is None else acc + img
            img = acc / n
        else:
            img = self.render_clean(pose)
        occ = fx.get("occluder")
        if occ and occ.get("start", 0) <= t <= occ.get("end", 0):
            self._draw_hand(img, pose, t, occ)
        img = cv2.resize(img, (sc.camera.width, sc.camera.height), interpolation=cv2.INTER_AREA)
        img = self._camera_response(img, t)
        return img, pose, t

    def _camera_response(self, img: np.ndarray, t: float) -> np.ndarray:
        fx = self.scene.effects
        gain = 1.0
        exp = fx.get("exposure")
        if exp:
            gain = 1.0 + float(exp.get("amplitude", 0.2)) * np.sin(2 * np.pi * t / float(exp.get("period", 2.0)))
        vig = float(fx.get("vignette") or 0.0)
        if vig:
            cam = self.scene.camera
            yy, xx = np.mgrid[0:cam.height, 0:cam.width].astype(np.float32)
            r2 = ((xx - cam.cx) ** 2 + (yy - cam.cy) ** 2) / (cam.cx ** 2 + cam.cy ** 2)
            img = img * (1.0 - vig * r2)[..., None]
        img = img * gain
        psf = float(fx.get("optics_blur") or 0.0)
        if psf > 0:
            img = cv2.GaussianBlur(img, (0, 0), psf)
        sigma = float(fx.get("noise") or 0.0)
        if sigma > 0:
            # Read noise plus shot noise growing with brightness (sigma given at mid-grey).
            std = sigma * np.sqrt(0.3 + 0.7 * np.clip(img, 0, 255) / 128.0)
            img = img + self.rng.standard_normal(img.shape).astype(np.float32) * std
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        q = fx.get("jpeg_quality")
        if q:
            ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
            out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return out

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
