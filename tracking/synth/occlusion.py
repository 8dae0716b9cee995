"""Synthetic occlusion recordings: a hand or an object passing between the camera and a model, with a depth
stream as a stereo depth camera gives it and ground-truth occlusion masks (docs/occlusion.md).

The scene's `occlusion` block (metres, seconds; desk frame: the world anchor's paper plane, z up out of it):

    "occlusion": {"model": {"size": [0.06, 0.05, 0.09], "offset": [0.0, 0.0]},
                  "occluder": {"kind": "hand" or "object", "start": 0.2, "end": 1.8, "fraction": 0.45,
                               "sweep": 0.18, "radius": 0.03, "height": 0.2},
                  "depth": {"noise_per_m2": 0.003, "baseline": 0.0375, "speckle": 0.004, "flying": 0.4,
                            "fattening_px": 1, "max_range": 3.0}}

- model: the virtual model whose occlusion is measured, a box standing on the desk at the anchors'
  centre plus `offset`: what the product would draw there. Its ground truth comes from ray casting the
  box here, independent of the product's OpenGL renderer.
- occluder: between the model and the camera, at `fraction` of the way from the model's centre to the
  camera, sweeping across the line of sight from -sweep to +sweep (metres, horizontal, perpendicular to
  it) between `start` and `end` (smoothstep). "object": a vertical round post of `radius` and `height`
  standing on the desk (a bottle, a mug's side); "hand": a hand facing the camera (palm, four fingers, a
  thumb and the forearm trailing off the side it comes from), all as unions of spheres, ray cast exactly.
- depth: the depth camera: noise of `noise_per_m2 * z^2` (standard deviation, metres), holes in the strip
  beside near edges that one camera of a stereo pair of `baseline` cannot see (to the left of an object,
  as for a depth aligned to a colour camera between the pair), flying pixels at depth edges (a fraction),
  near edges fattened by `fattening_px`, speckle holes (a fraction of pixels), nothing beyond `max_range`.

Files written besides the recording's own (`synthesize`):
- `depth/NNNNNN.png`: the simulated sensor depth (docs/recording-format.md, "Depth").
- `occlusion/NNNNNN.png`: ground truth, 8-bit: 0 no model, 128 model hidden by the occluder, 255 model
  visible; a pixel's class is that of its centre's ray.
- `occlusion.json`: the model box (`world_from_model`, `size`) and this legend.
The depth and masks are per output pixel centre (the colour follows the scene's supersampling). Global
shutter and no motion blur only (the occluder is drawn at the frame's time).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracking.errors import SessionError
from tracking.poses import invert
from tracking.synth.renderer import SKIN_BGR, DeskRenderer, _pixel_rays

MASK_NONE, MASK_HIDDEN, MASK_VISIBLE = 0, 128, 255
FOLDER = "occlusion"
OCCLUDER_DEFAULTS = {"kind": "hand", "start": 0.0, "end": 1.0, "fraction": 0.45, "sweep": 0.18, "radius": 0.03,
                     "height": 0.2}
DEPTH_DEFAULTS = {"noise_per_m2": 0.003, "baseline": 0.0375, "speckle": 0.004, "flying": 0.4, "fattening_px": 1,
                  "max_range": 3.0}
MODEL_DEFAULTS = {"size": [0.06, 0.05, 0.09], "offset": [0.0, 0.0]}


def check_occlusion(block, where: str = "occlusion") -> dict:
    """The `occlusion` block with defaults filled in; SessionError naming the field otherwise."""
    if not isinstance(block, dict):
        raise SessionError(f"{where}: must be an object with model, occluder and depth")
    for k in block:
        if k not in ("model", "occluder", "depth"):
            raise SessionError(f"{where}.{k}: unknown key (known: depth, model, occluder)")
    out = {}
    for name, defaults in (("model", MODEL_DEFAULTS), ("occluder", OCCLUDER_DEFAULTS), ("depth", DEPTH_DEFAULTS)):
        sub = block.get(name, {})
        if not isinstance(sub, dict):
            raise SessionError(f"{where}.{name}: must be an object")
        merged = dict(defaults)
        for k, v in sub.items():
            if k not in defaults:
                raise SessionError(f"{where}.{name}.{k}: unknown key (known: {', '.join(defaults)})")
            merged[k] = v
        out[name] = merged
    for key in ("start", "end", "fraction", "sweep", "radius", "height"):
        v = out["occluder"][key]
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise SessionError(f"{where}.occluder.{key}: must be a number, got {v!r}")
    if out["occluder"]["kind"] not in ("hand", "object"):
        raise SessionError(f"{where}.occluder.kind: must be 'hand' or 'object', got {out['occluder']['kind']!r}")
    size = out["model"]["size"]
    if not (isinstance(size, list) and len(size) == 3 and all(isinstance(s, (int, float)) and s > 0 for s in size)):
        raise SessionError(f"{where}.model.size: must be [x, y, z] metres, got {size!r}")
    return out


@dataclass
class OcclusionFrame:
    """One rendered frame: BGR image, world_from_camera, t, sensor depth (float32 m, 0 = none), ground-truth
    mask (uint8, MASK_*), the true scene depth (float32 m) and the model's true depth (float32 m, inf off it)."""

    image: np.ndarray
    pose: np.ndarray
    t: float
    depth: np.ndarray
    mask: np.ndarray
    true_depth: np.ndarray
    model_depth: np.ndarray


