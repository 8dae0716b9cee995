"""Drawing anchors: printable top views and synthetic camera views with a known pose.

One code path draws the paper, ChArUco squares, ArUco markers and QR symbols
through a homography `pixel_from_plane` (anchor plane, metres -> pixels), so
a printed sheet and a rendered test view are the same picture. Marker bits
are warped with nearest-neighbour sampling: crisp edges; views are
supersampled and averaged down for anti-aliasing.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.kinds.qr import qr_modules
from tracking.anchors.model import AnchorModel, build_models
from tracking.camera import Camera
from tracking.poses import invert
from tracking.anchors.kinds import AnchorSpec

# qr_modules lives with the QR kind (tracking/anchors/kinds/qr.py); named here too
__all__ = ["qr_modules", "plane_layout", "draw_anchor", "render_view", "look_at"]


def plane_layout(model: AnchorModel, margin: float | None = None):
    """What to draw for one anchor, in its plane frame (metres).

    Returns (paper (4,2) corners, black quads list[(4,2)], patches list[(bits image, (4,2) corners TL,TR,BR,BL)]).
    `margin`: white border around the pattern (default: the kind's, e.g. one marker cell / 4 QR modules).
    """
    patches, black, m = model.anchor_kind.layout(model.spec, model.markers, margin)
    pts = [c for _, c in patches] + black
    allp = np.concatenate(pts, axis=0)
    lo, hi = allp.min(axis=0) - m, allp.max(axis=0) + m
    paper = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    return paper, black, patches


def _apply_h(H: np.ndarray, pts2: np.ndarray) -> np.ndarray:
    p = np.c_[pts2, np.ones(len(pts2))] @ H.T
    return p[:, :2] / p[:, 2:3]


def _fill_quad(canvas: np.ndarray, quad: np.ndarray, value: int) -> None:
    shift = 4
    q = np.round(quad * (1 << shift)).astype(np.int64)
    if np.abs(q).max() > 2**30:
        return
    cv2.fillConvexPoly(canvas, q.astype(np.int32), int(value), lineType=cv2.LINE_8, shift=shift)


def _warp_patch(canvas: np.ndarray, bits: np.ndarray, quad: np.ndarray) -> None:
    """Warp a bit image whose outer corners land on `quad` (pixels) into `canvas`, nearest neighbour."""
    h, w = bits.shape
    src = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], np.float64)
    x0 = max(int(np.floor(quad[:, 0].min())) - 1, 0)
    y0 = max(int(np.floor(quad[:, 1].min())) - 1, 0)
    x1 = min(int(np.ceil(quad[:, 0].max())) + 2, canvas.shape[1])
    y1 = min(int(np.ceil(quad[:, 1].max())) + 2, canvas.shape[0])
    if x1 <= x0 or y1 <= y0:
        return
    H = cv2.getPerspectiveTransform(src.astype(np.float32), (quad - [x0, y0]).astype(np.float32))
    size = (x1 - x0, y1 - y0)
    warped = cv2.warpPerspective(bits, H, size, flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    mask = cv2.warpPerspective(np.full_like(bits, 255), H, size, flags=cv2.INTER_NEAREST,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    roi = canvas[y0:y1, x0:x1]
    np.copyto(roi, warped, where=mask > 0)


def draw_anchor(canvas: np.ndarray, model: AnchorModel, pixel_from_plane: np.ndarray, margin: float | None = None,
                paper: bool = True) -> None:
    """Draw one anchor into a gray uint8 canvas through a 3x3 homography (anchor plane metres -> pixels)."""
    paper_q, black, patches = plane_layout(model, margin)
    if paper:
        _fill_quad(canvas, _apply_h(pixel_from_plane, paper_q), 255)
    square = np.zeros((1, 1), np.uint8)
    for q in black:
        _warp_patch(canvas, square, _apply_h(pixel_from_plane, q))
    for bits, q in patches:
        _warp_patch(canvas, bits, _apply_h(pixel_from_plane, q))


def render_view(anchors: list[AnchorSpec] | list[AnchorModel], camera: Camera, world_from_camera: np.ndarray,
                background: int = 110, supersample: int = 3, noise_std: float = 0.0,
                rng: np.random.Generator | None = None, bgr: bool = False, blur: float = 0.6) -> np.ndarray:
    """A synthetic camera image (uint8) of the anchors on white paper seen from `world_from_camera`.

    Rendered pinhole at `supersample` times the resolution, averaged down, blurred by a Gaussian of
    `blur` pixels (the lens; perfectly sharp edges bias corner detectors), distorted with `camera.dist`;
    optional Gaussian pixel noise (`noise_std` grey levels).
    """
    models = anchors if anchors and isinstance(anchors[0], AnchorModel) else build_models(list(anchors))
    s = int(supersample)
    cam_s = camera.scaled(camera.width * s, camera.height * s)
    canvas = np.full((cam_s.height, cam_s.width), background, np.uint8)
    camera_from_world = invert(world_from_camera)
    for m in models:
        cfa = camera_from_world @ m.world_from_anchor
        paper_q, _, _ = plane_layout(m)
        pc = np.c_[paper_q, np.zeros(4)] @ cfa[:3, :3].T + cfa[:3, 3]
        if np.any(pc[:, 2] <= 1e-3):
            continue  # behind (or at) the camera: not drawn
        # The printed side faces the kind's `face` (+z markers and QR codes, -z OpenCV boards): a sheet
        # seen from behind shows no pattern.
        if m.anchor_kind.face * float(cfa[:3, 2] @ -cfa[:3, 3]) <= 0:
            continue
        H = cam_s.K @ np.c_[cfa[:3, 0], cfa[:3, 1], cfa[:3, 3]]
        draw_anchor(canvas, m, H)
    img = cv2.resize(canvas, (camera.width, camera.height), interpolation=cv2.INTER_AREA) if s > 1 else canvas
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if camera.has_distortion:
        mx, my = camera.distort_maps()
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    if noise_std > 0:
        rng = rng or np.random.default_rng(0)
        img = np.clip(img + rng.normal(0, noise_std, img.shape), 0, 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if bgr else img


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """world_from_camera (OpenCV axes) of a camera at `eye` looking at `target`; `up` is world up (image up)."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T
