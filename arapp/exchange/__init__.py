"""File exchange: mesh formats (meshes.py: one suffix table, one loader, one units rule, one writer table),
JSON documents read with errors naming the file (jsonfile.py), and the table of arapp's document formats
(files.py: model, session, printer profile, camera calibration, each with its one reader), and scene files
(scene.py: a desk's keypoint map, anchors and placed models, docs/scene-format.md)."""

from .jsonfile import read_json
from .meshes import (
    EXPORT_SUFFIXES,
    FORMATS,
    MESH_SUFFIXES,
    MeshFileError,
    MeshFormat,
    is_mesh_path,
    load_mesh,
    units_to_mm,
    write_atomic,
    write_mesh,
)
from . import scene as _scene  # noqa: F401  (registers the "scene" document format)

__all__ = ["EXPORT_SUFFIXES", "FORMATS", "MESH_SUFFIXES", "MeshFileError", "MeshFormat", "is_mesh_path",
           "load_mesh", "read_json", "units_to_mm", "write_atomic", "write_mesh"]
