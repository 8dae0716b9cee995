"""A virtual camera orbiting a model: what the view shows when no marker is seen (or no source is open).
No Qt, no GL; the GUI renders with arapp.render at the pose this gives.

The orbit is around the centre of the model's bounding box, in the model's own frame and units
(z up, as models stand on the printer bed), at `azimuth_deg` around z and `elevation_deg` above the
xy plane. At zoom 1 the bounding sphere fills `FILL` of the shorter image side; the wheel multiplies
the zoom. The camera is a pinhole with square pixels, centred, no distortion, `FOV_DEG` across the
shorter side.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tracking.anchors.render import look_at
from tracking.camera import Camera
from tracking.poses import invert

FOV_DEG = 35.0        # across the shorter image side: a mild telephoto, little perspective distortion
FILL = 0.8            # share of the shorter side the bounding sphere spans at zoom 1
ZOOM_RANGE = (0.2, 8.0)
ELEVATION_RANGE = (-85.0, 85.0)  # short of the poles, where "up" stops being defined
DEG_PER_PIXEL = 0.4   # drag: a 450 px drag is half a turn


@dataclass(frozen=True)
class Orbit:
    """Where the virtual camera sits: degrees around z and above the xy plane, and a zoom factor."""

    azimuth_deg: float = -60.0
    elevation_deg: float = 25.0
    zoom: float = 1.0

    def dragged(self, dx_px: float, dy_px: float) -> "Orbit":
        """Turned by a pointer drag of (dx, dy) screen pixels: right turns the model right, down tilts it."""
        el = float(np.clip(self.elevation_deg + dy_px * DEG_PER_PIXEL, *ELEVATION_RANGE))
        return replace(self, azimuth_deg=(self.azimuth_deg - dx_px * DEG_PER_PIXEL) % 360.0, elevation_deg=el)

    def zoomed(self, notches: float) -> "Orbit":
        """Zoomed by wheel notches (positive: nearer), 15 % a notch."""
        return replace(self, zoom=float(np.clip(self.zoom * 1.15 ** notches, *ZOOM_RANGE)))


def virtual_camera(width: int, height: int) -> Camera:
    """The orbit view's camera for a picture of `width` x `height` pixels."""
    f = 0.5 * min(width, height) / np.tan(np.radians(FOV_DEG) / 2)
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]], float)
    return Camera(K, np.zeros(5), int(width), int(height))


def bounds(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the bounding box's circumscribed sphere of (N, 3) vertices (model units)."""
    v = np.asarray(vertices, float).reshape(-1, 3)
    lo, hi = v.min(0), v.max(0)
    return (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 1e-9)


def camera_from_model(orbit: Orbit, vertices: np.ndarray, camera: Camera) -> np.ndarray:
    """4x4 camera_from_model (OpenCV camera axes, model units) of `camera` on `orbit` around `vertices`."""
    centre, radius = bounds(vertices)
    half = np.radians(FOV_DEG) / 2
    # the sphere's angular radius should be FILL of the half field of view
    distance = radius / np.sin(np.arctan(FILL * np.tan(half))) / orbit.zoom
    az, el = np.radians(orbit.azimuth_deg), np.radians(orbit.elevation_deg)
    eye = centre + distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return invert(look_at(eye, centre, up=(0.0, 0.0, 1.0)))
