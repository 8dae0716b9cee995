"""A full frame's pose fits: the anchors' corners jointly with the map points matched near them
(`PoseFits.with_anchors`), or the map points alone (`PoseFits.from_map`, relocalising when the motion
model has nothing to offer). Poses are `world_from_camera` 4x4 (metres); pixels are undistorted."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.camera import Camera
from tracking.fusion.config import TrackerConfig
from tracking.fusion.handover import Handover, anchor_output, anchor_usable, precise
from tracking.slam.features import Features
from tracking.slam.frame_pose import MotionModel, match_by_projection, pnp_ransac, refine_pose
from tracking.slam.fusion import fuse_pose
from tracking.slam.map import Map
from tracking.slam.relocalise import relocalise


@dataclass
class Fit:
    """A frame's pose fit on a full frame: `pose` world_from_camera, `state` ("marker" / "slam"),
    `inliers` count; the map points it used: `point_ids`, their features `feature_idx` and world
    positions `points` (N,3); `visible` the map points matched at all; `source`/`out_pose` what to
    show instead of `pose` (the anchors' own pose), when set."""

    pose: np.ndarray
    state: str
    inliers: int
    point_ids: np.ndarray
    feature_idx: np.ndarray
    points: np.ndarray
    visible: np.ndarray
    source: str | None = None
    out_pose: np.ndarray | None = None
    precise: bool = False   # `out_pose` is the anchors' pose measured on 12+ corners


def anchor_points(ar, camera: Camera, covered_too: bool = False) -> tuple[np.ndarray, np.ndarray, int]:
    """The anchors' measured corners this frame: world points (N,3), undistorted pixels (N,2) and the
    marker count; empty when the anchors gave no pose or (unless `covered_too`) rest on partly
    covered markers (their corners may be off by pixels: the map and flow carry the pose then)."""
    if (ar is None or ar.raw_world_from_camera is None or len(ar.object_points) < 4
            or (ar.covered and not covered_too)):
        return np.zeros((0, 3)), np.zeros((0, 2)), 0
    corners_uv = camera.undistort_points(np.asarray(ar.image_points, float).reshape(-1, 2))
    return np.asarray(ar.object_points, float).reshape(-1, 3), corners_uv, int(ar.markers)


class PoseFits:
    """The pose fits of a full frame, against the tracker's `map` (read, never changed here)."""

    def __init__(self, config: TrackerConfig, camera: Camera, the_map: Map, motion: MotionModel,
                 handover: Handover):
        self.config = config
        self.camera = camera
        self.K = camera.K.copy()
        self.map = the_map
        self.motion = motion
        self.handover = handover

    def match(self, pose, X, D, feats: Features, radius: float):
        """Map points X (N,3) with descriptors D matched to `feats` by projection from `pose`: (point
        indices, feature indices)."""
        return match_by_projection(self.K, self.camera.width, self.camera.height, pose, X, D, feats, radius)

    def track_map(self, init, X, D, feats):
        """Pose from map points alone: projection matching, Huber refinement, RANSAC and wider search as
        fallbacks. (pose, point indices, feature indices, inlier mask) or four Nones."""
        min_inliers, radius0 = self.config.min_inliers, self.config.radius
        for radius in (radius0, 3 * radius0):
            pi, fi = self.match(init, X, D, feats, radius)
            if pi.size < min_inliers:
                continue
            p, inl, _ = refine_pose(self.K, init, X[pi], feats.und[fi])
            if inl.sum() < max(min_inliers, 0.4 * pi.size):
                pr, mask = pnp_ransac(self.K, X[pi], feats.und[fi], guess=init)
                if pr is None or mask.sum() < min_inliers:
                    continue
                p, inl, _ = refine_pose(self.K, pr, X[pi][mask], feats.und[fi][mask])
                full = np.zeros(pi.size, bool)
                full[np.nonzero(mask)[0][inl]] = True
                inl = full
            if inl.sum() >= min_inliers:
                return p, pi, fi, inl
        return None, None, None, None

    def with_anchors(self, ar, anchor_pose, init, corners_w, corners_uv, feats, arrays, young: bool, t: float,
                     lost: int) -> Fit:
        """Anchors seen: one robust fit of their corners and the map points matched near them (the
        corners dominate; where the map disagrees, the markers win and bundle adjustment corrects the
        map), from `init` (`anchor_pose`, the anchors' raw pose, or the motion model's prediction when
        that pose is implausible: a flipped planar solution). The anchors' own pose is what is shown
        while they are in view. `arrays`: the map's (ids, X, D)."""
        cfg = self.config
        ids, X, D = arrays
        pi, fi = self.match(init, X, D, feats, cfg.radius)
        if getattr(ar, "desk", False):
            # a lone head-on marker whose tilt the desk around it decided (tracking.anchors.desk): its four
            # corners fit the other tilt as well, and the map (the same desk's points) pulled the joint fit
            # there now and then (9 degrees off, then shown as the anchors' pose read as a jump from it): the
            # desk's pose is the frame's, the map's points are only classified under it
            nc = len(corners_w)
            _, inl, _ = refine_pose(self.K, anchor_pose, np.concatenate([corners_w, X[pi]]),
                                    np.concatenate([corners_uv, feats.und[fi]]), iterations=0)
            source, out_pose, exact = self._shown(ar, inl[nc:], corners_w, t, lost)
            return Fit(anchor_pose, "marker", int(inl.sum()), ids[pi[inl[nc:]]], fi[inl[nc:]], X[pi[inl[nc:]]],
                       ids[pi], source, out_pose, exact)
        share = 0.8 if young else cfg.corner_share   # a young map must not pull the markers
        p, cin, min_, _ = fuse_pose(self.K, init, corners_w, corners_uv, X[pi], feats.und[fi], cfg.corner_weight,
                                    corner_share=share)
        if cin.any() and share < 0.8:
            cerr = np.linalg.norm(self.camera.project_world(corners_w, p) - self.camera.project_world(
                corners_w, anchor_pose), axis=1).max()
            if cerr > 1.5:   # map and markers disagree: the markers win, BA corrects the map
                p, cin, min_, _ = fuse_pose(self.K, init, corners_w, corners_uv, X[pi], feats.und[fi],
                                            cfg.corner_weight, corner_share=0.8)
        if cin.mean() < 0.75 and init is not anchor_pose:
            p, cin, min_, _ = fuse_pose(self.K, anchor_pose, corners_w, corners_uv, X[pi], feats.und[fi],
                                        cfg.corner_weight, corner_share=cfg.corner_share)
        if cin.mean() < 0.75:
            # the map disagrees with the markers: trust the markers, the map gets corrected by BA
            p, cin, _ = refine_pose(self.K, anchor_pose, corners_w, corners_uv)
            min_ = np.zeros(pi.size, bool)
        source, out_pose, exact = self._shown(ar, min_, corners_w, t, lost)
        return Fit(p, "marker", int(cin.sum() + min_.sum()), ids[pi[min_]], fi[min_], X[pi[min_]], ids[pi],
                   source, out_pose, exact)

    def _shown(self, ar, map_inliers, corners_w, t, lost: int):
        """(source, pose to show, precise) of a joint fit: the anchors' own pose while they are in view, else
        (None, None, False): the fit itself."""
        if (self.config.anchor_first and anchor_usable(ar)
                and (lost > 0 or self.handover.plausible(anchor_output(ar), self.motion.last, t))):
            # the anchors' pose is what is shown while they are in view (a jump the motion cannot
            # explain is left to the joint fit); the fit places this frame in the map
            return "anchors", anchor_output(ar), precise(ar)
        if map_inliers.sum() < self.config.min_inliers and ar.world_from_camera is not None and len(corners_w) < 12:
            # the map does not help yet and one marker's pose is noisy: the anchors' filtered pose
            # (a board's many corners are precise as they are; its filter would only add lag)
            return "anchors", np.asarray(ar.world_from_camera, float), False
        return None, None, False

    def from_map(self, feats, pred, arrays, t) -> Fit | None:
        """No anchors: the pose from map points alone (from the motion's prediction, else by
        relocalising against keyframes and confirming by projection matching), or None.
        `arrays`: the map's (ids, X, D)."""
        ids, X, D = arrays
        min_inliers = self.config.min_inliers
        if X.shape[0] < min_inliers:
            return None
        if pred is not None:
            p, pi, fi, inl = self.track_map(pred, X, D, feats)
            if p is not None and self.handover.plausible(p, self.motion.last, t):
                return Fit(p, "slam", int(inl.sum()), ids[pi[inl]], fi[inl], X[pi[inl]], ids[pi])
        if len(feats) < min_inliers:
            return None
        p, _ = relocalise(self.map, feats, self.K, near=self.motion.last)
        if p is None:
            return None
        p2, pi, fi, inl = self.track_map(p, X, D, feats)
        if p2 is None or not (self.motion.last is None or self.handover.plausible(p2, self.motion.last, t, lost=True)):
            return None
        return Fit(p2, "slam", int(inl.sum()), ids[pi[inl]], fi[inl], X[pi[inl]], ids[pi])
