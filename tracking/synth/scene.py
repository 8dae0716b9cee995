"""A synthetic scene: camera, anchors on a textured desk, trajectory, effects (JSON format).

Scene JSON (all keys but `anchors` and `trajectory` optional; metres, seconds, degrees):

    {"name": "board_orbit", "seed": 1, "fps": 30, "duration": 4,
     "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": [k1, k2, p1, p2, k3]}
               or {"width": ..., "height": ..., "K": [[...]], "dist": [...]},
     "anchors": [ ...exactly as in session.json... ],
     "desk": {"size": [1.4, 1.0], "ppm": 2000, "seed": 3, "style": "desk", "bed" or "tiles",
              "anchors_shown": true,                 (false: the anchors are taken off the desk; they
                                                     still define the world frame of the ground truth)
              "lamp": {"at": [0.3, 0.2], "strength": 0.2, "ambient": 0.88}},   (the desk lamp: brightness
                                                     ambient + strength exp(-|p - centre - at|^2 / 0.5))
     "trajectory": {"kind": "orbit", ...}            (see tracking.synth.trajectory),
     "effects": {"noise": 2.0, "motion_blur": 0.0, "blur_samples": 7,
                 "exposure": {"amplitude": 0.2, "period": 2.0},
                 "jpeg_quality": null, "vignette": 0.15, "optics_blur": 0.5,
                 "occluder": {"start": 1.0, "end": 3.0, "anchor": 0},
                 "rolling_shutter": 0.02, "defocus": 0.8, "auto_exposure": {"target": 110, "speed": 0.2},
                 "white_balance": {"amplitude": 0.04, "period": 3.0}, "sensor": {"full_well": 3000, "read_noise": 1.5},
                 "chroma_422": true},
     "video": {"fourcc": "MJPG", "quality": 90},
     "supersample": 3,
     "held": {...},                                  (optional: a card held before the camera, see
                                                     tracking.synth.held)
     "occlusion": {...}}                             (optional: a hand or object passing before a model, with
                                                     depth and ground-truth masks, see tracking.synth.occlusion)

The desk is the world anchor's paper plane (world z = 0); the camera sees it
from the out-of-paper side. Desk coordinates: x = world x; y "away" and z up
out of the paper, so for an aruco/qr world the desk frame is the world frame
and for a board world (z into the paper) it is the world turned over x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracking.camera import Camera
from tracking.errors import CalibrationError, SessionError
from tracking.jsonfile import read_json
from tracking.poses import invert
from tracking.anchors.kinds import AnchorSpec
from tracking.recording.schema import parse_anchors
from tracking.synth.held import check_held
from tracking.synth.patterns import pattern_for
from tracking.synth.texture import STYLES
from tracking.synth.trajectory import make_trajectory

DEFAULT_LAMP = (0.3, 0.2, 0.2, 0.88)   # the desk lamp: at (x, y) m from the desk centre, strength, ambient
DEFAULT_EFFECTS = {
    "noise": 0.0,  # sensor noise standard deviation at mid-grey, 8-bit levels (simple model; see "sensor")
    "motion_blur": 0.0,  # exposure time as a fraction of the frame interval (0 = sharp)
    "blur_samples": 7,  # sub-frame renders averaged for motion blur
    "exposure": None,  # {"amplitude": a, "period": s}: gain 1 + a*sin(2 pi t / period)
    "jpeg_quality": None,  # extra JPEG round trip at this quality, or [low, high] drawn per frame
    "vignette": 0.0,  # brightness fall-off at the image corners (0..1)
    "optics_blur": 0.5,  # lens point-spread, Gaussian sigma in output pixels (symmetric: ground truth unmoved)
    "occluder": None,  # {"start": s, "end": s, "anchor": i, "ramp": s}: a hand over that anchor; with
    #                    "style": "border", "approach_deg", "reach" (m), "offset" (m): fingertips onto its border
    "rolling_shutter": 0.0,  # readout time top to bottom row, seconds (0 = global shutter)
    "defocus": 0.0,  # pillbox radius in output pixels, or {"radius", "swing", "period"} (focus hunting)
    "auto_exposure": None,  # {"target": luma, "speed": 0..1, "initial_gain": g, "min_gain", "max_gain"}
    "white_balance": None,  # {"amplitude": a, "period": s, "phase": rad}: drifting B/R gains
    "sensor": None,  # {"full_well": electrons at level 255, "read_noise": levels}: shot + read noise
    "chroma_422": False,  # YUYV 4:2:2 link: pixel pairs share chroma
}


@dataclass
class Scene:
    """Everything needed to render a synthetic recording deterministically."""

    name: str
    camera: Camera
    anchors: list[AnchorSpec]
    anchor_blocks: list[dict]
    trajectory: dict
    fps: float = 30.0
    duration: float = 4.0
    seed: int = 0
    desk_size: tuple[float, float] = (1.4, 1.0)
    desk_ppm: float = 2000.0
    desk_seed: int = 0
    desk_style: str = "desk"
    effects: dict = field(default_factory=lambda: dict(DEFAULT_EFFECTS))
    fourcc: str = "MJPG"
    quality: int = 90
    supersample: int = 3
    held: dict | None = None
    """a card held before the camera (tracking.synth.held): the desk is the card, moving in a room"""
    occlusion: dict | None = None
    """a hand or object passing before a virtual model, with depth and masks (tracking.synth.occlusion)"""
    anchors_shown: bool = True   # false: the desk without its anchors (a revisit with the marker removed)
    lamp: tuple = DEFAULT_LAMP   # (x, y from the desk centre m, strength, ambient): the desk lamp

    @property
    def frame_count(self) -> int:
        return int(round(self.duration * self.fps))

    @property
    def world_from_desk(self) -> np.ndarray:
        """Desk frame (z out of the world anchor's paper) in the world frame."""
        if pattern_for(self.anchors[0]).normal_sign > 0:
            return np.eye(4)
        return np.diag([1.0, -1.0, -1.0, 1.0])

    @property
    def centre_desk(self) -> np.ndarray:
        """Desk-frame centre of all printed anchors: what trajectories circle around."""
        desk_from_world = invert(self.world_from_desk)
        pts = []
        for a in self.anchors:
            pat = pattern_for(a)
            w, h = pat.extent
            for p, q in ((0, 0), (w, 0), (w, h), (0, h)):
                xa = pat.origin[0] + p * pat.sx
                ya = pat.origin[1] + q * pat.sy
                pw = a.world_from_anchor @ np.array([xa, ya, 0.0, 1.0])
                pts.append((desk_from_world @ pw)[:3])
        pts = np.array(pts)
        return (pts.min(axis=0) + pts.max(axis=0)) / 2

    def to_dict(self) -> dict:
        return {
            "name": self.name, "seed": self.seed, "fps": self.fps, "duration": self.duration,
            "camera": self.camera.to_dict(), "anchors": self.anchor_blocks,
            "desk": {"size": list(self.desk_size), "ppm": self.desk_ppm, "seed": self.desk_seed,
                     "style": self.desk_style, **({} if self.anchors_shown else {"anchors_shown": False}),
                     **({} if self.lamp == DEFAULT_LAMP else {"lamp": {"at": list(self.lamp[:2]),
                                                                       "strength": self.lamp[2],
                                                                       "ambient": self.lamp[3]}})},
            "trajectory": self.trajectory, "effects": self.effects,
            "video": {"fourcc": self.fourcc, "quality": self.quality}, "supersample": self.supersample,
            **({"held": self.held} if self.held else {}),
            **({"occlusion": self.occlusion} if self.occlusion else {}),
        }


def camera_from_block(block: dict, where: str = "camera") -> Camera:
    """A Camera from `{width, height, K, dist}` or `{width, height, hfov_deg, dist}` (centred principal point)."""
    if not isinstance(block, dict):
        raise SessionError(f"{where}: must be an object with width, height and K or hfov_deg")
    if "K" in block:
        try:
            return Camera.from_dict(block, where)
        except CalibrationError as e:
            raise SessionError(str(e)) from None
    w, h = block.get("width", 640), block.get("height", 480)
    if not isinstance(w, int) or not isinstance(h, int) or w <= 0 or h <= 0:
        raise SessionError(f"{where}.width/height: must be positive integers, got {w!r} x {h!r}")
    hfov = block.get("hfov_deg", 62.0)
    if not isinstance(hfov, (int, float)) or not 5 < hfov < 170:
        raise SessionError(f"{where}.hfov_deg: must be a number of degrees between 5 and 170, got {hfov!r}")
    f = (w / 2) / math.tan(math.radians(hfov) / 2)
    K = [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]
    try:
        return Camera(K, block.get("dist", [0, 0, 0, 0, 0]), w, h)
    except CalibrationError as e:
        raise SessionError(f"{where}: {e}") from None


_SCENE_KEYS = {"name", "seed", "fps", "duration", "camera", "anchors", "desk", "trajectory", "effects", "video",
               "supersample", "held", "occlusion"}


def _scene_anchors(data: dict, where: str) -> list[AnchorSpec]:
    """The scene's anchors, each one the renderer can print, lying on the desk as the first one does."""
    if "anchors" not in data:
        raise SessionError(f"{where}.anchors: missing (list of anchors as in session.json)")
    anchors = parse_anchors(data["anchors"], f"{where}.anchors")
    for i, a in enumerate(anchors):
        pattern_for(a)  # raises for kinds the renderer cannot print
        _check_on_desk(a, pattern_for(anchors[0]).normal_sign, f"{where}.anchors[{i}]")
    return anchors


def _timing(data: dict, where: str) -> dict[str, float]:
    """{"fps": frames a second, "duration": seconds}, both positive (defaults 30 fps, 4 s)."""
    num = {}
    for key, default, lo in (("fps", 30.0, 1e-3), ("duration", 4.0, 1e-3)):
        v = data.get(key, default)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not v >= lo or not math.isfinite(v):
            raise SessionError(f"{where}.{key}: must be a positive number, got {v!r}")
        num[key] = float(v)
    return num


def _desk(data: dict, where: str) -> tuple[dict, list, str]:
    """(the desk block, its size [width, height] m, its texture style)."""
    desk = data.get("desk", {})
    if not isinstance(desk, dict):
        raise SessionError(f"{where}.desk: must be an object with size, ppm, seed")
    size = desk.get("size", [1.4, 1.0])
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(s, (int, float)) and s > 0 for s in size)):
        raise SessionError(f"{where}.desk.size: must be [width, height] in metres, got {size!r}")

    style = desk.get("style", "desk")
    if style not in STYLES:
        raise SessionError(f"{where}.desk.style: must be one of {', '.join(STYLES)}, got {style!r}")
    return desk, size, style


