"""OverlayRenderer: draws a model (trimesh) and line sets over camera frames, registered to the pixel.

Pipeline per frame (only the pose changes; meshes and line sets stay on the GPU):
1. Bound what is drawn (mesh convex hull, line-set boxes, shadow quad) in the camera; fit near/far.
2. Project the bound to a pixel crop of the undistorted image; render only that crop, anti-aliased
   (2x2 supersampling on a CPU rasteriser, MSAA on a GPU), premultiplied alpha; read the crop back.
3. With lens distortion, warp the crop into the distorted image through a cached remap table
   (Camera.distort_maps(), computed faster by projection.distort_maps_fast), only over the crop's
   distorted footprint.
4. draw(): composite the crop over the frame (premultiplied "over"), nothing outside it touched.

Frames: `camera_from_model` is a 4x4 from model coordinates (model units, any scale folded in) to
the OpenCV camera frame (x right, y down, z forward). The anchor plane is z = 0 of the model frame.
"""

from __future__ import annotations

from collections import OrderedDict

import cv2
import numpy as np
import trimesh

from arapp.render import composite, modes, occlusion as occlusion_mod, projection
from arapp.render.framebuffers import FBO_STEP, CropFramebuffers
from arapp.render.gpu import GpuLines, GpuMesh, box_corners
from arapp.render.gpu_cache import GpuCache
from arapp.render.gl import RendererError, create_context, release_context
from tracking.camera import Camera
from tracking.errors import CalibrationError




def _same_key(a, b) -> bool:
    """Memo keys are equal: objects (mesh, line sets) by identity, everything else by value."""
    if a is None or b is None or len(a) != len(b):
        return False
    if a[0] is not b[0] or len(a[6]) != len(b[6]) or any(x is not y for x, y in zip(a[6], b[6])):
        return False
    return a[1:6] == b[1:6]


