"""Model helpers that run in worker threads: control-point edits, display meshes and library thumbnails."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from arapp.render.thumbnails import render_thumbnail
from arapp.geometry import NurbsSurface, load_model
from arapp.geometry.placement import Placement


def display_placement(model) -> Placement:
    """The model's own placement (size_mm, offset x, y, z mm, rotation_deg about x, y, z; the GUI edits the
    turn about z, the anchor normal), or the default one for a model without."""
    return Placement.from_any(getattr(model, "placement", None))


def edited_model(model, edits: dict):
    """A copy of `model` with control points replaced: edits maps (surface, i, j) -> ((x, y, z), weight).

    The surfaces are rebuilt through NurbsSurface, so an edit that makes the
    surface invalid (a vanishing denominator) raises its ValueError here.
    """
    surfaces = list(model.surfaces)
    by_surface: dict[int, list] = {}
    for (k, i, j), value in edits.items():
        by_surface.setdefault(k, []).append((i, j, value))
    for k, changes in by_surface.items():
        if not 0 <= k < len(surfaces):
            raise ValueError(f"surface {k} does not exist; the model has {len(surfaces)}")
        s = surfaces[k]
        pts = np.array(s.control_points, dtype=float, copy=True)
        w = np.array(s.weights, dtype=float, copy=True)
        for i, j, (xyz, weight) in changes:
            pts[i, j] = xyz
            w[i, j] = weight
        surfaces[k] = NurbsSurface(pts, w, s.knots_u, s.knots_v, s.degree_u, s.degree_v)
    # a fresh copy: private caches (tessellations of the old surfaces) must not be shared
    caches = {f.name: {} for f in dataclasses.fields(model)
              if f.name.startswith("_") and f.init and isinstance(getattr(model, f.name), dict)}
    return dataclasses.replace(model, surfaces=surfaces, **caches)


def model_mesh(model):
    """(mesh, lines) for display: the tessellated surfaces and, for NURBS, isolines plus control net."""
    mesh = model.mesh()
    lines = model.lines() if getattr(model, "surfaces", None) else None
    return mesh, lines


_THUMBS: dict = {}  # (path, mtime, size) -> image; thumbnails are made once per process


def library_thumbnails(paths: list[Path], each, size: int = 72) -> int:
    """Render a thumbnail per model file and hand (path, bgr image) to each(), in this thread, as each is
    done (the GUI forwards them to its UI thread); skip files that do not load (opening one shows its error)."""
    done = 0
    for path in paths:
        try:
            key = (str(path), Path(path).stat().st_mtime, size)
            image = _THUMBS.get(key)
            if image is None:
                model = load_model(path)
                mesh = model.mesh()
                color = tuple(getattr(model, "color", (0.8, 0.55, 0.2))[:3])
                image = _THUMBS[key] = render_thumbnail(mesh.vertices, mesh.faces, size, color=color)
        except (ValueError, OSError, RuntimeError):
            continue
        each((str(path), image))
        done += 1
    return done