def _effects(data: dict, where: str) -> dict:
    """DEFAULT_EFFECTS with the scene's own effects over them, checked."""
    effects = dict(DEFAULT_EFFECTS)
    user_fx = data.get("effects", {})
    if not isinstance(user_fx, dict):
        raise SessionError(f"{where}.effects: must be an object")
    for k, v in user_fx.items():
        if k not in DEFAULT_EFFECTS:
            raise SessionError(f"{where}.effects.{k}: unknown effect (known: {', '.join(DEFAULT_EFFECTS)})")
        effects[k] = v
    _check_effects(effects, f"{where}.effects")
    return effects


def _check_occlusion_and_held(scene: Scene, effects: dict, where: str) -> None:
    """An occlusion block: not with a held card, a global shutter without motion blur, a valid block; a held
    block: valid for the scene's rolling shutter."""
    if scene.occlusion is not None:
        from tracking.synth.occlusion import check_occlusion   # (it imports the renderer, which imports this module)

        if scene.held is not None:
            raise SessionError(f"{where}.occlusion: not with a held card (held); use a desk scene")
        if (effects.get("rolling_shutter") or 0) > 0 or (effects.get("motion_blur") or 0) > 0:
            raise SessionError(f"{where}.occlusion: needs a global shutter without motion blur "
                               "(effects.rolling_shutter and effects.motion_blur 0)")
        check_occlusion(scene.occlusion, f"{where}.occlusion")
    if scene.held is not None:
        check_held(scene.held, effects.get("rolling_shutter"), f"{where}.held")


