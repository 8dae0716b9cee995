"""A synthetic scan recording with exact ground truth: a textured vase standing on an ArUco GridBoard.

    truth = write_vase_recording("recordings/scan_vase")   # arapp-recording/1 folder + VaseTruth

The scene (world = the GridBoard frame of docs/recording-format.md: origin at the
outer corner of the first marker, x right, y down the board, z into the paper,
so "up" is -z; metres):

- a desk plane (random texture) 2 mm below the paper;
- the printed board (6 x 6 markers of 24 mm, 8 mm apart) on white paper;
- a vase: a closed surface of revolution about the vertical line through the
  board centre, radius `VaseTruth.radius(h)` at height h above the paper,
  flat bottom on the paper and a flat top, painted with a random texture.

The camera orbits the vase at two elevations looking at its middle. Images are
rendered with pyrender offscreen (unlit textures: a Lambertian surface under
ambient light, so colours do not change with the view) and written through
tracking.recording.writer.RecordingWriter (lossless FFV1 when available) with
groundtruth.tum. Ground-truth depth maps are returned on request (the
benchmark's ceiling peer fuses them) and, with `with_depth=True`, written as
the recording's depth stream (16-bit PNG, millimetres: what a depth camera's
recording holds, docs/recording-format.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from PIL import Image
import trimesh

from tracking.camera import Camera
from tracking.recording.writer import RecordingWriter

# vase geometry (metres)
VASE_HEIGHT = 0.060
VASE_R0 = 0.022      # mean radius
VASE_BULGE = 0.006   # radius swing along the height
BOARD = dict(kind="aruco_board", dictionary="DICT_4X4_50", markers_x=6, markers_y=6,
             marker_length=0.024, separation=0.008, first_id=0)
PAPER_MARGIN = 0.012
DESK_DROP = 0.002    # the desk lies this far below the paper (the paper's thickness, exaggerated)


@dataclass
class VaseTruth:
    """What the synthetic scan shows: the vase's axis (a vertical line through `center`, metres in the
    world frame), its height and radius profile, the world's up direction and the true mesh."""

    center: np.ndarray        # (3,) centre of the vase's bottom disk, on the paper (z = 0)
    up: np.ndarray            # (3,) unit up vector in the world frame ((0, 0, -1) for a GridBoard)
    height: float
    mesh: trimesh.Trimesh     # the true closed surface, world frame, metres

    @staticmethod
    def radius(h: np.ndarray) -> np.ndarray:
        """Vase radius (m) at height h (m) above the paper: a smooth bulge, wider below the middle."""
        s = np.asarray(h, float) / VASE_HEIGHT
        return VASE_R0 + VASE_BULGE * np.sin(np.pi * s * 1.3 + 0.2)

    @property
    def volume(self) -> float:
        h = np.linspace(0.0, self.height, 2001)
        return float(np.trapezoid(np.pi * self.radius(h) ** 2, h))


def board_extent() -> tuple[float, float]:
    """(width, height) of the board's marker area, metres."""
    w = BOARD["markers_x"] * BOARD["marker_length"] + (BOARD["markers_x"] - 1) * BOARD["separation"]
    h = BOARD["markers_y"] * BOARD["marker_length"] + (BOARD["markers_y"] - 1) * BOARD["separation"]
    return w, h


def vase_truth() -> VaseTruth:
    w, h = board_extent()
    center = np.array([w / 2, h / 2, 0.0])
    up = np.array([0.0, 0.0, -1.0])
    return VaseTruth(center, up, VASE_HEIGHT, _vase_mesh(center, up, 180, 120))


