"""The overlay renderer's offscreen framebuffers, sized to the crop it draws.

One colour + depth framebuffer (multisampled with MSAA), plus a single-sample one to resolve MSAA into
before reading back. Sizes are in output pixels; with supersampling the buffers hold `ss` times that per
axis. They belong to the GL context current when they were made (the renderer's).
"""

from __future__ import annotations

import numpy as np

from arapp.render.gl import RendererError

#: framebuffers are sized to the crop, rounded up to this many output pixels per axis, so that a model
#: moving a little does not reallocate them every frame
FBO_STEP = 16


class CropFramebuffers:
    """The framebuffer drawn into (`fbo`) and the MSAA resolve target (`resolve`, None without MSAA),
    each (framebuffer id, [colour, depth renderbuffer ids])."""

    def __init__(self, GL, samples: int, ss: float, software: bool, und_limits, w: int, h: int):
        """samples: MSAA samples (0: none); ss: supersampling factor per axis; software: a CPU
        rasteriser (see fit()); und_limits: (x0, y0, w, h) of the undistorted image plane seen, which
        bounds the largest crop; w, h: first size in output pixels."""
        self.GL = GL
        self.samples, self.ss, self.software = samples, ss, software
        self.und_limits = und_limits
        self.fbo = self.resolve = None
        self.size = (0, 0)
        self.max = 0
        self.alloc(w, h)

    def alloc(self, w: int, h: int) -> None:
        """(Re)allocate both framebuffers for a w x h crop in output pixels (cut at the GL limit)."""
        GL = self.GL
        self.free()
        max_rb = int(int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE)) / self.ss)
        w, h = min(w, max_rb), min(h, max_rb)
        self.max = max_rb
        self.size = (w, h)  # in output pixels; the buffers hold ss times that
        w, h = int(np.ceil(w * self.ss)), int(np.ceil(h * self.ss))
        self.fbo = _framebuffer(GL, self.samples, w, h)
        self.resolve = _framebuffer(GL, 0, w, h) if self.samples > 0 else None
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)

    def fit(self, w: int, h: int) -> tuple[int, int]:
        """Make the framebuffers hold a w x h crop (output pixels) without being much larger; returns
        the crop size they hold (smaller only beyond the GL renderbuffer limit).

        Each frame clears the whole framebuffers (see OverlayRenderer._render_crop_gl), which on a CPU
        rasteriser costs in proportion to their area, and reallocating them costs little (measured on
        llvmpipe with the bench's 720p torus: a framebuffer fitted to every crop anew beat one with 1.5x
        room per axis). So there they grow to 5 % beyond the crop and shrink once they hold 1.5 times its
        area. On a GPU clearing is nearly free and a reallocation may stall the driver: 1.5x room, shrink
        at 4x the area.
        """
        room, shrink = (1.05, 1.5) if self.software else (1.5, 4.0)
        fw, fh = self.size
        mx = self.max  # beyond the GL limit the crop is cut, not the framebuffer grown
        too_small = (w > fw and fw < mx) or (h > fh and fh < mx)
        if too_small or fw * fh > shrink * w * h:
            if not too_small:
                fw = fh = 0  # shrinking: size to this crop alone

            def size(n, limit):  # with room, but not beyond the largest possible crop
                n = min(int(n * room), max(limit, n))
                return -(-n // FBO_STEP) * FBO_STEP

            self.alloc(size(max(w, fw), self.und_limits[2]), size(max(h, fh), self.und_limits[3]))
            fw, fh = self.size
        return min(w, fw), min(h, fh)

    def free(self) -> None:
        """Delete both framebuffers and their renderbuffers."""
        GL = self.GL
        for f in (self.fbo, self.resolve):
            if f is not None:
                GL.glDeleteFramebuffers(1, [f[0]])
                GL.glDeleteRenderbuffers(2, f[1])
        self.fbo = self.resolve = None


def _framebuffer(GL, samples: int, w: int, h: int):
    """A w x h RGBA8 + depth24 framebuffer with `samples` samples (0: single): (fb, [colour, depth])."""
    fb = GL.glGenFramebuffers(1)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fb)
    color, depth = GL.glGenRenderbuffers(2)
    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, color)
    GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, samples, GL.GL_RGBA8, w, h)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, color)
    GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, depth)
    GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, samples, GL.GL_DEPTH_COMPONENT24, w, h)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, depth)
    status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
    if status != GL.GL_FRAMEBUFFER_COMPLETE:
        raise RendererError(f"offscreen framebuffer {w}x{h} (samples={samples}) incomplete: 0x{int(status):x}")
    return fb, [color, depth]