def parse_scene(data: dict, where: str = "scene") -> Scene:
    """Validate a scene dict; errors are SessionErrors naming the field."""
    if not isinstance(data, dict):
        raise SessionError(f"{where}: must be a JSON object")
    for k in data:
        if k not in _SCENE_KEYS:
            raise SessionError(f"{where}.{k}: unknown key (known: {', '.join(sorted(_SCENE_KEYS))})")
    anchors = _scene_anchors(data, where)
    if "trajectory" not in data:
        raise SessionError(f"{where}.trajectory: missing (e.g. {{\"kind\": \"orbit\"}})")
    num = _timing(data, where)
    desk, size, style = _desk(data, where)
    effects = _effects(data, where)
    video = data.get("video", {})
    ss = data.get("supersample", 3)
    if not isinstance(ss, int) or not 1 <= ss <= 8:
        raise SessionError(f"{where}.supersample: must be an integer 1..8, got {ss!r}")
    scene = Scene(
        name=str(data.get("name", "synthetic")),
        camera=camera_from_block(data.get("camera", {}), f"{where}.camera"),
        anchors=anchors,
        anchor_blocks=data["anchors"],
        trajectory=data["trajectory"],
        fps=num["fps"], duration=num["duration"], seed=int(data.get("seed", 0)),
        desk_size=(float(size[0]), float(size[1])), desk_ppm=float(desk.get("ppm", 2000.0)),
        desk_seed=int(desk.get("seed", data.get("seed", 0))), desk_style=style,
        effects=effects, fourcc=str(video.get("fourcc", "MJPG")), quality=int(video.get("quality", 90)),
        supersample=ss, held=data.get("held"), occlusion=data.get("occlusion"),
        anchors_shown=_shown(desk, f"{where}.desk.anchors_shown"), lamp=_lamp(desk.get("lamp"), f"{where}.desk.lamp"),
    )
    _check_occlusion_and_held(scene, effects, where)
    make_trajectory(scene.trajectory, scene.duration, scene.seed, f"{where}.trajectory")  # validate now
    return scene