def _vase_mesh(center, up, n_around: int, n_along: int) -> trimesh.Trimesh:
    """Closed triangle mesh of the vase (side, bottom and top disks), world frame, with UVs for a texture."""
    hs = np.linspace(0.0, VASE_HEIGHT, n_along + 1)
    rs = VaseTruth.radius(hs)
    ang = np.linspace(0.0, 2 * np.pi, n_around + 1)  # duplicated seam column for the texture's u
    # local frame: e1, e2 horizontal, up
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(up, e1)
    verts, uvs, faces = [], [], []
    for i, (hh, r) in enumerate(zip(hs, rs)):
        for j, a in enumerate(ang):
            verts.append(center + up * hh + r * (np.cos(a) * e1 + np.sin(a) * e2))
            uvs.append([j / n_around, 0.5 + 0.5 * i / n_along])
    m = n_around + 1
    for i in range(n_along):
        for j in range(n_around):
            a, b, c, d = i * m + j, i * m + j + 1, (i + 1) * m + j + 1, (i + 1) * m + j
            faces += [[a, b, c], [a, c, d]]
    # caps: fans around a centre vertex; the texture's lower half holds them
    for hh, r, flip in ((0.0, rs[0], True), (VASE_HEIGHT, rs[-1], False)):
        c_idx = len(verts)
        verts.append(center + up * hh)
        uvs.append([0.25 if flip else 0.75, 0.25])
        ring = []
        for j in range(n_around):
            a = ang[j]
            ring.append(len(verts))
            verts.append(center + up * hh + r * (np.cos(a) * e1 + np.sin(a) * e2))
            uvs.append([(0.25 if flip else 0.75) + 0.2 * np.cos(a), 0.25 + 0.2 * np.sin(a)])
        for j in range(n_around):
            f = [c_idx, ring[j], ring[(j + 1) % n_around]]
            faces.append(f[::-1] if flip else f)  # bottom faces down, top up
    mesh = trimesh.Trimesh(np.array(verts), np.array(faces), process=False)
    mesh.visual = trimesh.visual.TextureVisuals(uv=np.array(uvs))
    return mesh


def _noise_texture(rng: np.random.Generator, size: int, colorful: bool) -> np.ndarray:
    """RGB uint8 texture with detail at several scales (what dense matching needs)."""
    tex = np.zeros((size, size, 3), np.float32)
    for scale, amp in ((8, 0.4), (32, 0.4), (128, 0.5), (256, 0.4)):
        small = rng.random((scale, scale, 3)).astype(np.float32)
        tex += amp * cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    if not colorful:
        tex = tex.mean(axis=2, keepdims=True).repeat(3, axis=2)
    return np.clip(tex * 200 + 30, 0, 255).astype(np.uint8)


def _board_image(px_per_m: float) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The printed board on white paper (RGB) and its extent (x0, y0, x1, y1) in the board frame."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, BOARD["dictionary"]))
    n = BOARD["markers_x"] * BOARD["markers_y"]
    board = cv2.aruco.GridBoard((BOARD["markers_x"], BOARD["markers_y"]), BOARD["marker_length"],
                                BOARD["separation"], d, np.arange(BOARD["first_id"], BOARD["first_id"] + n))
    w, h = board_extent()
    m = PAPER_MARGIN
    size = (int(round((w + 2 * m) * px_per_m)), int(round((h + 2 * m) * px_per_m)))
    img = board.generateImage(size, marginSize=int(round(m * px_per_m)), borderBits=1)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), (-m, -m, w + m, h + m)


def _quad(x0, y0, x1, y1, z, image) -> trimesh.Trimesh:
    """A textured rectangle in the plane z (board frame), image row 0 at y0 (y runs down the board)."""
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], float)  # texture v runs up the image
    mesh = trimesh.Trimesh(v, np.array([[0, 2, 1], [0, 3, 2]]), process=False)  # faces toward -z (up)

    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(image))
    return mesh


