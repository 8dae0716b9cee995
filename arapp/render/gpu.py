"""GPU copies of meshes and line sets (vertex arrays and buffers) for the overlay renderer.

All objects belong to the GL context current when they were made; the renderer makes its context
current before creating, drawing or deleting them.
"""

from __future__ import annotations

import ctypes
import weakref

import numpy as np

from arapp.render.shadow import footprint


class Buffer:
    """A VAO with one VBO (and optionally an index buffer): the GPU copy of a mesh or a line set."""

    def __init__(self, GL, vertex_data: np.ndarray, layout: list[int], indices: np.ndarray | None = None):
        self.GL = GL
        data = np.ascontiguousarray(vertex_data, dtype=np.float32)
        self.vao = GL.glGenVertexArrays(1)
        GL.glBindVertexArray(self.vao)
        self.vbo = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, data.nbytes, data, GL.GL_STATIC_DRAW)
        stride = data.shape[1] * 4
        offset = 0
        for loc, n in enumerate(layout):
            GL.glEnableVertexAttribArray(loc)
            GL.glVertexAttribPointer(loc, n, GL.GL_FLOAT, GL.GL_FALSE, stride, ctypes.c_void_p(offset))
            offset += n * 4
        self.ebo = None
        self.count = len(data)
        if indices is not None:
            idx = np.ascontiguousarray(indices, dtype=np.uint32).ravel()
            self.ebo = GL.glGenBuffers(1)
            GL.glBindBuffer(GL.GL_ELEMENT_ARRAY_BUFFER, self.ebo)
            GL.glBufferData(GL.GL_ELEMENT_ARRAY_BUFFER, idx.nbytes, idx, GL.GL_STATIC_DRAW)
            self.count = idx.size
        GL.glBindVertexArray(0)

    def draw(self, primitive):
        GL = self.GL
        GL.glBindVertexArray(self.vao)
        if self.ebo is not None:
            GL.glDrawElements(primitive, self.count, GL.GL_UNSIGNED_INT, None)
        else:
            GL.glDrawArrays(primitive, 0, self.count)

    def draw_ranges(self, primitive, firsts: np.ndarray, counts: np.ndarray):
        """Draw only the vertex ranges [first, first + count) (no index buffer)."""
        GL = self.GL
        GL.glBindVertexArray(self.vao)
        GL.glMultiDrawArrays(primitive, np.ascontiguousarray(firsts, np.int32),
                             np.ascontiguousarray(counts, np.int32), len(firsts))

    def delete(self):
        GL = self.GL
        GL.glDeleteVertexArrays(1, [self.vao])
        GL.glDeleteBuffers(1, [self.vbo])
        if self.ebo is not None:
            GL.glDeleteBuffers(1, [self.ebo])


class GpuLines:
    """A line set on the GPU with its model-frame bounding box."""

    def __init__(self, GL, segments: np.ndarray):
        self.buffer = Buffer(GL, segments, [3]) if len(segments) else None
        self.lo = segments.min(axis=0).astype(float) if len(segments) else None
        self.hi = segments.max(axis=0).astype(float) if len(segments) else None

    def delete(self):
        if self.buffer is not None:
            self.buffer.delete()


class GpuMesh:
    """A trimesh on the GPU: triangles with normals; edges and shadow built on first use."""

    def __init__(self, GL, mesh, version):
        self.GL = GL
        self.version = version
        self.ref = weakref.ref(mesh)
        try:
            shaded = mesh.smooth_shaded  # splits vertices at sharp edges so boxes look boxy
        except (ValueError, IndexError, AttributeError):
            shaded = mesh
        v = np.asarray(shaded.vertices, dtype=np.float32)
        n = np.asarray(shaded.vertex_normals, dtype=np.float32)
        self.surface = Buffer(GL, np.hstack([v, n]), [3, 3], np.asarray(shaded.faces))
        self.lo = np.asarray(mesh.bounds[0], dtype=float)
        self.hi = np.asarray(mesh.bounds[1], dtype=float)
        try:
            self.hull = np.asarray(mesh.convex_hull.vertices, dtype=float)
        except Exception:  # noqa: BLE001 - qhull fails on flat/degenerate input; the box corners still bound it
            self.hull = box_corners(self.lo, self.hi)
        self._mesh_data = (np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.edges_unique))
        # a closed, outward-wound mesh shows only front faces from outside: culling the back half of the
        # triangles halves the rasteriser's work without changing any pixel
        try:
            self.closed = bool(mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0)
        except (ValueError, IndexError):
            self.closed = False
        self.edges = None
        self.shadow = None  # (buffer, texture id, corners)

    def edge_lines(self) -> GpuLines:
        if self.edges is None:
            verts, _, edges = self._mesh_data
            self.edges = GpuLines(self.GL, np.asarray(verts[edges.ravel()], dtype=np.float32))
        return self.edges

    def shadow_quad(self):
        if self.shadow is None:
            GL = self.GL
            verts, faces, _ = self._mesh_data
            tex, corners = footprint(verts, faces)
            uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
            quad = np.hstack([corners.astype(np.float32), uv])
            buf = Buffer(GL, quad, [3, 2], np.array([0, 1, 2, 0, 2, 3]))
            tid = GL.glGenTextures(1)
            GL.glBindTexture(GL.GL_TEXTURE_2D, tid)
            GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
            data = np.ascontiguousarray(np.clip(tex * 255 + 0.5, 0, 255).astype(np.uint8))
            GL.glTexImage2D(GL.GL_TEXTURE_2D, 0, GL.GL_R8, tex.shape[1], tex.shape[0], 0,
                            GL.GL_RED, GL.GL_UNSIGNED_BYTE, data)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MIN_FILTER, GL.GL_LINEAR)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_MAG_FILTER, GL.GL_LINEAR)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_WRAP_S, GL.GL_CLAMP_TO_EDGE)
            GL.glTexParameteri(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_WRAP_T, GL.GL_CLAMP_TO_EDGE)
            self.shadow = (buf, tid, corners)
        return self.shadow

    def delete(self):
        self.surface.delete()
        if self.edges is not None:
            self.edges.delete()
        if self.shadow is not None:
            self.shadow[0].delete()
            self.GL.glDeleteTextures(1, [self.shadow[1]])


def box_corners(lo, hi) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)