def _lamp(block, where: str) -> tuple:
    if block is None:
        return DEFAULT_LAMP
    at = block.get("at", list(DEFAULT_LAMP[:2])) if isinstance(block, dict) else None
    vals = [block.get("strength", DEFAULT_LAMP[2]), block.get("ambient", DEFAULT_LAMP[3])] if at is not None else []
    if (at is None or set(block) - {"at", "strength", "ambient"} or not isinstance(at, list) or len(at) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in [*at, *vals])
            or not 0 <= vals[0] <= 2 or not 0 < vals[1] <= 2):
        raise SessionError(f"{where}: must be {{\"at\": [x, y] metres, \"strength\": 0..2, \"ambient\": 0..2}}, "
                           f"got {block!r}")
    return (float(at[0]), float(at[1]), float(vals[0]), float(vals[1]))


def _shown(desk: dict, where: str) -> bool:
    v = desk.get("anchors_shown", True)
    if not isinstance(v, bool):
        raise SessionError(f"{where}: must be true or false, got {v!r}")
    return v


_EFFECT_KEYS = {"auto_exposure": {"target", "speed", "initial_gain", "min_gain", "max_gain"},
                "white_balance": {"amplitude", "period", "phase"}, "sensor": {"full_well", "read_noise"},
                "defocus": {"radius", "swing", "period"},
                "occluder": {"start", "end", "anchor", "ramp", "style", "approach_deg", "reach", "offset"}}


def _check_effects(fx: dict, where: str) -> None:
    """Camera-effect blocks: known keys only, numbers where numbers belong."""
    for k, keys in _EFFECT_KEYS.items():
        v = fx.get(k)
        if not v or (k == "defocus" and isinstance(v, (int, float))):
            continue
        if not isinstance(v, dict):
            raise SessionError(f"{where}.{k}: must be an object with keys {', '.join(sorted(keys))}")
        for kk, vv in v.items():
            if kk not in keys:
                raise SessionError(f"{where}.{k}.{kk}: unknown key (known: {', '.join(sorted(keys))})")
            if kk != "style" and (not isinstance(vv, (int, float)) or isinstance(vv, bool)):
                raise SessionError(f"{where}.{k}.{kk}: must be a number, got {vv!r}")
    occ = fx.get("occluder")
    if occ and occ.get("style", "cover") not in ("cover", "border"):
        raise SessionError(f"{where}.occluder.style: must be 'cover' or 'border', got {occ.get('style')!r}")
    rs = fx.get("rolling_shutter") or 0.0
    if not isinstance(rs, (int, float)) or isinstance(rs, bool) or rs < 0:
        raise SessionError(f"{where}.rolling_shutter: must be a readout time in seconds >= 0, got {rs!r}")
    if (fx.get("sensor") or {}).get("full_well", 1) <= 0:
        raise SessionError(f"{where}.sensor.full_well: must be a positive number of electrons")


def _check_on_desk(anchor: AnchorSpec, world_normal_sign: float, where: str) -> None:
    """The renderer prints anchors on the desk plane, face up: check world_from_anchor allows that."""
    T = anchor.world_from_anchor
    out_of_paper_world = T[:3, 2] * pattern_for(anchor).normal_sign
    desk_up_world = np.array([0.0, 0.0, world_normal_sign])
    if abs(T[2, 3]) > 1e-9 or not np.allclose(out_of_paper_world, desk_up_world, atol=1e-9):
        raise SessionError(
            f"{where}.world_from_anchor: synth prints anchors on the desk (the world anchor's paper plane, "
            "world z = 0) face up; this transform lifts or tilts the anchor off it"
        )


def load_scene(path: str | Path) -> Scene:
    """Read a scene JSON file."""
    path = Path(path)
    if not path.is_file():
        raise SessionError(f"{path}: scene file does not exist (give a preset name or a JSON file)")
    return parse_scene(read_json(path, "scene", SessionError), str(path))