def orbit_poses(truth: VaseTruth, n_frames: int, distance: float = 0.30,
                elevations_deg=(32.0, 58.0)) -> list[np.ndarray]:
    """world_from_camera (OpenCV axes) along circles around the vase at the given elevations,
    looking at the vase's middle; frames split evenly between the circles."""
    target = truth.center + truth.up * truth.height * 0.5
    poses = []
    per = [n_frames // len(elevations_deg) + (1 if i < n_frames % len(elevations_deg) else 0)
           for i in range(len(elevations_deg))]
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(truth.up, e1)
    for k, (elev, n) in enumerate(zip(elevations_deg, per)):
        el = np.radians(elev)
        for i in range(n):
            az = 2 * np.pi * i / n + k * np.pi / n  # the second circle interleaves with the first
            eye = target + distance * (np.cos(el) * (np.cos(az) * e1 + np.sin(az) * e2) + np.sin(el) * truth.up)
            z = target - eye
            z /= np.linalg.norm(z)
            x = np.cross(z, truth.up)  # image right; image down = z x x
            x /= np.linalg.norm(x)
            y = np.cross(z, x)
            T = np.eye(4)
            T[:3, :3] = np.column_stack([x, y, z])
            T[:3, 3] = eye
            poses.append(T)
    return poses


def default_K(width: int, height: int) -> np.ndarray:
    f = 0.95 * width
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])


def render_scan(poses: list[np.ndarray], K: np.ndarray, width: int, height: int, seed: int = 7,
                noise_std: float = 1.0, with_depth: bool = False):
    """Render the scene from each pose: list of BGR uint8 images (and metric depth maps, 0 = nothing)."""
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    import pyrender  # GL: loaded only where the synthetic images are rendered

    rng = np.random.default_rng(seed)
    truth = vase_truth()
    scene = pyrender.Scene(bg_color=[0.1, 0.1, 0.1, 1.0], ambient_light=[1.0, 1.0, 1.0])
    vase = truth.mesh.copy()

    vase.visual = trimesh.visual.TextureVisuals(uv=truth.mesh.visual.uv,
                                                image=Image.fromarray(_noise_texture(rng, 1024, True)))
    board_img, (x0, y0, x1, y1) = _board_image(4000.0)
    desk_img = _noise_texture(rng, 1024, True) // 2 + 40
    w, h = board_extent()
    for mesh in (vase, _quad(x0, y0, x1, y1, 0.0, board_img),
                 _quad(-0.25, -0.25, w + 0.25, h + 0.25, DESK_DROP, desk_img)):
        scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=False))
    # GL pixel centres are at +0.5 of OpenCV's (integer centres): shift the principal point to match
    cam = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5, znear=0.01, zfar=3.0)
    node = scene.add(cam, pose=np.eye(4))
    r = pyrender.OffscreenRenderer(width, height)
    flip = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes -> OpenGL's
    images, depths = [], []
    try:
        for T in poses:
            scene.set_pose(node, T @ flip)
            color, depth = r.render(scene, flags=pyrender.RenderFlags.FLAT)
            img = color.astype(np.float32)
            if noise_std > 0:
                img += rng.normal(0.0, noise_std, img.shape)
            images.append(cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_RGB2BGR))
            depths.append(depth.astype(np.float32))
    finally:
        r.delete()
    return (images, depths) if with_depth else images


def write_vase_recording(folder: str | Path, n_frames: int = 48, width: int = 640, height: int = 480,
                         distance: float = 0.30, seed: int = 7, force: bool = True,
                         with_depth: bool = False) -> VaseTruth:
    """Render the orbit and write it as an arapp-recording/1 folder with groundtruth.tum (and, with
    `with_depth`, the renderer's exact depth as the depth stream, rounded to 1 mm); returns the truth."""
    truth = vase_truth()
    K = default_K(width, height)
    poses = orbit_poses(truth, n_frames, distance)
    if with_depth:
        images, depths = render_scan(poses, K, width, height, seed, with_depth=True)
    else:
        images, depths = render_scan(poses, K, width, height, seed), [None] * len(poses)
    camera = Camera(K, np.zeros(5), width, height)
    fps = 10.0
    with RecordingWriter(folder, camera, fps, anchors=[dict(BOARD)], source={"kind": "synthetic", "scene": "scan_vase"},
                         fourcc="FFV1", force=force) as wr:
        for i, (img, T, depth) in enumerate(zip(images, poses, depths)):
            wr.write(img, i / fps, T, depth=depth)
    return truth
