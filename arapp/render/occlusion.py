"""Occlusion of the overlay by real things: the model is drawn per pixel only where it is nearer than the scene.

Modes (`MODES`):
- "off": the model is drawn over everything (as before).
- "depth": the scene's depth is measured (a depth camera such as an OAK-D, or a recording's `depth/`
  stream): float32 metres along the camera's z on the colour image's pixels, 0 where there is none.
- "plane": no depth sensor; the scene is the anchor's plane (world z = 0, the table top), so the parts of
  the model below the table are hidden (a model sunk into the desk, a cut-away preview).

How a crop of the overlay is occluded (`visibility`):
1. the scene depth around the crop is taken with a margin; holes (0: no stereo match, out of range) are
   filled along each row from the *farther* of the two valid neighbours (`fill_holes`): stereo depth
   loses the background beside a near object's edge (the strip one camera of the pair cannot see), and
   the background is what lies there; holes open to the window's edge on one side stay unknown;
2. a 5x5 median removes flying pixels at depth edges and speckle;
3. a model pixel is visible where its depth is at most the scene's plus a tolerance that grows with the
   distance as stereo noise does (`tolerance_m + noise_per_m2 * z^2`); unknown scene depth (0) and
   pixels without model depth (a contact shadow) leave the model visible;
4. the model's depth is first carried a few px beyond its silhouette (so that neither the erosion nor the
   feather treats the silhouette as an occlusion edge), the hidden part is eroded by `shrink_px` (stereo
   depth edges bulge about a pixel past the object: foreground fattening) and the mask is feathered by a
   Gaussian of `feather_px`: a soft edge of about two pixels.

The premultiplied crop is multiplied by that alpha (`apply_alpha`); `Occluder` packages it as the callable
`OverlayRenderer.draw(..., occlusion=)` takes. The model's depth comes from the renderer's depth buffer
(`read_model_depth`, called by the renderer when an occlusion is asked for): OpenCV-camera z in the
camera's units, +inf where nothing was drawn, on the same (distorted) pixels as the colour crop.
Docs: docs/occlusion.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

MODES = ("off", "depth", "plane")


@dataclass(frozen=True)
class OcclusionParams:
    """Tuned on the tuning recordings `tune_occlusion_*` only (tracking/synth/presets/occlusion.py OCCLUSION_TUNING)."""

    tolerance_m: float = 0.006  # a model pixel this far behind the measured surface is still drawn
    noise_per_m2: float = 0.004  # plus this times z^2 (metres): stereo depth noise grows with the square of z
    plane_tolerance_m: float = 0.001  # plane mode: the plane is exact, only the renderer's depth precision
    feather_px: float = 1.0  # Gaussian sigma of the soft edge, pixels
    shrink_px: int = 1  # the occluder's mask eroded (> 0) or grown (< 0) by this much (foreground fattening)
    median_px: int = 3  # 0, 3 or 5: median filter of the scene depth (flying pixels, speckle)
    margin_px: int = 64  # scene depth read this far around the crop (hole filling along rows reaches out)
    fill: bool = True  # fill holes from the farther side (False: holes are unknown, the model drawn there)


DEFAULT_PARAMS = OcclusionParams()


def check_mode(mode: str) -> str:
    """`mode` if it is one of MODES; ValueError naming the choices otherwise."""
    if mode not in MODES:
        raise ValueError(f"occlusion must be one of {', '.join(MODES)}, got {mode!r}")
    return mode


def fill_holes(depth: np.ndarray) -> np.ndarray:
    """Depth (h, w) float32 metres with holes (<= 0) filled along each row by the farther of the nearest
    valid pixels to their left and right; a hole with no valid pixel on one side (it reaches the edge of
    the window) stays 0, unknown: beside a near object that side may be the background it hides."""
    d = np.ascontiguousarray(depth, np.float32)
    hole = d <= 0
    if not hole.any():
        return d
    h, w = d.shape
    # runs of holes along the rows, found in one pass over the rows laid end to end (a False column
    # between rows keeps runs from wrapping); each run takes one value, repeated over its pixels
    padded = np.zeros((h, w + 2), np.int8)
    padded[:, 1:-1] = hole
    step = np.diff(padded.ravel())
    first = np.flatnonzero(step == 1) + 1  # padded flat index of each run's first hole pixel
    last = np.flatnonzero(step == -1)  # ... and of its last
    row = first // (w + 2)
    c0, c1 = first % (w + 2) - 1, last % (w + 2) - 1
    closed = (c0 > 0) & (c1 < w - 1)
    lv = d[row, np.maximum(c0 - 1, 0)]
    rv = d[row, np.minimum(c1 + 1, w - 1)]
    value = np.where(closed, np.maximum(lv, rv), np.float32(0.0)).astype(np.float32)
    out = d.copy()
    out[hole] = np.repeat(value, c1 - c0 + 1)  # boolean indexing is row-major, as the runs are
    return out


def scene_window(depth: np.ndarray, x0: int, y0: int, w: int, h: int, margin: int):
    """The part of the full-frame `depth` around the crop (x0, y0, w, h), `margin` pixels more on each side
    (clipped to the frame): (window, (ox, oy)) with (ox, oy) the crop's offset inside the window."""
    H, W = depth.shape
    a, b = max(0, x0 - margin), max(0, y0 - margin)
    c, d = min(W, x0 + w + margin), min(H, y0 + h + margin)
    return depth[b:d, a:c], (x0 - a, y0 - b)


