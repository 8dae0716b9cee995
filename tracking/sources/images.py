"""A folder of images played as a video (spec: the folder's path): photo sequences and frame dumps; one
image file plays as a video of one frame (a photo of a marker, to try an anchor on).

The images are the folder's own files whose suffix is in IMAGE_SUFFIXES, in natural name order
(`frame2.png` before `frame10.png`), at frame / fps seconds (30 fps unless given: a folder carries no
frame rate, which a note says). Every image must have the first one's size. Images are read as 8-bit
colour as stored, their EXIF orientation ignored: every photo as the sensor took it, so one camera (one
calibration) fits them all, portrait or landscape.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterator

import cv2

from tracking.camera import Camera
from tracking.errors import SourceError

from .base import Frame, Source, _calibrated

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
DEFAULT_FPS = 30.0
READ_FLAGS = cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION   # 8-bit BGR (16-bit PNGs scaled), as stored


def natural_key(name: str) -> list:
    """A sort key that orders the digit runs of `name` as numbers: img2 < img10."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def is_image(path: str | Path) -> bool:
    """Whether `path` names an image file by its suffix (IMAGE_SUFFIXES, any case)."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def image_files(folder: Path) -> list[Path]:
    """The image files directly in `folder` (IMAGE_SUFFIXES, any case), in natural name order; for an image
    file itself, [that file]."""
    if folder.is_file():
        return [folder] if is_image(folder) else []
    files = [p for p in folder.iterdir() if p.is_file() and is_image(p)]
    return sorted(files, key=lambda p: natural_key(p.name))


class ImageFolderSource(Source):
    """The images of a folder (or one image file) as frames (`image_files` order), frame i at i / fps seconds. With
    `calibration` (a file tracking.calibration_file reads, or a Camera) it has a camera, fitted to the
    images' size like a video's."""

    kind = "file"   # session.json's source kind of a recording made from it: file-based, like a video

    def __init__(self, folder: str | Path, calibration: str | Path | Camera | None = None, fps: float | None = None):
        super().__init__()
        self.path = Path(folder)
        self.files = image_files(self.path)
        if not self.files:
            raise SourceError(f"{self.path}: no images ({', '.join(s[1:] for s in IMAGE_SUFFIXES)}) in this folder")
        first = cv2.imread(str(self.files[0]), READ_FLAGS)
        if first is None:
            raise SourceError(f"{self.files[0]}: OpenCV cannot read this image (corrupt file or unsupported "
                              "format); remove it from the folder or convert it")
        self.height, self.width = first.shape[:2]
        self.fps = float(fps or DEFAULT_FPS)
        self.frame_count = len(self.files)
        self.notes = [] if fps or self.frame_count == 1 else [
            f"{self.describe()}: played at {self.fps:g} fps (a folder of images has no frame rate)"]
        if calibration is not None:
            self._camera, notes = _calibrated(calibration, self.width, self.height, str(self.path))
            self.notes += notes
        self.info = {"kind": self.kind, "path": str(self.path)}

    def describe(self) -> str:
        if self.path.is_file():
            return f"image {self.path}"
        return f"image folder {self.path} ({self.frame_count} images)"

    def _frames(self) -> Iterator[Frame]:
        for i, path in enumerate(self.files):
            if self.closed:
                return
            img = cv2.imread(str(path), READ_FLAGS)
            if img is None:
                self._fail(f"{path}: OpenCV cannot read this image; {self._delivered(i)}")
                return
            if img.shape[:2] != (self.height, self.width):
                self._fail(f"{path}: {img.shape[1]}x{img.shape[0]}, but the folder's first image is "
                           f"{self.width}x{self.height}; {self._delivered(i)} (every image must have "
                           "one size)")
                return
            yield Frame(i, i / self.fps, img)