class OverlayRenderer:
    """Offscreen renderer of overlays for one camera (intrinsics K, distortion, image size).

    Holds a GL context (EGL, or OSMesa as fallback; see arapp.render.gl), its shader programs,
    framebuffers and the GPU copies of the meshes and line sets it has drawn. Not thread-safe:
    use one renderer per thread. Release with close() (or use it as a context manager).
    """

    def __init__(self, K, dist, width: int, height: int, antialias: str = "auto", samples: int = 4,
                 supersample: float = 2.0):
        """K 3x3, dist OpenCV coefficients (None or zeros: none), image size in pixels.

        antialias: "msaa" (multisampling, `samples` per pixel: cheap on GPUs), "ssaa" (rendering at
        `supersample` times the resolution per axis, then an exact area downsample: cheaper than MSAA on
        Mesa's llvmpipe CPU rasteriser), "none", or "auto" (ssaa on a software rasteriser, msaa otherwise).
        """
        if antialias not in ("auto", "msaa", "ssaa", "none"):
            raise RendererError(f"antialias must be 'auto', 'msaa', 'ssaa' or 'none', got {antialias!r}")
        try:
            self.camera = Camera(K, dist, width, height)
        except CalibrationError as e:
            raise RendererError(f"OverlayRenderer: {e}") from None
        self.width, self.height = self.camera.width, self.camera.height
        self.K = self.camera.K
        self._distorted = self.camera.has_distortion
        if self._distorted:
            self._maps = projection.distort_maps_fast(self.camera)  # = Camera.distort_maps(), much faster
            self._und_limits = self._undistorted_limits()
        else:
            self._maps = None
            self._und_limits = (0, 0, self.width, self.height)
        if not 1.0 <= float(supersample) <= 4.0:
            raise RendererError(f"supersample must be within 1..4, got {supersample}")
        self._antialias_request, self._samples_request = antialias, samples
        self._supersample = float(supersample)
        self._closed = True  # until the GL side exists
        self._init_gl()
        self._closed = False

    def _init_gl(self) -> None:
        """Create the context, programs and framebuffers (again after a lost context); caches start empty."""
        self._platform, self.platform_name = create_context(self.width, self.height)
        from OpenGL import GL  # bound to the platform chosen by create_context

        self.GL = GL
        from arapp.render import programs  # imports OpenGL.GL: only after create_context chose the platform

        self._surface_prog = programs.build_program(programs.SURFACE_VS, programs.SURFACE_FS)
        self._line_prog = programs.build_program(programs.LINE_VS, programs.FLAT_FS, programs.LINE_GS)
        self._shadow_prog = programs.build_program(programs.SHADOW_VS, programs.SHADOW_FS)
        self.gl_renderer = GL.glGetString(GL.GL_RENDERER).decode(errors="replace")
        antialias = self._antialias_request
        software = any(k in self.gl_renderer.lower() for k in ("llvmpipe", "softpipe", "swrast", "software"))
        self._software = software
        if antialias == "auto":
            antialias = "ssaa" if software else "msaa"
        self.antialias = antialias
        max_samples = int(GL.glGetIntegerv(GL.GL_MAX_SAMPLES))
        self.samples = max(0, min(int(self._samples_request), max_samples)) if antialias == "msaa" else 0
        self.ss = float(self._supersample) if antialias == "ssaa" else 1.0
        self.cull = True  # back-face culling of closed meshes (switchable for comparisons)
        # sized to the crop on each draw (see CropFramebuffers.fit): a framebuffer much larger than what is
        # drawn costs a CPU rasteriser per frame (clearing, binning) even outside the scissor box
        self._framebuffers = CropFramebuffers(GL, self.samples, self.ss, software, self._und_limits,
                                              min(self.width, 8 * FBO_STEP), min(self.height, 8 * FBO_STEP))
        self._readback = None  # reused read-back buffer of the supersampled crop
        self._memo = None  # (key, last crop): see _render_crop
        # what the last draw() composited: (premultiplied RGBA crop, x0, y0 in frame pixels), None for nothing
        # (the live view composites the same crop again onto its picture scaled to the window)
        self.last_crop = None
        self._read_depth, self._last_depth = False, None  # the model's depth, read once an occlusion asks
        self._lines_cache: OrderedDict[tuple, tuple] = OrderedDict()  # see _collect_lines
        self._gpu = GpuCache(GL)
        self._meshes, self._linesets = self._gpu.meshes, self._gpu.linesets  # the cache's, for inspection

    def _make_current(self) -> None:
        """Make this renderer's context current, rebuilding it if it was lost.

        A lost context happens when other code in the process terminates the shared EGL display:
        pyrender's OffscreenRenderer.delete() (also run by its __del__) does that.
        """
        try:
            self._platform.make_current()
            return
        except Exception:  # noqa: BLE001 - EGLError / AssertionError from pyrender's platform
            pass
        try:
            self._init_gl()
        except RendererError as e:
            raise RendererError(f"the OpenGL context was lost and could not be recreated: {e}") from e

    # -- public API --------------------------------------------------------------------------
    def render(self, mesh, camera_from_model, mode: str = "shaded", lines=None, color=None,
               line_sets=None, shadow: bool = False) -> np.ndarray:
        """The overlay alone: (H, W, 4) uint8 straight (non-premultiplied) RGBA, distortion applied.

        mesh: trimesh.Trimesh in model units, or None (line sets only).
        camera_from_model: 4x4, model frame -> OpenCV camera frame (scale included).
        mode: "shaded", "wireframe", "isolines", "translucent" (see arapp.render.modes).
        lines: polylines (k, 3) in the model frame drawn as isolines/control net in `modes.ISOLINE_COLOR`,
            or a list of (polyline, rgba) pairs, drawn in any mode.
        color: surface RGBA (0..1 floats or 0..255 ints); its alpha multiplies the mode's opacity.
        line_sets: list of modes.LineSet or (polylines, rgba[, width_px[, hidden_alpha]]) tuples.
        shadow: draw a soft contact shadow of the mesh on the anchor plane z = 0.
        """
        out = np.zeros((self.height, self.width, 4), np.uint8)
        res = self._render_crop(mesh, camera_from_model, mode, lines, color, line_sets, shadow)
        if res is not None:
            crop, x0, y0 = res
            out[y0:y0 + crop.shape[0], x0:x0 + crop.shape[1]] = composite.unpremultiply(crop)
        return out

    def draw(self, frame_bgr: np.ndarray, mesh, camera_from_model, mode: str = "shaded", lines=None,
             color=None, line_sets=None, shadow: bool = False, inplace: bool = False,
             occlusion=None) -> np.ndarray:
        """`frame_bgr` (H, W, 3) uint8 with the overlay composited on it (a copy unless inplace=True).

        Arguments as render(). Pixels outside the overlay's footprint are returned unchanged.
        occlusion: None, or a callable (crop, x0, y0, model_z) -> crop (arapp.render.occlusion.Occluder) that
        fades out the pixels of the premultiplied crop hidden by the scene, given the model's depth.
        """
        frame = np.asarray(frame_bgr)
        if frame.shape != (self.height, self.width, 3) or frame.dtype != np.uint8:
            raise RendererError(
                f"draw(): frame must be ({self.height}, {self.width}, 3) uint8 BGR for this renderer, "
                f"got {frame.shape} {frame.dtype}; resize it or build the renderer with Camera.scaled()"
            )
        out = frame if inplace else frame.copy()
        if occlusion is not None and not self._read_depth:
            self._read_depth, self._memo = True, None  # from now on every render reads its depth back
        res = self._render_crop(mesh, camera_from_model, mode, lines, color, line_sets, shadow)
        self.last_crop = None
        if res is not None:
            crop, x0, y0 = res
            if occlusion is not None and self._last_depth is not None:
                crop = occlusion(crop, x0, y0, self._last_depth[0])
            composite.over_bgr(out, crop, x0, y0)
            self.last_crop = (crop, x0, y0)
        return out

    def draw_lines(self, frame_bgr: np.ndarray, line_sets, camera_from_model, inplace: bool = False) -> np.ndarray:
        """`frame_bgr` with only line sets drawn (e.g. sliced toolpaths in bed millimetres): draw(frame, None, ...)."""
        return self.draw(frame_bgr, None, camera_from_model, line_sets=line_sets, inplace=inplace)

    def close(self) -> None:
        """Free the GPU objects and the GL context."""
        if getattr(self, "_closed", True):
            return
        self._closed = True
        try:
            self._platform.make_current()
        except Exception:  # noqa: BLE001 - context already lost (see _make_current): nothing left to free
            self._gpu.clear()
            return
        try:
            self._gpu.delete_all()
            self._framebuffers.free()
            for prog, _ in (self._surface_prog, self._line_prog, self._shadow_prog):
                self.GL.glDeleteProgram(prog)
        finally:
            release_context(self._platform, self.platform_name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown: GL may already be gone
            pass

    # -- setup -------------------------------------------------------------------------------
    def _undistorted_limits(self) -> tuple[int, int, int, int]:
        """Pixel rectangle of the undistorted image plane that the distorted image sees (from the map),
        bounded to one image size beyond each edge (strong fisheye corners are cut there)."""
        mx, my = self._maps
        fin = np.isfinite(mx) & np.isfinite(my)
        W, H = self.width, self.height
        x0 = int(np.floor(max(mx[fin].min(), -W))) - 2
        y0 = int(np.floor(max(my[fin].min(), -H))) - 2
        x1 = int(np.ceil(min(mx[fin].max(), 2 * W))) + 2
        y1 = int(np.ceil(min(my[fin].max(), 2 * H))) + 2
        return x0, y0, x1 - x0 + 1, y1 - y0 + 1

    # -- caches ------------------------------------------------------------------------------
    def _gpu_mesh(self, mesh) -> GpuMesh:
        """The cached GPU copy of `mesh` (see GpuCache.mesh)."""
        return self._gpu.mesh(mesh)

    def _gpu_lineset(self, ls: modes.LineSet, persistent: bool) -> GpuLines:
        """The GPU copy of `ls` (see GpuCache.lineset)."""
        return self._gpu.lineset(ls, persistent)

    # -- frame -------------------------------------------------------------------------------
    def _collect_lines(self, mode, lines, line_sets):
        """[(LineSet, persistent)] to draw: the `lines` argument first, then `line_sets`.

        `lines` given as the same arrays frame after frame map to the same cached LineSets (keyed by the
        arrays' identities, which the cache keeps alive), so they are uploaded once; arrays edited in
        place are not noticed: pass new arrays (or a new LineSet) when the lines change.
        """
        out = []
        if lines is not None and len(lines) > 0:
            if isinstance(lines, modes.LineSet):
                out.append((lines, True))
            else:
                out += [(ls, True) for ls in self._lines_as_sets(mode, lines)]
        for item in line_sets or ():
            ls = modes.as_line_set(item)
            out.append((ls, ls is item))
        return out

    def _lines_as_sets(self, mode, lines) -> list:
        hidden = 0.0 if mode == "shaded" else 0.3  # see-through modes show hidden lines dimmed
        key_parts = []
        for item in lines:
            if isinstance(item, (tuple, list)) and len(item) == 2 and np.ndim(item[0]) == 2:
                key_parts.append((id(item[0]), modes.parse_rgba(item[1])))
            else:
                key_parts.append(id(item))
        key = (hidden, tuple(key_parts))
        hit = self._lines_cache.get(key)
        if hit is not None:
            self._lines_cache.move_to_end(key)
            return hit[1]
        plain, coloured = [], {}
        for item, part in zip(lines, key_parts):
            if isinstance(part, tuple):
                coloured.setdefault(part[1], []).append(item[0])
            else:
                plain.append(item)
        sets = []
        if plain:
            sets.append(modes.LineSet(plain, modes.ISOLINE_COLOR, 2.0, hidden))
        for rgba, pls in coloured.items():
            sets.append(modes.LineSet(pls, rgba, 2.0, hidden))
        keep = [item[0] if isinstance(part, tuple) else item for item, part in zip(lines, key_parts)]
        self._lines_cache[key] = (keep, sets)  # holding the arrays keeps their ids from being reused
        while len(self._lines_cache) > 8:
            self._lines_cache.popitem(last=False)
        return sets

    def _render_crop(self, mesh, camera_from_model, mode, lines, color, line_sets, shadow):
        """Premultiplied RGBA crop of the distorted image and its top-left (x0, y0), or None if nothing shows."""
        if self._closed:
            raise RendererError("OverlayRenderer is closed")
        if mode not in modes.MODES:
            raise ValueError(f"unknown display mode {mode!r}; choose one of {', '.join(modes.MODES)}")
        T = np.asarray(camera_from_model, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"camera_from_model must be a finite 4x4 matrix, got shape {T.shape}")
        rgba = modes.parse_rgba(color)
        if mesh is not None and not isinstance(mesh, trimesh.Trimesh):
            raise ValueError(
                f"mesh must be a trimesh.Trimesh (got {type(mesh).__name__}); "
                "for a trimesh.Scene pass scene.dump(concatenate=True)"
            )
        line_list = self._collect_lines(mode, lines, line_sets)
        # render only what changed: the same mesh data, pose and arguments give the last crop again
        memo_key = None
        if all(persistent for _, persistent in line_list):
            memo_key = (mesh, None if mesh is None else hash(mesh), T.tobytes(), mode, rgba, bool(shadow),
                        tuple(ls for ls, _ in line_list))
            last = self._memo
            if last is not None and _same_key(last[0], memo_key):
                return last[1]
        result = self._render_crop_gl(mesh, T, mode, line_list, color, rgba, shadow)
        self._memo = (memo_key, result) if memo_key is not None else None
        return result

    def _render_crop_gl(self, mesh, T, mode, line_list, color, rgba, shadow):
        """Draw one frame's crop on the GPU: the steps of the module docstring, in order."""
        self._make_current()
        gmesh, line_items, shadow_quad = self._upload(mesh, mode, line_list, color, rgba, shadow)
        # 1. bounds of everything drawn, near/far
        fit = self._fit_depth(T, gmesh, line_items, shadow_quad)
        if fit is None:
            return None
        near, far, pc = fit
        # 2. pixel crop in the undistorted image, then in the output image
        crops = self._fit_crop(pc, near, line_items)
        if crops is None:
            return None
        crop, out_crop = crops
        w, h = crop[2], crop[3]
        # 3. draw; with supersampling the same crop (same P) is drawn into ss times as many pixels
        P = projection.gl_projection(self.K, crop, near, far)
        MV = projection.gl_view(T)
        sw, sh = int(round(w * self.ss)), int(round(h * self.ss))
        self._begin_frame(sw, sh)
        mv32 = np.ascontiguousarray(MV, np.float32)
        p32 = np.ascontiguousarray(P, np.float32)
        if shadow_quad is not None:
            self._draw_shadow(shadow_quad, mv32, p32)
        if gmesh is not None:
            # culling is exact only when the whole mesh is in front of the near plane: a camera inside
            # the mesh, or a near plane cutting it, must see the inner (back) faces
            hull_z = gmesh.hull @ T[2, :3] + T[2, 3]
            cull = self.cull and gmesh.closed and bool(hull_z.min() > near)
            self._draw_surface(gmesh, MV, mv32, p32, rgba, modes.SURFACE_ALPHA[mode] * rgba[3], cull)
        if line_items:
            self._draw_lines(line_items, mv32, p32, (sw, sh), near, (w, h), self._stack_ranges(line_items, T, near))
        # 4. read back (resolve MSAA first), downsample, distort
        buf = self._read_back(sw, sh, w, h)
        if self._read_depth:  # for occlusion: the model's depth on the same pixels as the crop
            self._last_depth = occlusion_mod.read_model_depth(self, (sw, sh), crop, out_crop, near, far)
        if (sw, sh) != (w, h):
            # exact area-weighted downsample (premultiplied, so colours average correctly)
            buf = cv2.resize(buf, (w, h), interpolation=cv2.INTER_AREA)
        return self._distort(buf, crop, out_crop)

    def _upload(self, mesh, mode, line_list, color, rgba, shadow):
        """The GPU copies drawn this frame: (GpuMesh or None, [(LineSet, GpuLines)], shadow quad or None).

        In wireframe mode the mesh's edges come first among the line sets."""
        gmesh = self._gpu_mesh(mesh) if mesh is not None else None
        line_items = [
            (ls, self._gpu_lineset(ls, persistent))
            for ls, persistent in line_list
        ]
        self._gpu.trim_linesets({id(ls) for ls, persistent in line_list if persistent})
        if gmesh is not None and mode == "wireframe":
            edge_set = modes.LineSet([], modes.WIRE_COLOR if color is None else rgba[:3] + (1.0,), 1.0, 0.0)
            line_items.insert(0, (edge_set, gmesh.edge_lines()))
        shadow_quad = gmesh.shadow_quad() if (gmesh is not None and shadow) else None
        return gmesh, line_items, shadow_quad

    @staticmethod
    def _fit_depth(T, gmesh, line_items, shadow_quad):
        """(near, far, bound points in the camera frame (n, 3)) of everything drawn, or None when nothing
        is drawn or all of it is behind the camera."""
        pts, los, his = [], [], []
        if gmesh is not None:
            pts.append(gmesh.hull)
            los.append(gmesh.lo)
            his.append(gmesh.hi)
        for _, g in line_items:
            if g.buffer is not None:
                pts.append(box_corners(g.lo, g.hi))
                los.append(g.lo)
                his.append(g.hi)
        if shadow_quad is not None:
            pts.append(shadow_quad[2])
            los.append(shadow_quad[2].min(axis=0))
            his.append(shadow_quad[2].max(axis=0))
        if not pts:
            return None
        lo, hi = np.min(los, axis=0), np.max(his, axis=0)
        center, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)
        cam_center = T[:3, :3] @ center + T[:3, 3]
        scale = float(np.cbrt(abs(np.linalg.det(T[:3, :3])))) or 1.0
        min_near = 1e-3 * max(radius * scale, 1e-9)
        near, far = projection.near_far(T, center, radius, min_near)
        if cam_center[2] + radius * scale < min_near:
            return None  # entirely behind the camera
        pc = np.concatenate(pts) @ T[:3, :3].T + T[:3, 3]
        return near, far, pc

    def _fit_crop(self, pc, near, line_items):
        """(crop in the undistorted image, crop in the output image), each (x0, y0, w, h) pixels, or None
        when nothing shows; the framebuffers are fitted to the first (which they may cut)."""
        bounds = projection.pixel_bounds(pc, self.K, near)
        if bounds is None:
            return None
        max_width = max([ls.width_px for ls, _ in line_items] + [1.0])
        pad = int(np.ceil(max_width / 2)) + 2
        crop = projection.crop_from_bounds(bounds, self._und_limits, pad)
        if crop is None:
            return None
        if self._distorted:
            out_crop = projection.crop_from_bounds(
                projection.distorted_bounds(crop, self.K, self.camera.dist), (0, 0, self.width, self.height), 1
            )
            if out_crop is None:
                return None
        else:
            out_crop = crop
        w, h = self._framebuffers.fit(crop[2], crop[3])
        return (crop[0], crop[1], w, h), out_crop

    def _begin_frame(self, sw: int, sh: int) -> None:
        """Bind the framebuffer, clear it and set the GL state every draw starts from."""
        GL = self.GL
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._framebuffers.fbo[0])
        GL.glViewport(0, 0, sw, sh)
        # the framebuffers are sized to the crop (CropFramebuffers.fit), so the whole of them is cleared: a
        # scissored clear is drawn as a quad through the fragment pipeline, a full one is a plain fill
        GL.glDisable(GL.GL_SCISSOR_TEST)
        GL.glClearColor(0.0, 0.0, 0.0, 0.0)
        GL.glClearDepth(1.0)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glColorMask(GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        GL.glScissor(0, 0, sw, sh)  # draw only into the crop
        GL.glEnable(GL.GL_SCISSOR_TEST)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDisable(GL.GL_CULL_FACE)
        GL.glEnable(GL.GL_BLEND)
        GL.glBlendFunc(GL.GL_ONE, GL.GL_ONE_MINUS_SRC_ALPHA)
        if self.samples > 0:
            GL.glEnable(GL.GL_MULTISAMPLE)

    def _draw_shadow(self, shadow_quad, mv32, p32) -> None:
        """The soft contact shadow: a textured quad on z = 0, blended without writing depth."""
        GL = self.GL
        prog, u = self._shadow_prog
        GL.glUseProgram(prog)
        GL.glUniformMatrix4fv(u["u_mv"], 1, GL.GL_TRUE, mv32)
        GL.glUniformMatrix4fv(u["u_proj"], 1, GL.GL_TRUE, p32)
        GL.glUniform1f(u["u_opacity"], 0.45)
        GL.glActiveTexture(GL.GL_TEXTURE0)
        GL.glBindTexture(GL.GL_TEXTURE_2D, shadow_quad[1])
        GL.glUniform1i(u["u_tex"], 0)
        GL.glDepthMask(GL.GL_FALSE)
        GL.glDepthFunc(GL.GL_LEQUAL)
        shadow_quad[0].draw(GL.GL_TRIANGLES)
        GL.glDepthMask(GL.GL_TRUE)

    def _read_back(self, sw: int, sh: int, w: int, h: int) -> np.ndarray:
        """The drawn (sh, sw, 4) premultiplied RGBA, MSAA resolved first. Supersampled (sw, sh) != (w, h):
        a view of a reused buffer (to be downsampled); else a new array (returned and memoised as it is)."""
        GL = self.GL
        fb = self._framebuffers
        if fb.resolve is not None:
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fb.fbo[0])
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb.resolve[0])
            GL.glDisable(GL.GL_SCISSOR_TEST)
            GL.glBlitFramebuffer(0, 0, sw, sh, 0, 0, sw, sh, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fb.resolve[0])
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        if (sw, sh) != (w, h):
            rb = self._readback
            if rb is None or rb.size < sw * sh * 4:
                rb = self._readback = np.empty(sw * sh * 4, np.uint8)
            buf = rb[:sw * sh * 4].reshape(sh, sw, 4)
        else:
            buf = np.empty((sh, sw, 4), np.uint8)
        GL.glReadPixels(0, 0, sw, sh, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE, buf)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        return buf

    def _distort(self, buf, crop, out_crop):
        """(crop, x0, y0) in the output image: `buf` as it is, or warped through the lens distortion."""
        if not self._distorted:
            # the crop lies inside the image (the undistorted limits are the image)
            return buf, crop[0], crop[1]
        ox, oy, ow, oh = out_crop
        mx, my = self._maps
        warped = composite.warp_crop(buf, (mx[oy:oy + oh, ox:ox + ow], my[oy:oy + oh, ox:ox + ow]), crop[:2])
        return warped, ox, oy

    def _draw_surface(self, g: GpuMesh, MV, mv32, p32, rgba, alpha, cull):
        GL = self.GL
        prog, u = self._surface_prog
        GL.glUseProgram(prog)
        GL.glUniformMatrix4fv(u["u_mv"], 1, GL.GL_TRUE, mv32)
        GL.glUniformMatrix4fv(u["u_proj"], 1, GL.GL_TRUE, p32)
        nmat = np.linalg.inv(MV[:3, :3]).T
        GL.glUniformMatrix3fv(u["u_nmat"], 1, GL.GL_TRUE, np.ascontiguousarray(nmat, np.float32))
        GL.glUniform1f(u["u_ambient"], 0.35)
        GL.glUniform4f(u["u_color"], rgba[0], rgba[1], rgba[2], alpha)
        # pushed back a little so lines lying on the surface (edges, isolines) win the depth test
        GL.glEnable(GL.GL_POLYGON_OFFSET_FILL)
        GL.glPolygonOffset(1.0, 2.0)
        if cull:
            GL.glEnable(GL.GL_CULL_FACE)
            GL.glFrontFace(GL.GL_CW)  # the projection mirrors y (see projection.gl_projection)
            GL.glCullFace(GL.GL_BACK)
        if alpha >= 1.0:
            GL.glDepthFunc(GL.GL_LESS)
            # opaque: "over" with alpha 1 writes the source unchanged, so blending (reading the colour
            # buffer back per fragment) is switched off, the same pixels for less rasteriser work
            GL.glDisable(GL.GL_BLEND)
            g.surface.draw(GL.GL_TRIANGLES)
            GL.glEnable(GL.GL_BLEND)
        else:
            # depth pre-pass, then colour of the nearest layer only: order-independent translucency
            GL.glDepthFunc(GL.GL_LESS)
            GL.glColorMask(GL.GL_FALSE, GL.GL_FALSE, GL.GL_FALSE, GL.GL_FALSE)
            g.surface.draw(GL.GL_TRIANGLES)
            GL.glColorMask(GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE, GL.GL_TRUE)
            GL.glDepthFunc(GL.GL_LEQUAL)
            GL.glDepthMask(GL.GL_FALSE)
            g.surface.draw(GL.GL_TRIANGLES)
            GL.glDepthMask(GL.GL_TRUE)
        GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)
        GL.glDisable(GL.GL_CULL_FACE)

    def _stack_ranges(self, items, T, near) -> dict:
        """{id(LineSet): (firsts, counts)} for the layer stacks (LineSet.layer_starts) of which only every k-th
        layer is needed at this pose: layers nearer on screen than modes.layer_stride allows look the same."""
        out = {}
        scale = float(np.cbrt(abs(np.linalg.det(T[:3, :3])))) or 1.0
        f = float(min(self.K[0, 0], self.K[1, 1]))
        for ls, g in items:
            if ls.layer_starts is None or not ls.layer_pitch > 0 or g.buffer is None or len(ls.layer_starts) < 2:
                continue
            z = box_corners(g.lo, g.hi) @ T[2, :3] + T[2, 3]
            pitch_px = ls.layer_pitch * scale * f / max(float(z.min()), near)
            stride = modes.layer_stride(pitch_px, ls.width_px)
            if stride > 1:
                out[id(ls)] = modes.layer_ranges(ls.layer_starts, g.buffer.count // 2, stride)
        return out

    def _draw_lines(self, items, mv32, p32, size, near, size_out, ranges=None):
        GL = self.GL
        prog, u = self._line_prog
        GL.glUseProgram(prog)
        GL.glUniformMatrix4fv(u["u_mv"], 1, GL.GL_TRUE, mv32)
        GL.glUniformMatrix4fv(u["u_proj"], 1, GL.GL_TRUE, p32)
        GL.glUniform2f(u["u_viewport"], float(size[0]), float(size[1]))
        GL.glUniform1f(u["u_near"], float(near))

        def pass_(depth_func, alpha_of, write_depth):
            GL.glDepthFunc(depth_func)
            GL.glDepthMask(GL.GL_TRUE if write_depth else GL.GL_FALSE)
            for ls, g in items:
                a = ls.rgba[3] * alpha_of(ls)
                if g.buffer is None or a <= 0:
                    continue
                GL.glUniform4f(u["u_color"], ls.rgba[0] * a, ls.rgba[1] * a, ls.rgba[2] * a, a)
                GL.glUniform1f(u["u_width"], ls.width_px * size[0] / size_out[0])
                r = (ranges or {}).get(id(ls))
                if r is None:
                    g.buffer.draw(GL.GL_LINES)
                else:
                    g.buffer.draw_ranges(GL.GL_LINES, *r)
            GL.glDepthMask(GL.GL_TRUE)

        # parts behind the surface first (dimmed), then the visible parts, which also occlude each other
        pass_(GL.GL_GREATER, lambda ls: ls.hidden_alpha, False)
        pass_(GL.GL_LEQUAL, lambda ls: 1.0, True)
        self._gpu.free_transient(items)
