"""Source specs as the app uses them, opened through tracking.sources; which sources are live.

Specs: a recording folder (or `file:FOLDER`), a video `file:VIDEO` with its
calibration as `file:VIDEO?calibration=CAM.yaml`, `v4l2:N`, `v4l2:/dev/videoN`,
`depthai`, `depthai:<device id>`.
"""

from __future__ import annotations

from pathlib import Path

from tracking import sources

# source kinds that deliver at their own pace and cannot seek (read by `is_live` when a source does
# not say so itself with a `live` attribute)
LIVE_KINDS = ("v4l2", "depthai")


def is_live(source) -> bool:
    """Cameras deliver at their own pace and cannot seek; files and recordings are paced by the player."""
    live = getattr(source, "live", None)
    if isinstance(live, bool):
        return live
    return getattr(source, "kind", "") in LIVE_KINDS


def is_seekable(source) -> bool:
    """A recording or video with a known frame count and a `seek` method."""
    return not is_live(source) and hasattr(source, "seek") and int(getattr(source, "frame_count", 0) or 0) > 0


def split_calibration(spec: str) -> tuple[str, str | None]:
    """('file:video.mp4', 'cam.yaml') from 'file:video.mp4?calibration=cam.yaml'."""
    if "?calibration=" in spec:
        base, calib = spec.split("?calibration=", 1)
        return base, calib
    return spec, None


def video_spec(video: str, calibration: str | None) -> str:
    return f"file:{video}" + (f"?calibration={calibration}" if calibration else "")


def recording_folder(spec: str) -> Path | None:
    """The recording folder a spec names, or None when it names something else."""
    path = spec[5:] if spec.startswith("file:") else spec
    p = Path(path)
    if p.name == "session.json":
        p = p.parent
    return p if (p / "session.json").is_file() else None


def display_name(spec: str) -> str:
    base, _ = split_calibration(spec)
    folder = recording_folder(base)
    if folder is not None:
        return folder.name
    if base.startswith("file:"):
        return Path(base[5:]).name
    return base


def open_spec(spec: str):
    """Open the source a spec names. Recordings are read as fast as asked (the player paces them itself)."""
    base, calib = split_calibration(spec)
    folder = recording_folder(base)
    if folder is not None:
        return sources.RecordingSource(folder, realtime=False, loop=False)
    return sources.open_source(base, calibration=calib)


def list_devices() -> list[tuple[str, str]]:
    """(spec, description) of attached cameras (V4L2 and DepthAI); may take a second (DepthAI looks on USB)."""
    out = []
    for d in sources.list_v4l2():
        out.append((d["spec"], f"V4L2 {d.get('name', '?')} ({d.get('device', '')})"))
    for d in sources.list_depthai():
        out.append((d["spec"], f"DepthAI {d.get('name', '?')} {d.get('id', '')} ({d.get('state', '')})"))
    return out
