"""Photo-like desk textures: multi-scale noise, random shapes and text, rich in keypoints.

A texture is a BGR uint8 image covering a desk rectangle; its pixel centres
are at integer coordinates (see `DeskTexture`). Deterministic for a seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

_WORDS = ("invoice", "arapp", "notes", "PLA 1.75", "meeting 14:30", "TODO", "nozzle", "layer 0.2",
          "x = 42", "bed level", "draft", "receipt", "M104 S205", "calib", "Ref 7731", "coffee",
          "OAK-D", "page 3", "total", "filament", "sketch", "v2.1", "keep", "printer")


@dataclass
class DeskTexture:
    """A desk texture: `image` (BGR uint8) covers the desk-plane rectangle
    [x_min, x_min + width/ppm] x [y_min, y_min + height/ppm] in desk coordinates (metres).

    Desk coordinates are 2D on the desk plane, x right and y "away" as seen from
    above; texture column u grows with x, row v grows as y decreases. Pixel
    (u, v) has its centre at desk point (x_min + (u + 0.5)/ppm, y_max - (v + 0.5)/ppm).
    """

    image: np.ndarray
    x_min: float
    y_max: float
    ppm: float

    def pixel_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Texture pixel coordinates (u, v) of desk points (x, y), pixel centres at integers."""
        return (x - self.x_min) * self.ppm - 0.5, (self.y_max - y) * self.ppm - 0.5


