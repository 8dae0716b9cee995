"""Model helpers for the GUI that run in worker threads: control-point edits and library thumbnails."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


def display_placement(model) -> dict:
    """The model's placement as the dict `arapp.placement.placement_from_any` takes:
    size_mm, offset (x, y, z mm), rotation_deg (about x, y, z; the GUI edits the turn about z, the anchor normal)."""
    from arapp.placement import placement_from_any

    p = placement_from_any(getattr(model, "placement", None))
    return {"size_mm": float(p.size_mm), "offset": tuple(float(x) for x in p.offset),
            "rotation_deg": tuple(float(x) for x in p.rotation_deg)}


def edited_model(model, edits: dict):
    """A copy of `model` with control points replaced: edits maps (surface, i, j) -> ((x, y, z), weight).

    The surfaces are rebuilt through NurbsSurface, so an edit that makes the
    surface invalid (a vanishing denominator) raises its ValueError here.
    """
    from arapp.geometry import NurbsSurface

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


def library_thumbnails(paths: list[Path], each, owner=None, size: int = 72) -> int:
    """Render a thumbnail per model file and hand (path, bgr image) to each() on the UI thread (unless `owner`
    is gone by then); skip files that do not load (opening one shows its error)."""
    from arapp.geometry import load_model
    from arapp.gui.tasks import on_ui
    from arapp.gui.thumbnails import render_thumbnail

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
        on_ui(each, (str(path), image), owner)
        done += 1
    return done
