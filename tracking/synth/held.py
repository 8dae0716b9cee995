"""A card held before a camera: the anchors printed on a small textured card that moves in a room, in front
of a textured wall, seen by a still (webcam) or moving camera.

The scene's `held` block (metres, seconds, degrees):

    "held": {"wall": {"distance": 0.8, "size": [3.0, 2.4], "ppm": 500, "seed": 7, "style": "desk"},
             "keys": [{"t": 0.0, "centre": [x, y, z], "rot": [rx, ry, rz]}, ...]}

Room frame: the frame the scene's `trajectory` block (tracking.synth.trajectory) is written in, z up, the
camera's pose `room_from_camera` as that block gives it (nothing added: a webcam is kind `static`, e.g.
azimuth -90, distance 0.45, elevation 4 from the target [0, 0, 0]). The wall is the vertical plane
y = `wall.distance`, facing -y (toward such a camera). The card is the scene's desk cut to `desk.size`
around the anchors' centre (its texture, the anchors printed on it); each key puts the anchors' centre at
`centre` in the room with the card turned by the rotation vector `rot` (degrees, room axes) from upright
facing -y (card x = room x, the card's "away" y = room z up). Keys are joined by clamped cubic splines
(centre and rotation vector), held before the first and after the last: close keys make a fast swing.

Ground truth is the camera in the card's anchor frame: `world_from_camera = world_from_card @
inv(room_from_card(t)) @ room_from_camera(t)`, what a model on the card is drawn from. Global shutter
only (`rolling_shutter` must be 0); motion blur averages as many sub-frame renders as the image moves
pixels over the exposure (up to `blur_samples`), so still frames cost one render.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from tracking.errors import SessionError
from tracking.poses import invert, make_pose
from tracking.synth.renderer import DeskRenderer
from tracking.synth.texture import STYLES
from tracking.synth.trajectory import make_trajectory

WALL_DEFAULTS = {"distance": 0.8, "size": [3.0, 2.4], "ppm": 500.0, "seed": 0, "style": "desk"}


def check_held(held, rolling_shutter, where: str = "held") -> None:
    """Validate a `held` block; errors are SessionErrors naming the field."""
    if not isinstance(held, dict):
        raise SessionError(f"{where}: must be an object with wall and keys")
    for k in held:
        if k not in ("wall", "keys"):
            raise SessionError(f"{where}.{k}: unknown key (known: keys, wall)")
    wall = held.get("wall", {})
    if not isinstance(wall, dict) or any(k not in WALL_DEFAULTS for k in wall):
        raise SessionError(f"{where}.wall: must be an object with keys {', '.join(WALL_DEFAULTS)}")
    size = wall.get("size", WALL_DEFAULTS["size"])
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(s, (int, float)) and s > 0 for s in size)):
        raise SessionError(f"{where}.wall.size: must be [width, height] in metres, got {size!r}")
    if wall.get("style", "desk") not in STYLES:
        raise SessionError(f"{where}.wall.style: must be one of {', '.join(STYLES)}")
    keys = held.get("keys")
    if not isinstance(keys, list) or len(keys) < 2:
        raise SessionError(f"{where}.keys: need at least two keys {{t, centre [x, y, z], rot [rx, ry, rz]}}")
    for i, k in enumerate(keys):
        ok = (isinstance(k, dict) and isinstance(k.get("t"), (int, float))
              and all(isinstance(k.get(n, [0, 0, 0]), list) and len(k.get(n, [0, 0, 0])) == 3
                      and all(isinstance(v, (int, float)) for v in k.get(n, [0, 0, 0])) for n in ("centre", "rot"))
              and "centre" in k)
        if not ok:
            raise SessionError(f"{where}.keys[{i}]: must be {{t: s, centre: [x, y, z] m, rot: [rx, ry, rz] deg}}")
    if np.any(np.diff([k["t"] for k in keys]) <= 0):
        raise SessionError(f"{where}.keys: times must increase")
    if float(rolling_shutter or 0.0) > 0:
        raise SessionError(f"{where}: a held card is rendered with a global shutter; set effects.rolling_shutter to 0")


# the card upright facing -y: card x = room x, card y ("away" on a desk) = room z, card z (out of the paper) = -y
UPRIGHT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def card_path(keys: list[dict]):
    """`t -> room_from_card_centre` (4x4): the card's pose in the room, its origin at the anchors' centre."""
    ts = np.array([k["t"] for k in keys], float)
    c = CubicSpline(ts, np.array([k["centre"] for k in keys], float), bc_type="clamped")
    r = CubicSpline(ts, np.radians(np.array([k.get("rot", [0, 0, 0]) for k in keys], float)), bc_type="clamped")

    def pose(t: float) -> np.ndarray:
        tc = float(np.clip(t, ts[0], ts[-1]))
        return make_pose(Rotation.from_rotvec(r(tc)).as_matrix() @ UPRIGHT, c(tc))

    return pose


class HeldRenderer:
    """Renders a scene with a `held` block: `render(i)` -> (BGR uint8 frame, world_from_camera, t), as
    `DeskRenderer` does for a desk."""

    def __init__(self, scene):
        self.scene = scene
        held = scene.held
        # the card: the scene's desk (cut to its size) with the anchors printed on it
        self.card = DeskRenderer(scene)
        wall = {**WALL_DEFAULTS, **held.get("wall", {})}
        wall_scene = dataclasses.replace(scene, desk_size=tuple(float(s) for s in wall["size"]),
                                         desk_ppm=float(wall["ppm"]), desk_seed=int(wall["seed"]),
                                         desk_style=str(wall["style"]), effects={**scene.effects, "occluder": None})
        self.wall = DeskRenderer(wall_scene)
        # nothing printed on the wall (the renderer draws its `printed` anchors: emptying `patterns` alone left a
        # copy of the card's marker on the wall, a second detection of the anchor 0.8 m behind the card)
        self.wall.patterns = self.wall.printed = []
        self.card_pose = card_path(held["keys"])
        self.camera_pose = make_trajectory(scene.trajectory, scene.duration, scene.seed)
        # room_from_card_desk = room_from_card_centre @ centre_from_desk (the anchors' centre to the origin)
        self.centre_from_desk = make_pose(np.eye(3), -np.asarray(scene.centre_desk, float))
        self.half = np.asarray(scene.desk_size, float) / 2
        # the wall renderer's desk frame from the room: (x, y, z) -> (x, z, distance - y)
        self.wall_desk_from_room = make_pose(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]),
                                             [0.0, 0.0, float(wall["distance"])])
        self.rng = self.card.rng

    def time_of(self, i: int) -> float:
        return i / self.scene.fps

    def room_from_card_desk(self, t: float) -> np.ndarray:
        return self.card_pose(t) @ self.centre_from_desk

    def world_from_camera(self, t: float) -> np.ndarray:
        """Ground truth at time t: the camera in the card's anchor (world) frame."""
        return self.card.world_from_desk @ invert(self.room_from_card_desk(t)) @ self.camera_pose(t)

    def _room_view(self, t: float) -> np.ndarray:
        """The camera in the wall renderer's world frame at time t."""
        return self.wall.world_from_desk @ self.wall_desk_from_room @ self.camera_pose(t)

    def card_mask(self, world_from_camera: np.ndarray) -> np.ndarray:
        """(H_ss, W_ss) bool: the supersampled pixels whose ray meets the card (in front of the camera,
        within `desk.size` around the anchors' centre)."""
        H, W = self.card.rays.shape[:2]
        mask = np.zeros((H, W), bool)
        region = self.card_region(world_from_camera)
        if region is not None:
            rs, cs, sub = region
            mask[rs, cs] = sub
        return mask

    def _card_mask_in(self, world_from_camera: np.ndarray, rs: slice, cs: slice) -> np.ndarray:
        """`card_mask` on the supersampled pixels [rs, cs] only."""
        rays = np.ascontiguousarray(self.card.rays[rs, cs])
        Hd, valid = self.card.plane_homography(world_from_camera)
        cx, cy = self.scene.centre_desk[:2]
        # desk (x, y) -> ((x - cx) / hx, (y - cy) / hy): the card is |.| <= 1 in both
        to_unit = np.array([[1 / self.half[0], 0, -cx / self.half[0]], [0, 1 / self.half[1], -cy / self.half[1]],
                            [0, 0, 1.0]])
        h, w = rays.shape[:2]
        xy = cv2.perspectiveTransform(rays.reshape(-1, 1, 2), to_unit @ Hd).reshape(h, w, 2)
        inside = cv2.inRange(xy, (-1.0, -1.0), (1.0, 1.0)) > 0
        return inside & valid(rays)

    def card_region(self, world_from_camera: np.ndarray):
        """(rows slice, cols slice, mask of that block) around the card's supersampled pixels, or None when
        the card is out of view: found on a 4-pixel grid first (the card's outline bends little over 4 px),
        then exact within one grid step around what the grid found."""
        step = 4
        H, W = self.card.rays.shape[:2]
        coarse = self._card_mask_in(world_from_camera, slice(None, None, step), slice(None, None, step))
        if not coarse.any():
            return None
        rows, cols = np.nonzero(coarse.any(axis=1))[0], np.nonzero(coarse.any(axis=0))[0]
        rs = slice(max(0, (rows[0] - 1) * step), min(H, (rows[-1] + 2) * step))
        cs = slice(max(0, (cols[0] - 1) * step), min(W, (cols[-1] + 2) * step))
        return rs, cs, self._card_mask_in(world_from_camera, rs, cs)

    def _wall_image(self, t: float) -> np.ndarray:
        """The wall's clean image at time t (a copy), kept for the last camera pose: a still webcam sees the
        same wall in every blur sample and frame."""
        view = self._room_view(t)
        key = view.tobytes()
        if getattr(self, "_wall_key", None) != key:
            self._wall_key, self._wall_img = key, self.wall.render_clean(view)
        return self._wall_img.copy()

    def render_clean(self, t: float) -> np.ndarray:
        """Noise-free supersampled float32 BGR image at time t: the card over the wall."""
        pose = self.world_from_camera(t)
        img = self._wall_image(t)
        region = self.card_region(pose)
        if region is not None:
            rs, cs, mask = region
            sub = img[rs, cs]
            sub[mask] = self.card.render_clean(pose, (rs, cs))[mask]
        return img

    def _image_motion(self, t0: float, t1: float) -> float:
        """Pixels the card's corners or the wall's image corners move between times t0 and t1."""
        cam = self.scene.camera
        cx, cy = self.scene.centre_desk[:2]
        hx, hy = self.half
        desk = np.array([[cx - hx, cy - hy, 0, 1], [cx + hx, cy - hy, 0, 1], [cx + hx, cy + hy, 0, 1],
                         [cx - hx, cy + hy, 0, 1]], float)
        card_world = (self.card.world_from_desk @ desk.T).T[:, :3]
        wall_pts = []
        P0 = self._room_view(t0)   # the wall is its renderer's world plane z = 0
        for u, v in ((0, 0), (cam.width - 1, 0), (0, cam.height - 1), (cam.width - 1, cam.height - 1)):
            ray = cam.unproject(np.array([[u, v]], float)).reshape(-1)
            d = P0[:3, :3] @ ray
            s = -P0[2, 3] / d[2] if abs(d[2]) > 1e-9 else 0.0
            wall_pts.append(P0[:3, 3] + s * d)
        moved = 0.0
        for pts, pose in ((card_world, self.world_from_camera), (np.array(wall_pts), self._room_view)):
            a, b = cam.project_world(pts, pose(t0)), cam.project_world(pts, pose(t1))
            moved = max(moved, float(np.nanmax(np.linalg.norm(a - b, axis=1))))
        return moved

    def render(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Frame i with all effects: (BGR uint8 image, world_from_camera at its time, t seconds)."""
        sc, fx = self.scene, self.scene.effects
        t = self.time_of(i)
        pose = self.world_from_camera(t)
        blur = float(fx.get("motion_blur") or 0.0)
        exposure = blur / sc.fps
        n = 1
        if blur > 0:
            # one sub-frame render for every ~1.5 px the image moves over the exposure (a still card: one)
            moved = self._image_motion(t - exposure / 2, t + exposure / 2)
            n = int(min(max(1, math.ceil(moved / 1.5)), max(2, int(fx.get("blur_samples", 7)))))
        if n > 1:
            offsets = (np.arange(n) + 0.5) / n - 0.5
            img = sum(self.render_clean(t + o * exposure) for o in offsets) / n
        else:
            img = self.render_clean(t)
        img = cv2.resize(img, (sc.camera.width, sc.camera.height), interpolation=cv2.INTER_AREA)
        card = self.card
        if card.ae is not None and i != card._next_index:
            card.ae.reset()
        card._next_index = i + 1
        return card._camera_response(img, t), pose, t


def make_renderer(scene):
    """The renderer for `scene`: `HeldRenderer` when it has a `held` block, else `DeskRenderer`."""
    return HeldRenderer(scene) if getattr(scene, "held", None) else DeskRenderer(scene)
