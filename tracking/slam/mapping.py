"""Local mapping, off the tracking thread: keyframe insertion, triangulation of new map points
between keyframes with enough parallax, culling, local bundle adjustment.

Lengths in metres, image points in undistorted pixels.
"""

from __future__ import annotations

import logging
import queue
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from tracking.poses import invert
from tracking.slam.ba import local_bundle_adjustment
from tracking.slam.features import Features
from tracking.slam.map import Keyframe, Map

log = logging.getLogger(__name__)


@dataclass
class KeyframeRequest:
    """What the tracker hands the mapper: a frame, its pose, the map points it matched, anchor corners."""

    t: float
    pose: np.ndarray
    feats: Features
    point_ids: np.ndarray
    anchor_world: np.ndarray | None = None
    anchor_uv: np.ndarray | None = None


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _match_unmapped(a: Keyframe, b: Keyframe, max_hamming: int, ratio: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Features of a and b not yet on map points, paired by descriptor (ratio test), one-to-one: (indices in
    a, indices in b); None when fewer than 8 pairs (or unmatched features) are there."""
    ia = np.nonzero(a.point_ids < 0)[0]
    ib = np.nonzero(b.point_ids < 0)[0]
    if ia.size < 8 or ib.size < 8:
        return None
    baseline = np.linalg.norm(a.centre - b.centre)
    if baseline < 1e-3:
        return None
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    knn = matcher.knnMatch(a.feats.desc[ia], b.feats.desc[ib], k=2)
    pa, pb = [], []
    for m in knn:
        if len(m) == 0:
            continue
        if m[0].distance > max_hamming:
            continue
        if len(m) > 1 and m[0].distance > ratio * m[1].distance:
            continue
        pa.append(ia[m[0].queryIdx])
        pb.append(ib[m[0].trainIdx])
    if len(pa) < 8:
        return None
    pa, pb = np.array(pa), np.array(pb)
    # one-to-one
    _, u = np.unique(pb, return_index=True)
    return pa[u], pb[u]


def _on_epipolar_lines(K: np.ndarray, a: Keyframe, b: Keyframe, pa: np.ndarray, pb: np.ndarray,
                       scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs whose feature in b lies within 2 sigma (its octave's) of the epipolar line of its feature in a."""
    Tb = invert(b.pose)                               # cam_from_world
    Tba = Tb @ a.pose                                 # b_from_a
    E = skew(Tba[:3, 3]) @ Tba[:3, :3]
    Kinv = np.linalg.inv(K)
    F = Kinv.T @ E @ Kinv
    xa = np.c_[a.feats.und[pa], np.ones(pa.size)]
    xb = np.c_[b.feats.und[pb], np.ones(pb.size)]
    lines = xa @ F.T                                  # epipolar lines in b
    d = np.abs((lines * xb).sum(1)) / np.maximum(np.linalg.norm(lines[:, :2], axis=1), 1e-12)
    sig = scale ** b.feats.octave[pb]
    ok = d < 2.0 * sig
    return pa[ok], pb[ok]


def _keep_point(K: np.ndarray, a: Keyframe, b: Keyframe, Ta: np.ndarray, Tb: np.ndarray, X_: np.ndarray,
                i: int, j: int, min_parallax_deg: float, scale: float) -> bool:
    """Whether world point X_ (from features i of a and j of b) lies in front of both cameras, with
    parallax >= min_parallax_deg, reprojecting within the chi-square bound (its octaves' sigma) in both."""
    xa_c = Ta[:3, :3] @ X_ + Ta[:3, 3]
    xb_c = Tb[:3, :3] @ X_ + Tb[:3, 3]
    if xa_c[2] <= 0.02 or xb_c[2] <= 0.02:
        return False
    ra, rb = X_ - a.centre, X_ - b.centre
    cosp = ra @ rb / (np.linalg.norm(ra) * np.linalg.norm(rb))
    if cosp > np.cos(np.radians(min_parallax_deg)):
        return False
    ua = K[:2, :2] @ (xa_c[:2] / xa_c[2]) + K[:2, 2]
    ub = K[:2, :2] @ (xb_c[:2] / xb_c[2]) + K[:2, 2]
    sa, sb = scale ** a.feats.octave[i], scale ** b.feats.octave[j]
    return not (np.sum((ua - a.feats.und[i]) ** 2) > 5.991 * sa * sa
                or np.sum((ub - b.feats.und[j]) ** 2) > 5.991 * sb * sb)


def triangulate_pair(K: np.ndarray, a: Keyframe, b: Keyframe, min_parallax_deg: float = 2.0,
                     max_hamming: int = 50, ratio: float = 0.8, scale: float = 1.2) -> list[tuple[np.ndarray, int, int]]:
    """New points seen by keyframes a and b: [(xyz, feature index in a, feature index in b)].

    Unmatched features are paired by descriptor (ratio test), checked against the
    epipolar line, triangulated linearly, and kept only in front of both cameras,
    reprojecting within the chi-square bound, with parallax >= min_parallax_deg.
    """
    pairs = _match_unmapped(a, b, max_hamming, ratio)
    if pairs is None:
        return []
    pa, pb = _on_epipolar_lines(K, a, b, *pairs, scale)
    if pa.size == 0:
        return []
    Ta, Tb = invert(a.pose), invert(b.pose)          # cam_from_world
    Pa = K @ Ta[:3]
    Pb = K @ Tb[:3]
    Xh = cv2.triangulatePoints(Pa, Pb, a.feats.und[pa].T.astype(float), b.feats.und[pb].T.astype(float))
    w = Xh[3]
    good = np.abs(w) > 1e-12
    X = (Xh[:3] / np.where(good, w, 1.0)).T
    return [(X_, int(i), int(j)) for X_, i, j, g in zip(X, pa, pb, good)
            if g and _keep_point(K, a, b, Ta, Tb, X_, i, j, min_parallax_deg, scale)]


class LocalMapper:
    """Consumes keyframe requests on its own thread (or inline when `threaded=False`).

    For each: add the keyframe, triangulate against the `neighbours` nearest
    keyframes, cull weak points, run local bundle adjustment (when `ba`).
    """

    def __init__(self, m: Map, K: np.ndarray, ba: bool = True, threaded: bool = True, neighbours: int = 3,
                 window: int = 5, max_keyframes: int = 200):
        self.map = m
        self.K = K
        self.ba = ba
        self.neighbours = neighbours
        self.window = window
        self.max_keyframes = max_keyframes
        self.threaded = threaded
        self._q: queue.Queue = queue.Queue()
        self._untriangulated = 0          # submitted keyframes not yet mapped and adjusted
        self.submitted = 0                # keyframe requests handed in so far
        self.done = 0                     # of those, fully mapped
        self._cv = threading.Condition()
        self._thread = None
        self.ba_runs = 0
        self._since_ba = 0
        self.error: Exception | None = None
        if threaded:
            self._thread = threading.Thread(target=self._loop, name="slam-mapping", daemon=True)
            self._thread.start()

    @property
    def pending(self) -> int:
        """Keyframes submitted but not yet mapped (inserted, triangulated, adjusted)."""
        return self._untriangulated

    def submit(self, req: KeyframeRequest) -> None:
        self.submitted += 1
        if self.threaded:
            with self._cv:
                self._untriangulated += 1
            self._q.put(req)
        else:
            self._process(req)

    def wait_idle(self) -> None:
        """Block until every submitted keyframe is mapped (for tests and offline replay)."""
        if self.threaded:
            self._q.join()

    def close(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            self._q.put(None)
            self._thread.join(timeout=10)
        self._thread = None

    def _loop(self) -> None:
        while True:
            req = self._q.get()
            try:
                if req is None:
                    return
                self._process(req)
            except Exception as e:  # noqa: BLE001 - keep mapping alive; the error is kept for the caller
                log.exception("mapping failed")
                self.error = e
                if not getattr(req, "mapped", False):
                    self._triangulated()
            finally:
                self._q.task_done()

    def _process(self, req: KeyframeRequest) -> None:
        m = self.map
        kf = m.new_keyframe(req.t, req.pose, req.feats, req.point_ids, req.anchor_world, req.anchor_uv)
        nbs = [k for k in m.nearest_keyframes(kf.pose, self.neighbours + 1) if k.id != kf.id][: self.neighbours]
        for nb in nbs:
            for X, i, j in triangulate_pair(self.K, kf, nb):
                with m.lock:
                    if kf.point_ids[i] >= 0 or nb.point_ids[j] >= 0:
                        continue
                    # raw triangulations stay hidden from tracking until bundle adjustment refines them
                    m.add_point(X, kf.feats.desc[i], {kf.id: i, nb.id: j}, ready=not self.ba)
        m.cull(kf.id)
        self._trim()
        # when more keyframes wait, BA every other keyframe: the newest ones matter more
        self._since_ba += 1
        if self.ba and len(m.keyframes) >= 2 and (not self.threaded or self._q.qsize() == 0 or self._since_ba >= 2):
            if local_bundle_adjustment(m, kf.id, self.K, self.window):
                self.ba_runs += 1
                self._since_ba = 0
        req.mapped = True
        self._triangulated()

    def _triangulated(self) -> None:
        with self._cv:
            self.done += 1
            self._untriangulated = max(0, self._untriangulated - 1)
            self._cv.notify_all()

    def wait_done(self, n: int, timeout: float = 10.0) -> None:
        """Block until the first n submitted keyframes are mapped."""
        if not self.threaded:
            return
        with self._cv:
            self._cv.wait_for(lambda: self.done >= n or self._thread is None, timeout=timeout)

    def _trim(self) -> None:
        """Bound memory: drop the oldest non-anchor keyframes beyond max_keyframes."""
        m = self.map
        with m.lock:
            if len(m.keyframes) <= self.max_keyframes:
                return
            old = sorted(m.keyframes)[: len(m.keyframes) - self.max_keyframes]
            for k in old:
                kf = m.keyframes.pop(k)
                for fi, pid in enumerate(kf.point_ids):
                    p = m.points.get(int(pid))
                    if pid >= 0 and p is not None:
                        p.obs.pop(k, None)
                        if not p.obs:
                            m.points.pop(int(pid))
            m.version += 1
