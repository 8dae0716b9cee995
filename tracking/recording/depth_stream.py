"""The optional depth stream of a recording (docs/recording-format.md, "Depth"): one 16-bit PNG per frame.

    depth/000000.png, depth/000001.png, ...   greyscale, 16 bits, counts of `scale` metres (1 mm), 0 = none
    session.json: "depth": {"path": "depth", "encoding": "png16", "units": "mm", "scale": 0.001,
                            "aligned_to": "camera"}

Depth here is the camera-frame z of the surface seen at each pixel (along the
optical axis, not the ray length), in metres in memory (float32, 0 = no
depth) and in counts of `scale` metres on disk. `aligned_to: "camera"` means
pixel (u, v) of a depth file looks along the same ray as pixel (u, v) of the
colour frame of the same index: same size, same intrinsics and distortion
(the session's `camera`). The recorder writes it (`encode`, `write_png`);
the recording source reads it back (`parse_block`, `DepthStream`).
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from tracking.errors import SessionError, SourceError

FOLDER = "depth"
ENCODING = "png16"
SCALE = 0.001          # metres per count written by arapp: millimetres
UNITS = "mm"
ALIGNED_TO = "camera"
MAX_COUNT = 65535
NAME = re.compile(r"^(\d{6})\.png$")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
BLOCK_KEYS = ("path", "encoding", "units", "scale", "aligned_to")


def file_name(index: int) -> str:
    """The depth file of frame `index` (0-based, as in frames.csv)."""
    return f"{index:06d}.png"


def block(folder: str = FOLDER, scale: float = SCALE) -> dict:
    """The session.json `depth` block arapp writes."""
    return {"path": folder, "encoding": ENCODING, "units": UNITS if scale == SCALE else f"{scale} m",
            "scale": scale, "aligned_to": ALIGNED_TO}


def encode(depth_m: np.ndarray, scale: float = SCALE) -> np.ndarray:
    """uint16 counts of `scale` metres (rounded to nearest) from a float depth map in metres; depths that
    are not finite, not positive or beyond the 16-bit range become 0 (no depth)."""
    d = np.asarray(depth_m)
    if not np.issubdtype(d.dtype, np.floating):
        raise SourceError(f"depth must be a float array in metres, got dtype {d.dtype}")
    with np.errstate(invalid="ignore", over="ignore"):
        counts = np.rint(d / scale)
        bad = ~np.isfinite(counts) | (counts <= 0) | (counts > MAX_COUNT)
    counts[bad] = 0
    return counts.astype(np.uint16)


def write_png(path: Path, depth_m: np.ndarray, scale: float = SCALE) -> None:
    """Write one depth frame (float metres, HxW) as a 16-bit greyscale PNG of counts."""
    if not cv2.imwrite(str(path), encode(depth_m, scale)):
        raise SourceError(f"{path}: cannot write the depth frame (check the folder is writable)")


@dataclass(frozen=True)
class DepthBlock:
    """A parsed session.json `depth` block: `folder` (absolute), `scale` (metres per count)."""

    folder: Path
    scale: float
    units: str


def parse_block(data, recording: Path, where: str) -> DepthBlock | None:
    """The `depth` block of a session dict, checked (None when the recording has no depth stream).
    Errors are one-line SessionErrors naming `where` (the session.json path) and the key."""
    if data is None:
        return None
    if not isinstance(data, dict):
        raise SessionError(f"{where}: depth: must be an object such as {block()}")
    unknown = sorted(set(data) - set(BLOCK_KEYS))
    if unknown:
        raise SessionError(f"{where}: depth.{unknown[0]}: unknown key; the keys are {', '.join(BLOCK_KEYS)}")
    path = data.get("path", FOLDER)
    if not isinstance(path, str) or not path or Path(path).is_absolute() or ".." in Path(path).parts:
        raise SessionError(f"{where}: depth.path: must name a folder inside the recording, e.g. 'depth'")
    enc = data.get("encoding", ENCODING)
    if enc != ENCODING:
        raise SessionError(f"{where}: depth.encoding: only {ENCODING!r} (16-bit greyscale PNG per frame) is "
                           f"supported, got {enc!r}")
    scale = data.get("scale")
    if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not (math.isfinite(scale) and scale > 0):
        raise SessionError(f"{where}: depth.scale: must be the metres of one count, e.g. 0.001 for "
                           f"millimetres, got {scale!r}")
    units = data.get("units", "")
    if not isinstance(units, str):
        raise SessionError(f"{where}: depth.units: must be a text such as 'mm', got {units!r}")
    if units == "mm" and abs(scale - 0.001) > 1e-12:
        raise SessionError(f"{where}: depth.units says 'mm' but depth.scale is {scale}; a millimetre is 0.001")
    aligned = data.get("aligned_to")
    if aligned != ALIGNED_TO:
        raise SessionError(f"{where}: depth.aligned_to: must be {ALIGNED_TO!r} (depth pixels on the colour "
                           f"camera's pixels, same size and intrinsics), got {aligned!r}")
    folder = Path(recording) / path
    if not folder.is_dir():
        raise SessionError(f"{folder}: missing; {where} declares a depth stream in folder {path!r}")
    return DepthBlock(folder, float(scale), units)


def _png_header(path: Path) -> tuple[int, int, int, int]:
    """(width, height, bit depth, colour type) from a PNG's IHDR chunk; SessionError if not a PNG."""
    try:
        with open(path, "rb") as f:
            head = f.read(33)
    except OSError as e:
        raise SessionError(f"{path}: cannot be read ({e.strerror or e})") from None
    if len(head) < 33 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise SessionError(f"{path}: not a PNG file; depth frames are 16-bit greyscale PNGs "
                           "(docs/recording-format.md, Depth)")
    w, h, bits, colour = struct.unpack(">IIBB", head[16:26])
    return w, h, bits, colour