def visibility(model_z: np.ndarray, scene_z: np.ndarray, params: OcclusionParams = DEFAULT_PARAMS,
               tolerance_m: float | None = None, noise_per_m2: float | None = None) -> np.ndarray:
    """Alpha (h, w) float32 0..1 of the model at each pixel: 1 drawn, 0 hidden behind the scene.

    model_z: the model's camera z (metres, +inf where it has none); scene_z: the scene's (metres, 0 where
    unknown), already hole-filled and filtered, same shape. The tolerance arguments override `params`'.
    """
    tol = params.tolerance_m if tolerance_m is None else tolerance_m
    k = params.noise_per_m2 if noise_per_m2 is None else noise_per_m2
    s = np.ascontiguousarray(scene_z, np.float32)
    m = np.ascontiguousarray(model_z, np.float32)
    reach = abs(int(params.shrink_px)) + int(np.ceil(3.0 * params.feather_px))
    if reach > 0:
        # pixels just outside the model (antialiased rims, gaps between thin lines) take the nearest model
        # depth around them, as far as the erosion and the feather reach, so that these never treat the
        # model's own silhouette as the edge of an occluder; the model's own pixels keep their depth
        near = cv2.erode(m, np.ones((2 * reach + 1, 2 * reach + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
        m = np.where(np.isinf(m), near, m)
    # OpenCV's element-wise operations (vectorised, no temporaries of Python floats): this runs per frame
    limit = cv2.add(cv2.multiply(s, s, scale=float(k)), s)
    limit = cv2.add(limit, float(tol))
    hidden = cv2.compare(m, limit, cv2.CMP_GT)  # 255 where the model is behind the scene
    hidden = cv2.bitwise_and(hidden, cv2.compare(s, 0.0, cv2.CMP_GT))  # scene depth known
    hidden = cv2.bitwise_and(hidden, cv2.compare(m, float(np.finfo(np.float32).max), cv2.CMP_LT))  # model there
    if not hidden.any():
        return np.ones(s.shape, np.float32)
    if params.shrink_px != 0:
        r = abs(int(params.shrink_px))
        op = cv2.erode if params.shrink_px > 0 else cv2.dilate  # negative: grow the occluder instead
        hidden = op(hidden, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)),
                    borderType=cv2.BORDER_REPLICATE)
    drawn = cv2.bitwise_not(hidden)
    if params.feather_px > 0:
        drawn = cv2.GaussianBlur(drawn, (0, 0), float(params.feather_px), borderType=cv2.BORDER_REPLICATE)
    return cv2.multiply(drawn, 1.0 / 255.0, dtype=cv2.CV_32F)


def prepare_scene(depth_window: np.ndarray, params: OcclusionParams = DEFAULT_PARAMS) -> np.ndarray:
    """Hole filling and the median filter of a scene depth window (float32 metres, 0 = none)."""
    d = fill_holes(depth_window) if params.fill else np.ascontiguousarray(depth_window, np.float32)
    m = int(params.median_px)
    if m in (3, 5) and min(d.shape) >= m:
        d = cv2.medianBlur(d, m)
    return d


def apply_alpha(premul_rgba: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """A premultiplied RGBA uint8 crop with every channel multiplied by `alpha` (h, w) 0..1 (rounded)."""
    a8 = cv2.convertScaleAbs(alpha, alpha=255.0)  # saturating, rounded
    return cv2.multiply(premul_rgba, cv2.merge([a8, a8, a8, a8]), scale=1.0 / 255.0)


class PlaneDepth:
    """Depth of a plane (world z = 0 by default) on a camera's pixels, for plane occlusion.

    The normalised rays of every (distorted) pixel are computed once per camera; per frame the plane's
    depth over a crop is one dot product per pixel. Metres in the camera frame; 0 where the ray misses.
    """

    def __init__(self, camera):
        xs, ys = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
        pts = np.stack([xs, ys], axis=-1).reshape(-1, 1, 2)
        und = cv2.undistortPoints(pts, camera.K, camera.dist).reshape(camera.height, camera.width, 2)
        self.rays = und.astype(np.float32)
        self.size = (camera.width, camera.height)

    def depth(self, camera_from_world: np.ndarray, x0: int, y0: int, w: int, h: int,
              world_normal=(0.0, 0.0, 1.0), world_point=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Plane depth (h, w) float32 over the crop (x0, y0, w, h): z of where each pixel's ray meets the
        plane through `world_point` with normal `world_normal`; 0 where it meets it behind the camera."""
        T = np.asarray(camera_from_world, np.float64)
        n = T[:3, :3] @ np.asarray(world_normal, np.float64)
        p = T[:3, :3] @ np.asarray(world_point, np.float64) + T[:3, 3]
        r = self.rays[y0:y0 + h, x0:x0 + w]
        denom = r[..., 0] * np.float32(n[0]) + r[..., 1] * np.float32(n[1]) + np.float32(n[2])
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.float32(n @ p) / denom
        z[~(z > 0) | ~np.isfinite(z)] = 0.0
        return z.astype(np.float32)


class Occluder:
    """What `OverlayRenderer.draw(..., occlusion=)` calls on each composited crop: `(crop, x0, y0, model_z)`
    -> the crop with the occluded pixels faded out.

    mode "depth": `depth` is the frame's measured depth (float32 metres, 0 = none, on the image's pixels).
    mode "plane": `plane` (a PlaneDepth for the camera) and `camera_from_world` give the table's depth.
    `last_alpha` keeps the alpha of the last crop (with `last_origin`), for measurements and tests.
    """

    def __init__(self, mode: str, depth: np.ndarray | None = None, plane: PlaneDepth | None = None,
                 camera_from_world: np.ndarray | None = None, params: OcclusionParams = DEFAULT_PARAMS):
        self.mode = check_mode(mode)
        if mode == "depth" and depth is None:
            raise ValueError("depth occlusion needs the frame's depth")
        if mode == "plane" and (plane is None or camera_from_world is None):
            raise ValueError("plane occlusion needs a PlaneDepth and camera_from_world")
        self.depth, self.plane, self.camera_from_world, self.params = depth, plane, camera_from_world, params
        self.last_alpha: np.ndarray | None = None
        self.last_origin = (0, 0)

    def alpha(self, x0: int, y0: int, model_z: np.ndarray) -> np.ndarray:
        """Alpha (h, w) of the model over the crop at (x0, y0) whose depth is `model_z`."""
        h, w = model_z.shape
        p = self.params
        if self.mode == "depth":
            window, (ox, oy) = scene_window(self.depth, x0, y0, w, h, p.margin_px)
            scene = prepare_scene(window, p)[oy:oy + h, ox:ox + w]
            return visibility(model_z, scene, p)
        if self.mode == "plane":
            scene = self.plane.depth(self.camera_from_world, x0, y0, w, h)
            return visibility(model_z, scene, p, tolerance_m=p.plane_tolerance_m, noise_per_m2=0.0)
        return np.ones((h, w), np.float32)

    def __call__(self, crop: np.ndarray, x0: int, y0: int, model_z: np.ndarray | None) -> np.ndarray:
        if self.mode == "off" or model_z is None:
            return crop
        a = self.alpha(x0, y0, model_z)
        self.last_alpha, self.last_origin = a, (x0, y0)
        return apply_alpha(crop, a)


def read_model_depth(renderer, ss_size: tuple[int, int], crop, out_crop, near: float, far: float):
    """The depth buffer of the crop just drawn by `renderer` (an OverlayRenderer, called from its
    _render_crop_gl right after the colour read-back): (model_z, x0, y0), model_z float32 (h, w) OpenCV z in
    the camera's units, +inf where nothing was drawn, on the output (distorted) pixels of the colour crop.

    Supersampled buffers keep the nearest sample of each output pixel; multisampled ones are resolved by a
    nearest blit (GL allows no other for depth); lens distortion is applied by the colour crop's remap
    table, nearest-neighbour."""
    GL = renderer.GL
    sw, sh = ss_size
    w, h = crop[2], crop[3]
    if renderer._framebuffers.resolve is not None:
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, renderer._framebuffers.fbo[0])
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, renderer._framebuffers.resolve[0])
        GL.glDisable(GL.GL_SCISSOR_TEST)
        GL.glBlitFramebuffer(0, 0, sw, sh, 0, 0, sw, sh, GL.GL_DEPTH_BUFFER_BIT, GL.GL_NEAREST)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, renderer._framebuffers.resolve[0])
    else:
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, renderer._framebuffers.fbo[0])
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 4)
    buf = np.empty((sh, sw), np.float32)
    GL.glReadPixels(0, 0, sw, sh, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT, buf)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
    z = ndc_to_z(buf, near, far)
    if (sw, sh) != (w, h):
        k = sw // w
        if k * w == sw and k * h == sh:
            z = z.reshape(h, k, w, k).min(axis=(1, 3))  # the nearest sample of each output pixel
        else:
            z = cv2.resize(z, (w, h), interpolation=cv2.INTER_NEAREST)
    if not renderer._distorted:
        return z, crop[0], crop[1]
    ox, oy, ow, oh = out_crop
    mx, my = renderer._maps
    mxs = mx[oy:oy + oh, ox:ox + ow] - np.float32(crop[0])
    mys = my[oy:oy + oh, ox:ox + ow] - np.float32(crop[1])
    zf = cv2.remap(z, mxs, mys, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=float("inf"))
    return zf, ox, oy


def ndc_to_z(buf: np.ndarray, near: float, far: float) -> np.ndarray:
    """OpenCV camera z from a GL depth buffer (0..1 window depth of gl_projection's perspective): +inf where
    the buffer holds the clear value 1 (nothing drawn)."""
    zn = buf * np.float32(2.0) - np.float32(1.0)
    with np.errstate(divide="ignore"):
        z = np.float32(2.0 * far * near) / (np.float32(far + near) - zn * np.float32(far - near))
    z[buf >= 1.0] = np.inf
    return z.astype(np.float32)
