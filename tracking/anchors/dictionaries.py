"""ArUco dictionaries by name: OpenCV's predefined ones (`DICT_4X4_50`, ...) and custom ones read from a file.

A custom dictionary is an OpenCV dictionary file, as `cv2.aruco.Dictionary.writeDictionary` writes it
(YAML or JSON: `nmarkers`, `markersize`, `maxCorrectionBits`, `marker_0`, ... one bit string per
marker, row by row). A session names it by its path (session.py resolves a relative path against the
recording folder). OpenCV's own tutorial boards are printed in such a dictionary.

This module imports nothing of arapp's anchors package, so session.py can use it while parsing.
"""

from __future__ import annotations

from pathlib import Path

import cv2

from tracking.errors import SessionError

CUSTOM_SUFFIXES = (".yml", ".yaml", ".json")

_CACHE: dict[tuple, cv2.aruco.Dictionary] = {}


def is_custom(name: str) -> bool:
    """True when `name` is a path to a dictionary file rather than an OpenCV predefined name."""
    return str(name).lower().endswith(CUSTOM_SUFFIXES)


def aruco_dictionary(name: str, where: str = "dictionary") -> cv2.aruco.Dictionary:
    """The dictionary named `name`: `DICT_*` (predefined) or a path to a dictionary file (see module doc).

    Raises SessionError (naming `where`) when the name is unknown or the file is missing or unreadable."""
    if not is_custom(name):
        value = getattr(cv2.aruco, str(name), None) if str(name).startswith("DICT_") else None
        if not isinstance(value, int):
            raise SessionError(f"{where}: {name!r} is neither an OpenCV ArUco dictionary (DICT_4X4_50, ...) nor a "
                               f"dictionary file ({', '.join(CUSTOM_SUFFIXES)})")
        return cv2.aruco.getPredefinedDictionary(value)
    path = Path(name)
    if not path.is_file():
        raise SessionError(f"{where}: dictionary file {str(path)!r} not found (a relative path is read from the "
                           f"recording folder)")
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _CACHE:
        d = cv2.aruco.Dictionary()
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        try:
            ok = fs.isOpened() and d.readDictionary(fs.root())
        except cv2.error:
            ok = False
        finally:
            fs.release()
        if not ok or d.bytesList is None or len(d.bytesList) == 0 or d.markerSize < 2:
            raise SessionError(f"{where}: {str(path)!r} is not an OpenCV dictionary file (it needs nmarkers, "
                               f"markersize and marker_0, marker_1, ... as cv2.aruco.Dictionary.writeDictionary "
                               f"writes)")
        _CACHE[key] = d
    return _CACHE[key]


def dictionary_size(name: str, where: str = "dictionary") -> int:
    """How many markers (ids 0 .. size-1) the dictionary `name` holds."""
    return int(aruco_dictionary(name, where).bytesList.shape[0])
