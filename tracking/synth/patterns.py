"""Printed anchors as exact cell patterns in their own anchor frame.

Each anchor becomes a `PrintedPattern`: a rectangular array of square tiles
(one tile per ArUco marker or QR symbol, or per ChArUco square), each tile a grid of black/white
cells, laid out in "print coordinates" (p, q): p to the right and q down the
sheet as printed, metres, origin at the first tile's top-left outer corner.
`anchor_xy = origin + (p * sx, q * sy)` maps them into the anchor frame
(see docs/recording-format.md for the anchor conventions).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.anchors.model import charuco_board
from tracking.errors import SessionError
from tracking.anchors.kinds import AnchorSpec


@dataclass
class PrintedPattern:
    """Tiles of `cells x cells` bits (0 black, 1 white), `pitch` apart, each `tile_size` wide (metres).

    `tiles` has shape (rows, cols, cells, cells). `margin` is the white paper
    around the tiles (metres). `normal_sign` is +1 when the anchor's z axis points
    out of the paper (aruco, qr), -1 when it points into it (boards).
    """

    tiles: np.ndarray
    pitch: float
    tile_size: float
    origin: tuple[float, float]
    sx: float
    sy: float
    margin: float
    normal_sign: float

    @property
    def extent(self) -> tuple[float, float]:
        """(width, height) of the tile array in print coordinates, paper margin excluded."""
        rows, cols = self.tiles.shape[:2]
        return (cols - 1) * self.pitch + self.tile_size, (rows - 1) * self.pitch + self.tile_size

    def print_coords(self, xa: np.ndarray, ya: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Print coordinates (p, q) of anchor-frame points (xa, ya)."""
        return (xa - self.origin[0]) * self.sx, (ya - self.origin[1]) * self.sy

    def sample(self, p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(on_paper mask, value in {0, 1}) at print coordinates; value is 1 (white) off the tiles."""
        w, h = self.extent
        m = self.margin
        on_paper = (p >= -m) & (p < w + m) & (q >= -m) & (q < h + m)
        rows, cols, n, _ = self.tiles.shape
        ti = np.floor(p / self.pitch).astype(np.int64)
        tj = np.floor(q / self.pitch).astype(np.int64)
        fu = p - ti * self.pitch
        fv = q - tj * self.pitch
        on_tile = (ti >= 0) & (ti < cols) & (tj >= 0) & (tj < rows) & (fu < self.tile_size) & (fv < self.tile_size)
        ci = np.clip(np.floor(fu / self.tile_size * n).astype(np.int64), 0, n - 1)
        cj = np.clip(np.floor(fv / self.tile_size * n).astype(np.int64), 0, n - 1)
        value = np.ones(p.shape, np.uint8)
        sel = on_tile
        value[sel] = self.tiles[np.clip(tj[sel], 0, rows - 1), np.clip(ti[sel], 0, cols - 1), cj[sel], ci[sel]]
        return on_paper, value


def _aruco_bits(dictionary: int, marker_id: int) -> np.ndarray:
    """Cells (n+2 square, black border included) of one ArUco marker, 0 black / 1 white."""
    d = cv2.aruco.getPredefinedDictionary(dictionary)
    n = d.markerSize + 2
    img = cv2.aruco.generateImageMarker(d, marker_id, n, borderBits=1)
    return (img > 127).astype(np.uint8)


def qr_modules(text: str) -> np.ndarray:
    """Modules of the QR symbol for `text` (quiet zone excluded), 0 black / 1 white."""
    img = cv2.QRCodeEncoder.create().encode(text)
    if img is None or img.size == 0:
        raise SessionError(f"qr anchor: OpenCV cannot encode {text!r} as a QR code")
    dark = img < 128
    ys, xs = np.nonzero(dark)
    sym = img[ys.min(): ys.max() + 1, xs.min(): xs.max() + 1]
    return (sym > 127).astype(np.uint8)


def _charuco_cells(squares_x: int, squares_y: int, square: float, marker: float, bits: int) -> int:
    """Cells per ChArUco square such that each marker spans a whole number of cells per bit and sits
    centred in its square (so OpenCV's board image is exact at that size); the ratio marker/square is
    kept to within 0.5 % (or as close as 400 cells per square allow)."""
    best, best_err = None, np.inf
    for cells in range(2 * bits, 401):
        m = round(marker / square * cells / bits) * bits   # marker cells: a multiple of the bit count
        if m <= 0 or m >= cells or (cells - m) % 2:
            continue
        err = abs(m / cells - marker / square)
        if err < best_err - 1e-12:
            best, best_err = cells, err
        if err <= 0.005 * marker / square and cells >= 60:
            return cells
    return best


def pattern_for(anchor: AnchorSpec) -> PrintedPattern:
    """The printed pattern of an anchor (aruco, aruco_board, charuco, qr)."""
    if anchor.kind == "aruco":
        L = anchor.length
        tiles = _aruco_bits(anchor.dictionary_id, anchor.id)[None, None]
        # Corner 0 (top-left as printed) is at (-L/2, +L/2): print q grows toward -y.
        return PrintedPattern(tiles, L, L, (-L / 2, L / 2), 1.0, -1.0, margin=0.25 * L, normal_sign=1.0)
    if anchor.kind == "qr":
        L = anchor.length
        tiles = qr_modules(anchor.text)[None, None]
        quiet = 4 * L / tiles.shape[-1]
        return PrintedPattern(tiles, L, L, (-L / 2, L / 2), 1.0, -1.0, margin=quiet * 1.5, normal_sign=1.0)
    if anchor.kind == "aruco_board":
        L, s = anchor.marker_length, anchor.separation
        rows, cols = anchor.markers_y, anchor.markers_x
        n = cv2.aruco.getPredefinedDictionary(anchor.dictionary_id).markerSize + 2
        tiles = np.zeros((rows, cols, n, n), np.uint8)
        for k, mid in enumerate(anchor.marker_ids()):
            tiles[k // cols, k % cols] = _aruco_bits(anchor.dictionary_id, mid)
        # GridBoard frame: origin at the first marker's outer corner, x right, y down, z into the paper.
        return PrintedPattern(tiles, L + s, L, (0.0, 0.0), 1.0, 1.0, margin=max(s, 0.3 * L), normal_sign=-1.0)
    if anchor.kind == "charuco":
        board = charuco_board(anchor)
        sq, cols, rows = anchor.square_length, anchor.squares_x, anchor.squares_y
        bits = board.getDictionary().markerSize + 2
        n = _charuco_cells(cols, rows, sq, anchor.marker_length, bits)
        img = board.generateImage((cols * n, rows * n), marginSize=0, borderBits=1)
        # one tile per chessboard square, in OpenCV's own drawing (pattern variant included)
        tiles = (img.reshape(rows, n, cols, n).transpose(0, 2, 1, 3) > 127).astype(np.uint8)
        # CharucoBoard frame: origin at the board's top-left outer corner, x right, y down, z into the paper.
        return PrintedPattern(tiles, sq, sq, (0.0, 0.0), 1.0, 1.0, margin=0.5 * sq, normal_sign=-1.0)
    raise SessionError(f"synth: cannot print a {anchor.kind!r} anchor; use aruco, aruco_board, charuco or qr")


def anchor_corners(anchor: AnchorSpec) -> np.ndarray:
    """Anchor-frame corners (N, 4, 3) of every marker/symbol, in OpenCV's corner order.

    aruco/qr: one square of side `length` centred at the origin; boards: the
    GridBoard's own `getObjPoints()`, so this is the reference the detectors use.
    """
    if anchor.kind in ("aruco", "qr"):
        h = anchor.length / 2
        return np.array([[[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]]], float)
    if anchor.kind == "aruco_board":
        d = cv2.aruco.getPredefinedDictionary(anchor.dictionary_id)
        board = cv2.aruco.GridBoard((anchor.markers_x, anchor.markers_y), anchor.marker_length,
                                    anchor.separation, d, np.array(anchor.marker_ids()))
        return np.asarray(board.getObjPoints(), float).reshape(-1, 4, 3)
    if anchor.kind == "charuco":
        return np.asarray(charuco_board(anchor).getObjPoints(), float).reshape(-1, 4, 3)
    raise SessionError(f"anchor_corners: {anchor.kind!r} anchors are not supported")
