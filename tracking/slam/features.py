"""FAST corners with ORB descriptors, spread over the image by grid bucketing, at several pyramid levels.

Keypoints are returned both as detected (distorted pixels) and undistorted
(same K, distortion removed) so that geometry can use the plain pinhole model.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.camera import Camera

# popcount of every byte value, for Hamming distances of packed binary descriptors
POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)


def hamming(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances between packed descriptors a (..., 32) and b (..., 32), broadcasting."""
    return POPCOUNT[np.bitwise_xor(a, b)].sum(axis=-1, dtype=np.int32)


@dataclass
class Features:
    """Keypoints of one image. `xy` distorted pixels (N,2), `und` undistorted pixels (N,2),
    `octave` pyramid level (N,), `desc` ORB descriptors (N,32) uint8."""

    xy: np.ndarray
    und: np.ndarray
    octave: np.ndarray
    desc: np.ndarray

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @staticmethod
    def empty() -> "Features":
        z = np.zeros((0, 2))
        return Features(z, z.copy(), np.zeros(0, int), np.zeros((0, 32), np.uint8))


def bucket(xy: np.ndarray, response: np.ndarray, width: int, height: int, grid: tuple[int, int],
           n: int) -> np.ndarray:
    """Indices of at most `n` keypoints, the strongest per grid cell first, so corners cover the image.

    Each of the gx x gy cells keeps its best ceil(n / cells) keypoints; remaining
    slots go to the strongest leftovers anywhere.
    """
    if xy.shape[0] <= n:
        return np.arange(xy.shape[0])
    gx, gy = grid
    cx = np.clip((xy[:, 0] * gx / width).astype(int), 0, gx - 1)
    cy = np.clip((xy[:, 1] * gy / height).astype(int), 0, gy - 1)
    cell = cy * gx + cx
    per = int(np.ceil(n / (gx * gy)))
    # sort by cell, then by descending response, and rank within each cell
    order = np.lexsort((-response, cell))
    sc = cell[order]
    start = np.searchsorted(sc, sc, side="left")
    rank = np.arange(order.size) - start
    chosen = order[rank < per]
    if chosen.size > n:
        chosen = chosen[np.argsort(-response[chosen])[:n]]
    elif chosen.size < n:
        rest = np.setdiff1d(np.arange(xy.shape[0]), chosen)
        rest = rest[np.argsort(-response[rest])[: n - chosen.size]]
        chosen = np.concatenate([chosen, rest])
    return np.sort(chosen)


class FeatureExtractor:
    """ORB (oriented FAST + rotated BRIEF) over a pyramid, bucketed on a grid.

    `n_features` keypoints at most; `levels` pyramid levels `scale` apart;
    `fast_threshold` is lowered automatically on textureless views (down to
    `min_fast_threshold`) so a flat view still yields what corners it has.
    """

    def __init__(self, camera: Camera, n_features: int = 800, levels: int = 4, scale: float = 1.2,
                 grid: tuple[int, int] | None = None, fast_threshold: int = 12, min_fast_threshold: int = 6,
                 max_width: int = 960):
        self.camera = camera
        # large frames are searched at a reduced size (keypoints mapped back to full-size pixels)
        self.work_scale = min(1.0, max_width / camera.width)
        self.n_features = int(n_features)
        self.grid = grid or (max(2, round(camera.width / 80)), max(2, round(camera.height / 80)))
        self.fast_threshold = fast_threshold
        self.min_fast_threshold = min_fast_threshold
        self.levels = levels
        self.scale = scale
        self._orb = {}

    def _detector(self, threshold: int) -> cv2.ORB:
        if threshold not in self._orb:
            self._orb[threshold] = cv2.ORB_create(
                nfeatures=int(self.n_features * 1.5), scaleFactor=self.scale, nlevels=self.levels,
                edgeThreshold=19, patchSize=19, fastThreshold=threshold, scoreType=cv2.ORB_FAST_SCORE,
            )
        return self._orb[threshold]

    def extract(self, gray: np.ndarray) -> Features:
        """Features of an 8-bit grey image of the camera's size."""
        if gray.ndim != 2 or gray.shape[0] < 40 or gray.shape[1] < 40:
            return Features.empty()
        s = self.work_scale
        if s < 1.0:
            gray = cv2.resize(gray, (round(gray.shape[1] * s), round(gray.shape[0] * s)), interpolation=cv2.INTER_AREA)
        thr = self.fast_threshold
        while True:
            kps, desc = self._detector(thr).detectAndCompute(gray, None)
            if len(kps) >= self.n_features // 3 or thr <= self.min_fast_threshold:
                break
            thr = max(self.min_fast_threshold, thr // 2)
        if desc is None or len(kps) == 0:
            return Features.empty()
        xy = cv2.KeyPoint_convert(kps).astype(float)
        resp = np.array([k.response for k in kps], dtype=float)
        octave = np.array([k.octave for k in kps], dtype=int)
        keep = bucket(xy, resp, gray.shape[1], gray.shape[0], self.grid, self.n_features)
        xy, octave, desc = xy[keep], octave[keep], desc[keep]
        if s < 1.0:
            xy = (xy + 0.5) / s - 0.5   # pixel centres at integers in both images
            octave = octave + int(round(np.log(1 / s) / np.log(self.scale)))
        und = self.camera.undistort_points(xy) if self.camera.has_distortion else xy.copy()
        return Features(xy, und, octave, np.ascontiguousarray(desc))
