"""The overlay renderer's GPU copies of meshes and line sets, cached across frames (LRU, by identity).

Meshes are keyed by id() and checked by a weak reference and trimesh's data hash; line sets by id()
and a weak reference. Everything belongs to the renderer's GL context, which must be current.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict

from arapp.render import modes
from arapp.render.gpu import GpuLines, GpuMesh

MESH_CACHE_SIZE = 16
LINESET_CACHE_SIZE = 64


class GpuCache:
    """`meshes` {id: GpuMesh} and `linesets` {id: (weakref to the LineSet, GpuLines)}, oldest first."""

    def __init__(self, GL):
        self.GL = GL
        self.meshes: OrderedDict[int, GpuMesh] = OrderedDict()
        self.linesets: OrderedDict[int, tuple[weakref.ref, GpuLines]] = OrderedDict()

    def mesh(self, mesh) -> GpuMesh:
        """The cached GPU copy of `mesh` (keyed by identity; rebuilt when its data hash changes)."""
        self.drop_dead()
        key = id(mesh)
        version = hash(mesh)  # trimesh caches this until the arrays are modified
        g = self.meshes.get(key)
        if g is not None and g.ref() is mesh and g.version == version:
            self.meshes.move_to_end(key)
            return g
        if g is not None:
            g.delete()
            del self.meshes[key]
        if len(mesh.faces) == 0:
            raise ValueError("mesh has no faces to draw")
        g = GpuMesh(self.GL, mesh, version)
        self.meshes[key] = g
        while len(self.meshes) > MESH_CACHE_SIZE:
            self.meshes.popitem(last=False)[1].delete()
        return g

    def lineset(self, ls: modes.LineSet, persistent: bool) -> GpuLines:
        """The GPU copy of `ls`: cached when `persistent`, else a fresh one for this frame only."""
        if not persistent:
            return GpuLines(self.GL, ls.segments())
        key = id(ls)
        entry = self.linesets.get(key)
        if entry is not None and entry[0]() is ls:
            self.linesets.move_to_end(key)
            return entry[1]
        if entry is not None:
            entry[1].delete()
        g = GpuLines(self.GL, ls.segments())
        self.linesets[key] = (weakref.ref(ls), g)
        return g

    def trim_linesets(self, in_use: set) -> None:
        """Keep at most LINESET_CACHE_SIZE line sets on the GPU, never evicting those drawn this frame."""
        for key in list(self.linesets):
            if len(self.linesets) <= LINESET_CACHE_SIZE:
                break
            if key not in in_use:
                self.linesets.pop(key)[1].delete()

    def drop_dead(self) -> None:
        """Free GPU copies of meshes and line sets that have been garbage collected."""
        for key in [k for k, g in self.meshes.items() if g.ref() is None]:
            self.meshes.pop(key).delete()
        for key in [k for k, (r, _) in self.linesets.items() if r() is None]:
            self.linesets.pop(key)[1].delete()

    def free_transient(self, items) -> None:
        """Delete the GPU buffers of the [(LineSet, GpuLines)] uploaded for this frame only."""
        cached = {id(g) for g in self._cached_line_buffers()}
        for _, g in items:
            if id(g) not in cached:
                g.delete()

    def _cached_line_buffers(self):
        for _, g in self.linesets.values():
            yield g
        for m in self.meshes.values():
            if m.edges is not None:
                yield m.edges

    def delete_all(self) -> None:
        """Delete every cached GPU copy (the context must be current)."""
        for g in self.meshes.values():
            g.delete()
        for _, g in self.linesets.values():
            g.delete()
        self.clear()

    def clear(self) -> None:
        """Forget every cached copy without deleting it (its context is gone)."""
        self.meshes.clear()
        self.linesets.clear()