class OcclusionRenderer:
    """Renders a scene with an `occlusion` block: the desk (DeskRenderer), the occluder over it, the sensor's
    depth and the ground truth. `render(i)` -> (image, pose, t) like the other renderers; `render_full(i)`
    -> OcclusionFrame."""

    def __init__(self, scene):
        self.scene = scene
        self.spec = check_occlusion(scene.occlusion)
        self.desk = DeskRenderer(scene)
        cam = scene.camera
        self.camera = cam
        rays = _pixel_rays(cam)  # output pixels: the depth and the masks are per pixel centre
        self.rays = np.concatenate([rays, np.ones(rays.shape[:2] + (1,), np.float32)], axis=-1)  # (H, W, 3), z = 1
        m = self.spec["model"]
        c = self.desk.centre
        self.model_size = np.array(m["size"], float)
        self.model_centre_desk = np.array([c[0] + m["offset"][0], c[1] + m["offset"][1], self.model_size[2] / 2])
        desk_from_model = np.eye(4)
        desk_from_model[:3, 3] = self.model_centre_desk
        self.world_from_model = self.desk.world_from_desk @ desk_from_model
        self.rng = np.random.default_rng(scene.seed + 7001)

    # -- geometry ---------------------------------------------------------------------------
    def spheres(self, t: float, desk_from_camera: np.ndarray) -> list[tuple[np.ndarray, float]]:
        """The occluder at time t as (centre in the desk frame, radius) spheres."""
        o = self.spec["occluder"]
        cam = desk_from_camera[:3, 3]
        M = self.model_centre_desk
        span = max(float(o["end"]) - float(o["start"]), 1e-6)
        s = float(np.clip((t - float(o["start"])) / span, 0.0, 1.0))
        s = s * s * (3 - 2 * s)
        lateral = float(o["sweep"]) * (2 * s - 1)
        look = cam - M
        flat = np.array([look[0], look[1], 0.0])
        flat /= max(np.linalg.norm(flat), 1e-9)
        u = np.array([-flat[1], flat[0], 0.0])  # horizontal, across the line of sight
        frac = float(o["fraction"])
        out = []
        if o["kind"] == "object":
            r, height = float(o["radius"]), float(o["height"])
            base = M + frac * np.array([look[0], look[1], 0.0]) + lateral * u
            base[2] = 0.0
            for z in np.arange(r, height - r + 1e-9, r / 3):
                out.append((base + np.array([0.0, 0.0, z]), r))
            return out
        n = look / np.linalg.norm(look)
        v = np.cross(n, u)  # in the hand's plane, roughly up
        if v[2] < 0:
            v = -v
        palm = M + frac * look + lateral * u

        def chain(a, b, r0, r1, step):
            k = max(2, int(np.ceil(np.linalg.norm(b - a) / step)) + 1)
            for w in np.linspace(0.0, 1.0, k):
                out.append((a + (b - a) * w, r0 + (r1 - r0) * w))

        for a in (-0.025, 0.0, 0.025):
            for b in (-0.028, 0.0, 0.028):
                out.append((palm + a * u + b * v, 0.02))
        for j, length in enumerate((0.062, 0.072, 0.068, 0.055)):
            base = palm + 0.04 * u + (j - 1.5) * 0.022 * v  # 3 mm apart: gaps the depth must resolve
            chain(base, base + length * u, 0.0095, 0.0085, 0.005)
        tb = palm + 0.015 * u - 0.045 * v
        chain(tb, tb + 0.045 * (0.6 * u - 0.8 * v), 0.012, 0.01, 0.006)
        wrist = palm - 0.045 * u
        chain(wrist, wrist - 0.32 * u - 0.05 * v, 0.028, 0.036, 0.012)
        return out

    def _box_depth(self, desk_from_camera: np.ndarray) -> np.ndarray:
        """Camera z where each pixel's ray enters the model box (inf where it misses)."""
        R, o = desk_from_camera[:3, :3], desk_from_camera[:3, 3]
        D = self.rays @ R.T.astype(np.float32)  # ray directions in the desk frame, camera z = 1
        lo = self.model_centre_desk - self.model_size / 2
        hi = self.model_centre_desk + self.model_size / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo.astype(np.float32) - o.astype(np.float32)) / D
            t2 = (hi.astype(np.float32) - o.astype(np.float32)) / D
        tn = np.nanmax(np.minimum(t1, t2), axis=-1)
        tf = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (tn <= tf) & (tn > 0)
        return np.where(hit, tn, np.inf).astype(np.float32)

    def _desk_depth(self, camera_from_desk: np.ndarray) -> np.ndarray:
        n = camera_from_desk[:3, 2]
        p = camera_from_desk[:3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.float32(n @ p) / (self.rays @ n.astype(np.float32))
        z[~(z > 0)] = np.inf
        return z.astype(np.float32)

    def _occluder(self, spheres, camera_from_desk):
        """(z, shade): the occluder's camera z per pixel (inf off it) and its Lambert shading (0..1)."""
        H, W = self.rays.shape[:2]
        z = np.full((H, W), np.inf, np.float32)
        shade = np.zeros((H, W), np.float32)
        cam = self.camera
        for c_desk, r in spheres:
            c = camera_from_desk[:3, :3] @ c_desk + camera_from_desk[:3, 3]
            if c[2] < r + 0.02:
                continue
            uv = cam.project(c[None, :]).reshape(-1)
            if not np.all(np.isfinite(uv)):
                continue
            rp = cam.fx * r / (c[2] - r) * 1.4 + 4
            x0, x1 = int(max(0, uv[0] - rp)), int(min(W, uv[0] + rp + 1))
            y0, y1 = int(max(0, uv[1] - rp)), int(min(H, uv[1] + rp + 1))
            if x0 >= x1 or y0 >= y1:
                continue
            d = self.rays[y0:y1, x0:x1]
            c32 = c.astype(np.float32)
            a = np.einsum("ijk,ijk->ij", d, d)
            b = d @ c32
            disc = b * b - a * (np.float32(c @ c) - np.float32(r * r))
            hit = disc > 0
            if not hit.any():
                continue
            s = (b - np.sqrt(np.maximum(disc, 0))) / a
            sub = z[y0:y1, x0:x1]
            near = hit & (s < sub)
            if not near.any():
                continue
            p = d * s[..., None] - c32
            nrm = p / np.float32(r)
            dn = d / np.sqrt(a)[..., None]
            lam = np.clip(-np.einsum("ijk,ijk->ij", nrm, dn), 0.0, 1.0)
            sub[near] = s[near]
            shade[y0:y1, x0:x1][near] = lam[near]
        return z, shade

    # -- sensor ------------------------------------------------------------------------------
    def sensor_depth(self, true_z: np.ndarray) -> np.ndarray:
        """The depth camera's reading of `true_z` (metres, inf = nothing): see the module docstring."""
        p = self.spec["depth"]
        z = np.where(np.isfinite(true_z), true_z, 0.0).astype(np.float32)
        far = z <= 0
        z[far] = 100.0
        k = int(p["fattening_px"])
        if k > 0:
            zmin = cv2.erode(z, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1)))
            z = np.where(z - zmin > 0.02, zmin, z)
        zmin3, zmax3 = cv2.erode(z, np.ones((3, 3), np.uint8)), cv2.dilate(z, np.ones((3, 3), np.uint8))
        edge = (zmax3 - zmin3) > 0.02
        fly = edge & (self.rng.random(z.shape) < float(p["flying"]))
        mix = self.rng.random(z.shape).astype(np.float32)
        z = np.where(fly, zmin3 + mix * (zmax3 - zmin3), z)
        # stereo shadow: a pixel is lost when a nearer surface up to its disparity difference to the right
        # hides it from the other camera of the pair
        disp = np.float32(self.camera.fx * float(p["baseline"])) / z
        hole = np.zeros(z.shape, bool)
        kmax = int(min(np.ceil(float(disp.max() - disp.min())), z.shape[1] - 1))
        for s in range(1, kmax + 1):
            hole[:, :-s] |= disp[:, s:] - disp[:, :-s] >= s
        sp = float(p["speckle"])
        if sp > 0:
            seeds = (self.rng.random(z.shape) < sp / 9).astype(np.uint8)
            hole |= cv2.dilate(seeds, np.ones((3, 3), np.uint8)).astype(bool)
        sigma = float(p["noise_per_m2"]) * z * z
        z = z + self.rng.standard_normal(z.shape).astype(np.float32) * sigma
        z[hole | far | (z > float(p["max_range"])) | (z <= 0)] = 0.0
        return z.astype(np.float32)

    # -- frames ------------------------------------------------------------------------------
    def render_full(self, i: int) -> OcclusionFrame:
        t = self.desk.time_of(i)
        pose = self.desk.world_from_camera(t)
        desk_from_camera = self.desk.desk_from_world @ pose
        camera_from_desk = invert(desk_from_camera)
        img = self.desk.render_clean(pose)
        if img.shape[:2] != self.rays.shape[:2]:
            img = cv2.resize(img, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)
        desk_z = self._desk_depth(camera_from_desk)
        occ_z, shade = self._occluder(self.spheres(t, desk_from_camera), camera_from_desk)
        in_front = occ_z < desk_z
        a = in_front.astype(np.float32)
        # the silhouette's edge antialiased as a lens does it (half a pixel); the masks stay per pixel centre
        a = cv2.GaussianBlur(a, (0, 0), 0.6)[..., None]
        skin = SKIN_BGR * (0.55 + 0.45 * shade)[..., None]
        img = img * (1.0 - a) + skin * a
        img = self.desk._camera_response(img.astype(np.float32), t)
        true_z = np.minimum(desk_z, occ_z)
        model_z = self._box_depth(desk_from_camera)
        on_model = np.isfinite(model_z)
        mask = np.full(model_z.shape, MASK_NONE, np.uint8)
        mask[on_model] = MASK_VISIBLE
        mask[on_model & (occ_z < model_z)] = MASK_HIDDEN
        return OcclusionFrame(img, pose, t, self.sensor_depth(true_z), mask, true_z, model_z)

    def render(self, i: int):
        f = self.render_full(i)
        return f.image, f.pose, f.t

    def model_info(self) -> dict:
        return {"model": {"kind": "box", "size": self.model_size.tolist(),
                          "world_from_model": self.world_from_model.tolist()},
                "mask": {"folder": FOLDER, "none": MASK_NONE, "hidden": MASK_HIDDEN, "visible": MASK_VISIBLE}}