class DepthStream:
    """The depth files of a recording, checked at open: names (six-digit frame index), frames that exist,
    16-bit greyscale PNGs of the camera's size (from their headers). `read(i)` gives frame i's depth
    (float32 metres, 0 = none) or None when that frame has no file."""

    def __init__(self, spec: DepthBlock, frame_count: int, width: int, height: int):
        self.spec = spec
        self.size = (width, height)
        self.files: dict[int, Path] = {}
        for p in sorted(spec.folder.iterdir()):
            if p.name.startswith("."):
                continue
            m = NAME.match(p.name)
            if m is None:
                raise SessionError(f"{p}: unexpected file in the depth folder; depth files are named by "
                                   "frame index, e.g. 000012.png for frame 12")
            i = int(m.group(1))
            if i >= frame_count:
                raise SessionError(f"{p}: depth for frame {i}, but the recording has frames 0..{frame_count - 1}")
            w, h, bits, colour = _png_header(p)
            if (bits, colour) != (16, 0):
                raise SessionError(f"{p}: a {bits}-bit PNG of colour type {colour}; depth frames are 16-bit "
                                   "greyscale (colour type 0)")
            if (w, h) != self.size:
                raise SessionError(f"{p}: depth of {w}x{h} but the camera is {width}x{height}; depth must be "
                                   "aligned to the colour frames at their size")
            self.files[i] = p

    def __len__(self) -> int:
        return len(self.files)

    def read(self, index: int) -> np.ndarray | None:
        """Frame `index`'s depth in metres (float32), None when it has none; SourceError (naming the file)
        when the file does not decode to what its header said."""
        p = self.files.get(index)
        if p is None:
            return None
        # Pillow, not cv2.imread: libpng's own complaints about a damaged file would reach stderr
        try:
            with Image.open(p) as im:
                counts = np.asarray(im)
        except (OSError, ValueError, SyntaxError) as e:
            raise SourceError(f"{p}: the depth PNG cannot be decoded ({e}); delete it (the frame then has no "
                              "depth) or re-record") from None
        if counts.dtype.kind != "u" or counts.dtype.itemsize != 2 or counts.shape != self.size[::-1]:
            raise SourceError(f"{p}: decodes to {counts.dtype} {counts.shape}, not 16-bit depth of "
                              f"{self.size[0]}x{self.size[1]}; re-record it")
        return counts.astype(np.float32) * np.float32(self.spec.scale)
