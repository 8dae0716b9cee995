"""Camera calibrations stored per camera and resolution in the user's config folder, and the rule
that gives every opened source a camera.

A calibration made in the GUI's wizard is saved as
`<config>/cameras/<camera name>_<W>x<H>.yaml` (OpenCV FileStorage YAML as
`arapp calibrate` writes, with `camera_name` and `rms_px`). The camera name is
the V4L2 device's name (`/sys/class/video4linux/videoN/name`, e.g. "HD Pro
Webcam C920") or, for a video file, `video:<file name>`.

`attach_camera(source)` applies, in order: the source's own camera (a
calibration file given with `?calibration=`, a recording's session.json, a
DepthAI device's factory calibration); a stored calibration for this camera
at this resolution (or at another resolution of the same aspect ratio,
scaled); the estimated camera of tracking.default_intrinsics.
"""

from __future__ import annotations

from pathlib import Path

from tracking.camera import Camera
from tracking.default_intrinsics import DEFAULT_HFOV_DEG, attach_estimated_camera, is_estimated, source_size
from tracking.errors import CalibrationError

from arapp.store.user_config import config_dir, slug

# what `attach_camera` / `calibration_kind` report
OWN, STORED, ESTIMATED = "own", "stored", "estimated"


def cameras_dir() -> Path:
    path = config_dir() / "cameras"
    path.mkdir(parents=True, exist_ok=True)
    return path


def camera_name(source) -> str:
    """The name a calibration of this source's camera is stored under."""
    info = getattr(source, "info", {}) or {}
    if info.get("kind") == "v4l2":
        name = info.get("name") or "?"
        return name if name != "?" else f"v4l2 {info.get('device', '')}"
    path = getattr(source, "path", None)
    if path is not None:
        return f"video:{Path(path).name}"
    return str(getattr(source, "kind", "camera"))


def stored_path(name: str, width: int, height: int) -> Path:
    return cameras_dir() / f"{slug(name)}_{int(width)}x{int(height)}.yaml"


def save_camera(name: str, camera: Camera, rms_px: float | None = None, views: int | None = None) -> Path:
    """Store `camera` as the calibration of camera `name` at its resolution; returns the file."""
    path = stored_path(name, camera.width, camera.height)
    extra = {"camera_name": name}
    if rms_px is not None:
        extra["rms_px"] = float(rms_px)
    if views is not None:
        extra["views"] = int(views)
    camera.save_yaml(path, extra)
    return path


def stored_camera(name: str, width: int, height: int) -> tuple[Camera, Path] | None:
    """The stored calibration of camera `name` for a width x height stream: exact size first, else one
    of the same aspect ratio scaled to it; None when there is none."""
    exact = stored_path(name, width, height)
    candidates = [exact] + sorted(p for p in cameras_dir().glob(f"{slug(name)}_*x*.yaml") if p != exact)
    for path in candidates:
        if not path.is_file():
            continue
        try:
            cam = Camera.load_yaml(path)
        except CalibrationError:
            continue  # a damaged file is skipped, the estimate (or another size) is used instead
        if (cam.width, cam.height) == (width, height):
            return cam, path
        if abs(cam.width / cam.height - width / height) < 1e-3:
            return cam.scaled(width, height), path
    return None


def attach_camera(source) -> str:
    """Give a just-opened source its camera (see the module doc); returns OWN, STORED or ESTIMATED.
    Sets `source.calibration_file` to the stored file used, when one was, and notes where the camera came
    from in `source.info["calibration"]` (the session.json `source` block of a recording made from it, so
    a recording never passes an estimate off as a calibration)."""
    if source.has_camera and not getattr(source, "camera_estimated", False):
        return OWN
    info = getattr(source, "info", None)
    note = info.__setitem__ if isinstance(info, dict) else (lambda _k, _v: None)
    size = source_size(source)
    if size is not None:
        found = stored_camera(camera_name(source), *size)
        if found is not None:
            source._camera, source.calibration_file = found
            source.camera_estimated = False
            note("calibration", f"stored {found[1].name}")
            return STORED
    if attach_estimated_camera(source) or getattr(source, "camera_estimated", False):
        note("calibration", f"estimated: pinhole, {DEFAULT_HFOV_DEG:g} deg field of view across the long side, "
                            "no distortion")
        return ESTIMATED
    return OWN


def calibration_kind(camera: Camera | None) -> str:
    """ESTIMATED when `camera` is the default estimate for its size, else OWN (for the UI's label,
    which only sees the camera the engine reports)."""
    return ESTIMATED if is_estimated(camera) else OWN