def write_extras(out: Path, renderer: OcclusionRenderer) -> None:
    """occlusion.json beside the recording's session.json."""
    (Path(out) / "occlusion.json").write_text(json.dumps(renderer.model_info(), indent=2) + "\n")


def write_mask(out: Path, index: int, mask: np.ndarray) -> None:
    folder = Path(out) / FOLDER
    folder.mkdir(exist_ok=True)
    if not cv2.imwrite(str(folder / f"{index:06d}.png"), mask):
        raise SessionError(f"{folder}: cannot write the occlusion mask (check the folder is writable)")


def read_truth(recording: Path):
    """(world_from_model 4x4, size (3,), masks {index: uint8 mask}) of an occlusion recording."""
    rec = Path(recording)
    info = json.loads((rec / "occlusion.json").read_text())
    masks = {}
    for p in sorted((rec / FOLDER).glob("*.png")):
        masks[int(p.stem)] = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    return np.array(info["model"]["world_from_model"], float), np.array(info["model"]["size"], float), masks


# -- scoring ----------------------------------------------------------------------------------
def iou(pred: np.ndarray, truth: np.ndarray) -> float | None:
    """Intersection over union of two boolean masks; None when both are empty."""
    union = np.count_nonzero(pred | truth)
    if union == 0:
        return None
    return float(np.count_nonzero(pred & truth) / union)


def edge_error_px(pred: np.ndarray, truth: np.ndarray) -> float | None:
    """Mean distance (pixels) from each boundary pixel of one mask to the other mask's boundary, both ways
    (a symmetric chamfer distance); None when either has no boundary."""
    def boundary(m):
        m8 = m.astype(np.uint8)
        return (m8 - cv2.erode(m8, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)) > 0

    bp, bt = boundary(pred), boundary(truth)
    if not bp.any() or not bt.any():
        return None
    dt = cv2.distanceTransform((~bt).astype(np.uint8), cv2.DIST_L2, 5)
    dp = cv2.distanceTransform((~bp).astype(np.uint8), cv2.DIST_L2, 5)
    return float((dt[bp].sum() + dp[bt].sum()) / (bp.sum() + bt.sum()))
