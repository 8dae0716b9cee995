"""AR overlay rendering: meshes and line sets drawn over camera frames, registered to the pixel.

    from arapp.render import OverlayRenderer, LineSet
    with OverlayRenderer(K, dist, width, height) as r:      # dist: None/zeros for none
        rgba = r.render(mesh, camera_from_model)              # (H, W, 4) uint8 straight RGBA
        out = r.draw(frame_bgr, mesh, camera_from_model,      # composited copy of the BGR frame
                     mode="isolines", lines=isolines_and_net, shadow=True)
        out = r.draw(frame_bgr, None, camera_from_printer,    # toolpaths only (print preview)
                     line_sets=[LineSet(perimeters, (255, 128, 0), 2.0),
                                LineSet(infill, (0, 200, 255), 1.0),
                                LineSet(travel, (0.5, 0.5, 0.5, 0.5), 1.0, hidden_alpha=0.0)])

- mesh: trimesh.Trimesh in model units (or None); camera_from_model: 4x4 model -> OpenCV camera
  (x right, y down, z forward), scale folded in. The anchor plane is z = 0 of the model frame.
- modes: "shaded", "wireframe", "isolines", "translucent" (modes.py); `color` = surface RGBA.
- lines: polylines (k, 3) in the model frame (or (polyline, rgba) pairs); line_sets: LineSet objects
  or (polylines, rgba[, width_px[, hidden_alpha]]) tuples. Keep LineSet objects alive between frames:
  their GPU copies are cached by object.
- The projection reproduces cv2.projectPoints (pixel centres at integers, skew ignored as OpenCV does);
  lens distortion is applied by warping the render with Camera.distort_maps().
- Meshes stay on the GPU (keyed by object and trimesh's data hash); a frame with the same mesh data,
  pose and arguments as the previous one is not rendered again.
- GL: EGL (headless Mesa, or the GPU driver's EGL on a desktop), OSMesa as fallback (gl.py). PyOpenGL
  binds its platform on first import: importing this package does not import OpenGL, but anything that
  imports OpenGL/pyrender before the first renderer must set PYOPENGL_PLATFORM (or call select_platform()).

See renderer.py for the pipeline, modes.py for display modes and LineSet, gl.py for the GL platform.
"""

from arapp.render.gl import RendererError, select_platform
from arapp.render.modes import MODES, LineSet


def __getattr__(name):
    # OverlayRenderer imports PyOpenGL, which binds its platform on import: defer it until used.
    if name == "OverlayRenderer":
        from arapp.render.renderer import OverlayRenderer

        return OverlayRenderer
    raise AttributeError(name)


__all__ = ["OverlayRenderer", "LineSet", "RendererError", "MODES", "select_platform"]
