"""Views for a scan: every frame tracked by arapp's tracker, then a few chosen by sharpness and baseline.

A `View` holds an undistorted BGR image (pinhole `K`, no distortion: every
later step works on these), its metric pose `world_from_camera` (4x4, OpenCV
camera axes, metres in the recording's world frame), its sharpness
(variance of the Laplacian of the grey image, grey levels squared) and, when
the source gives depth (a depth camera, a recording with a depth stream), its
depth map on the undistorted image's pixels (float32 metres along the
camera's z, 0 = none).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import warnings

import cv2
import numpy as np

from tracking.sources import SourceWarning
from tracking.fusion import Tracker


class ScanCancelled(Exception):
    """The scan was stopped (Ctrl-C or a cancel event) before anything was written."""


@dataclass
class View:
    index: int
    t: float
    image: np.ndarray
    pose: np.ndarray
    sharpness: float
    depth: np.ndarray | None = None

    @property
    def center(self) -> np.ndarray:
        return self.pose[:3, 3]

    @property
    def axis(self) -> np.ndarray:
        return self.pose[:3, 2]


def sharpness(gray: np.ndarray) -> float:
    """Variance of the Laplacian: high for crisp frames, low for motion-blurred or defocused ones."""
    return float(cv2.Laplacian(gray, cv2.CV_32F).var())


def track_views(source, camera, anchors, progress: Callable[[str, int, int], None] | None = None,
                cancel=None, max_frames: int | None = None, every: int = 1) -> list[View]:
    """Run the tracker (anchors only: the markers give metric poses; keypoint SLAM adds nothing while
    the board is in view) over `source`; keep the frames it placed from the markers, undistorted (their
    depth too, when frames carry it). A recording that ends with an error (a damaged video or depth
    file) stops the scan with that error rather than scanning part of it."""
    tracker = Tracker(camera, anchors, slam=False, filter=False)
    maps = None
    if np.any(camera.dist != 0):
        maps = cv2.initUndistortRectifyMap(camera.K, camera.dist, None, camera.K, (camera.width, camera.height),
                                           cv2.CV_32FC1)
    total = getattr(source, "frame_count", 0) or 0
    if max_frames:
        total = min(total, max_frames) if total else max_frames
    views: list[View] = []
    n = 0
    # a source's early end is warned from inside the loop; held here, it becomes the scan's one error line
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SourceWarning)
        try:
            for frame in source:
                if cancel is not None and cancel.is_set():
                    raise ScanCancelled()
                if max_frames is not None and n >= max_frames:
                    break
                n += 1
                res = tracker.process(frame.image, frame.t)
                if progress is not None:
                    progress("tracking", n, total)
                if res.world_from_camera is None or res.state != "marker" or (n - 1) % every:
                    continue
                img = frame.image if maps is None else cv2.remap(frame.image, maps[0], maps[1], cv2.INTER_LINEAR)
                depth = getattr(frame, "depth", None)
                if depth is not None and maps is not None:
                    # nearest, not linear: blending depths across an occluding edge invents surfaces
                    depth = cv2.remap(depth, maps[0], maps[1], cv2.INTER_NEAREST)
                gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                views.append(View(frame.index, frame.t, img, np.array(res.world_from_camera, float), sharpness(gray),
                                  depth))
        finally:
            tracker.close()
    error = getattr(source, "error", None)
    if error and error != getattr(source, "notice", None) and not getattr(source, "live", False):
        raise RuntimeError(f"{error}; nothing was scanned")
    for w in caught:   # not an error for the scan (a live camera's end): passed on as they came
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return views


def look_at_point(views: list[View]) -> np.ndarray:
    """The world point closest (least squares) to all the views' optical axes: what the user circled."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for v in views:
        d = v.axis / np.linalg.norm(v.axis)
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ v.center
    return np.linalg.lstsq(A, b, rcond=None)[0]


def select_views(views: list[View], max_views: int = 24, min_angle_deg: float = 7.0,
                 min_sharpness_ratio: float = 0.5) -> list[View]:
    """Choose views by sharpness and baseline. Frames blurrier than `min_sharpness_ratio` times their
    neighbours' median are dropped; of the rest, the sharpest starts and each next view is the one
    seen from the look-at point at the largest angle from every view chosen so far (farthest-point
    sampling of view directions: even coverage, wide baselines), while that angle is at least
    `min_angle_deg`, up to `max_views`. Returned in recording order."""
    if len(views) < 2:
        return list(views)
    target = look_at_point(views)
    dirs = np.array([v.center - target for v in views])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    sharp = np.array([v.sharpness for v in views])
    # blur is judged against the neighbouring frames (the scene's texture changes around the orbit)
    local = np.array([np.median(sharp[max(0, i - 5): i + 6]) for i in range(len(views))])
    ok = np.nonzero(sharp >= min_sharpness_ratio * local)[0]
    if len(ok) == 0:
        return []
    chosen = [int(ok[np.argmax(sharp[ok])])]
    gap = np.degrees(np.arccos(np.clip(dirs[ok] @ dirs[chosen[0]], -1, 1)))
    while len(chosen) < max_views:
        k = int(np.argmax(gap))
        if gap[k] < min_angle_deg:
            break
        chosen.append(int(ok[k]))
        gap = np.minimum(gap, np.degrees(np.arccos(np.clip(dirs[ok] @ dirs[ok[k]], -1, 1))))
    return [views[i] for i in sorted(chosen)]