def _noise_layer(rng: np.random.Generator, h: int, w: int, cell: int) -> np.ndarray:
    """Smooth random field in [-1, 1] with features of about `cell` pixels."""
    gh, gw = max(2, h // cell + 2), max(2, w // cell + 2)
    g = rng.uniform(-1.0, 1.0, (gh, gw)).astype(np.float32)
    return cv2.resize(g, (w, h), interpolation=cv2.INTER_CUBIC)


STYLES = {
    # base colour range, shape colour saturation (0 grey .. 1 full), noise amplitude factor
    "desk": ((70, 150), 0.75, 1.0),
    "bed": ((35, 60), 0.2, 0.6),  # a dark textured PEI sheet with faint prints and scratches
    "tiles": ((150, 190), 0.0, 0.1),  # identical tiles, each with the same motif: repeated texture
}
TILE_M = 0.04  # tile period of the "tiles" style, metres


def _tiles(w: int, h: int, ppm: float, rng: np.random.Generator, noise_amp: float) -> np.ndarray:
    """A floor of identical square tiles (grout lines, the same motif in every tile) with faint
    noise: every corner has many exact look-alikes, the hard case for descriptor matching."""
    p = TILE_M * ppm
    tile = np.full((int(round(p)), int(round(p)), 3), 175, np.float32)
    n = tile.shape[0]
    cv2.rectangle(tile, (0, 0), (n - 1, n - 1), (90, 95, 100), max(1, int(0.06 * n)))
    cv2.circle(tile, (int(0.35 * n), int(0.4 * n)), int(0.14 * n), (60, 110, 160), -1, cv2.LINE_AA)
    cv2.line(tile, (int(0.55 * n), int(0.2 * n)), (int(0.8 * n), int(0.75 * n)), (40, 40, 40),
             max(1, int(0.05 * n)), cv2.LINE_AA)
    img = np.tile(tile, (h // n + 1, w // n + 1, 1))[:h, :w].copy()
    img += _noise_layer(rng, h, w, 16)[..., None] * 255 * 0.02 * noise_amp
    return np.clip(img, 0, 255).astype(np.uint8)


def _noise_base(rng: np.random.Generator, h: int, w: int, lo: float, hi: float, noise_amp: float) -> np.ndarray:
    """(h, w, 3) uint8: a random base colour in [lo, hi) with multi-scale noise over it."""
    base = np.array(rng.uniform(lo, hi, 3), dtype=np.float32)
    img = np.empty((h, w, 3), np.float32)
    img[:] = base
    # Multi-scale noise, each octave with its own tint; amplitude grows with scale (photo-like 1/f).
    for cell in (8, 16, 32, 64, 128, 256, 512):
        amp = (1.5 + 0.045 * cell) * noise_amp
        tint = rng.uniform(0.5, 1.0, 3).astype(np.float32)
        img += _noise_layer(rng, h, w, cell)[..., None] * amp * tint
    return np.clip(img, 0, 255).astype(np.uint8)


def _draw_shape(img: np.ndarray, rng: np.random.Generator, kind: int, centre: tuple[int, int], size: int,
                thick: int, colour: tuple, scale: float) -> None:
    """Draw one clutter shape into `img` (in place): kind 0 a circle, 1 a rectangle, 2 a polygon, 3 a stroke,
    4 an ellipse, else a printed word; `size` px, `thick` px (-1 filled); what else it needs from `rng`."""
    cx, cy = centre
    if kind == 0:
        cv2.circle(img, (cx, cy), size, colour, thick, cv2.LINE_AA)
    elif kind == 1:
        cv2.rectangle(img, (cx - size, cy - size // 2), (cx + size, cy + size // 2), colour, thick, cv2.LINE_AA)
    elif kind == 2:
        pts = (np.array([cx, cy]) + rng.normal(0, size, (int(rng.integers(3, 7)), 2))).astype(np.int32)
        if thick < 0:
            cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
        else:
            cv2.polylines(img, [pts], True, colour, thick, cv2.LINE_AA)
    elif kind == 3:
        pts = np.cumsum(rng.normal(0, size * 0.6, (int(rng.integers(3, 9)), 2)), axis=0) + [cx, cy]
        cv2.polylines(img, [pts.astype(np.int32)], False, colour, max(1, int(2 * scale)), cv2.LINE_AA)
    elif kind == 4:
        cv2.ellipse(img, (cx, cy), (size, max(2, size // 3)), float(rng.uniform(0, 180)), 0, 360,
                    colour, thick, cv2.LINE_AA)
    else:
        word = _WORDS[int(rng.integers(len(_WORDS)))]
        font = int(rng.choice([cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX,
                               cv2.FONT_HERSHEY_COMPLEX, cv2.FONT_HERSHEY_TRIPLEX]))
        fs = float(np.exp(rng.uniform(np.log(0.5), np.log(3.0))) * scale)
        cv2.putText(img, word, (cx, cy), font, fs, colour, max(1, int(fs * 2)), cv2.LINE_AA)


def make_desk_texture(width_m: float, height_m: float, ppm: float, seed: int = 0,
                      x_min: float | None = None, y_max: float | None = None, style: str = "desk") -> DeskTexture:
    """A cluttered desk of `width_m` x `height_m` metres at `ppm` pixels per metre.

    Wood-like multi-scale noise, then random filled/outlined shapes, strokes and
    printed words at many scales: many corners and blobs for keypoint trackers,
    and no repetition (so nothing is confused with an anchor). Centred on the
    desk origin unless `x_min`/`y_max` say otherwise.
    """
    (lo, hi), saturation, noise_amp = STYLES[style]
    rng = np.random.default_rng(seed)
    w, h = int(round(width_m * ppm)), int(round(height_m * ppm))
    if style == "tiles":
        return DeskTexture(_tiles(w, h, ppm, rng, noise_amp), -width_m / 2 if x_min is None else x_min,
                           height_m / 2 if y_max is None else y_max, float(ppm))
    img = _noise_base(rng, h, w, lo, hi, noise_amp)
    scale = ppm / 2000.0  # shape sizes are chosen in metres, drawn in pixels
    n_shapes = int(110 * width_m * height_m / 0.5 + 30)
    for _ in range(n_shapes):
        raw = rng.integers(0, 256, 3).astype(float)
        grey = raw.mean() if style == "desk" else rng.uniform(lo, hi + 90)
        colour = tuple(int(grey + (c - grey) * saturation) for c in raw)
        kind = rng.integers(0, 6)
        cx, cy = int(rng.uniform(0, w)), int(rng.uniform(0, h))
        size = int(np.exp(rng.uniform(np.log(6), np.log(90))) * scale) + 2
        thick = -1 if rng.random() < 0.6 else int(rng.integers(1, 5) * scale) + 1
        _draw_shape(img, rng, kind, (cx, cy), size, thick, colour, scale)
    # A little softness so the texture is band-limited (no aliasing when rendered at the same scale).
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    return DeskTexture(
        image=img,
        x_min=-width_m / 2 if x_min is None else x_min,
        y_max=height_m / 2 if y_max is None else y_max,
        ppm=float(ppm),
    )
