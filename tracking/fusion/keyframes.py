"""When a tracked frame becomes a keyframe for the mapping thread (`tracking.slam.mapping.LocalMapper`), and
how offline drivers keep the map at the pace it would have live (`Keyframes.catch_up`)."""

from __future__ import annotations

import numpy as np

from tracking.fusion.config import TrackerConfig
from tracking.poses import rotation_angle
from tracking.slam.map import Map
from tracking.slam.mapping import KeyframeRequest, LocalMapper


class Keyframes:
    """The keyframe policy over one map: the last keyframe's frame (`last_frame`) and inlier count, the
    anchor keyframes so far, the scene depth, and the requests the mapper has not been waited for."""

    def __init__(self, config: TrackerConfig, the_map: Map, mapper: LocalMapper | None):
        self.config = config
        self.map = the_map
        self.mapper = mapper
        self.last_frame = -(10**9)
        self.inliers = 0
        self.anchor_kfs = 0
        self.depth = 0.5
        self.submissions: list[tuple[int, int]] = []   # (frame, mapper request number)

    def consider(self, frame: int, t, pose, feats, inl_ids, inl_feat, corners_w, corners_uv, state, inl_xyz,
                 inliers) -> None:
        """Submit frame `frame` (at t, `pose` world_from_camera, state "marker" / "slam") as a keyframe when it
        adds to the map: the first anchor frames, then on parallax, turn or thinning matches. `inl_ids`,
        `inl_feat`, `inl_xyz`: the map points it matched, their features and positions (N,3);
        `corners_w`, `corners_uv`: the anchors' corners (world (M,3), undistorted pixels (M,2))."""
        if self.mapper is None or len(feats) < 50:
            return
        # scene depth from what we see: matched map points, else the anchors
        pts = inl_xyz if len(inl_xyz) else corners_w
        if len(pts):
            d = np.linalg.norm(pts - pose[:3, 3], axis=1)
            self.depth = float(np.median(d))
        nkf = len(self.map.keyframes)   # (read before `pending`: the mapping thread may add one in between)
        if self.mapper.pending >= self.config.max_pending:
            return   # mapping is behind: no waiting here, a later frame asks again
        if not self._needed(frame, pose, state, inliers, nkf):
            return
        pid = np.full(len(feats), -1, int)
        pid[inl_feat] = inl_ids
        self.mapper.submit(KeyframeRequest(t, pose.copy(), feats, pid, corners_w if state == "marker" else None,
                                           corners_uv if state == "marker" else None))
        self.submissions.append((frame, self.mapper.submitted))
        self.last_frame = frame
        self.inliers = max(inliers, 1)
        self.anchor_kfs += state == "marker"

    def _needed(self, frame: int, pose, state: str, inliers: int, nkf: int) -> bool:
        cfg = self.config
        if nkf == 0 and self.mapper.pending == 0:
            return state == "marker"
        if (state == "marker" and self.anchor_kfs < (4 if cfg.anchor_first else 8)
                and frame - self.last_frame >= 5):
            return True   # early on, every anchor keyframe averages marker noise out of the map
        if frame - self.last_frame < 3:
            return False
        near = self.map.nearest_keyframes(pose, 1)
        if not near:
            return False
        kf = near[0]
        moved = np.linalg.norm(kf.centre - pose[:3, 3]) > cfg.keyframe_parallax * self.depth
        turned = rotation_angle(kf.pose[:3, :3].T @ pose[:3, :3]) > np.radians(8)
        # while the anchors carry the pose, the map only has to cover new views (no keyframe for a
        # thinning match count: each one costs a local bundle adjustment)
        thin = inliers < 0.7 * self.inliers and not (cfg.anchor_first and state == "marker")
        need = moved or turned or thin
        if state == "slam":
            need = need and inliers >= 30  # do not grow the map from a weak keypoint-only pose
        return bool(need)

    def catch_up(self, next_frame: int, lag: int) -> None:
        """Block until every keyframe submitted `lag` or more frames before `next_frame` is mapped."""
        while self.submissions and next_frame - self.submissions[0][0] >= lag:
            _, n = self.submissions.pop(0)
            self.mapper.wait_done(n)
