"""The real footage of tests/data/realvideo as `tracking.evaluation_real.RealSequence`s (see SOURCES.md there).

Used by tests/test_realvideo.py and benchmarks/bench_realvideo.py. Cameras: the source's calibration
where it has one (caliscope, apriltag_room), else the project's estimated camera for the frame size
(tracking.default_intrinsics, as `arapp replay` opens an uncalibrated video). Photos taken one after
another are a second apart (`photo_frames`): each is measured on its own. Tags whose places relative to
each other are unknown are each run as their own world (one run per tag).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2

from tracking.camera import Camera
from tracking.default_intrinsics import estimated_camera
from tracking.evaluation_real import RealSequence, photo_frames, video_frames
from tracking.recording.schema import parse_anchors

DATA = Path(__file__).resolve().parent / "data" / "realvideo"


def _anchors(path: Path):
    return parse_anchors(json.loads(path.read_text(encoding="utf-8")))


def _tag_runs(path: Path, ids=None):
    """One anchor list per tag (each its own world: their places relative to each other are unknown)."""
    blocks = json.loads(path.read_text(encoding="utf-8"))
    return [parse_anchors([b]) for b in blocks if ids is None or b["id"] in ids]


def _size(path: Path) -> tuple[int, int]:
    cap = cv2.VideoCapture(str(path))
    try:
        return int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    finally:
        cap.release()


def _limited(frames, limit):
    for i, f in enumerate(frames):
        if limit is not None and i >= limit:
            return
        yield f


def deepcharuco(limit: int | None = None) -> RealSequence:
    video = DATA / "deepcharuco_screen_board.mp4"
    return RealSequence("deepcharuco_screen_board", estimated_camera(*_size(video)),
                        lambda: _limited(video_frames(video), limit), [_anchors(DATA / "deepcharuco_anchors.json")],
                        note="hand-held phone, ChArUco on a screen, 320x180, estimated camera")


def caliscope(limit: int | None = None) -> RealSequence:
    video = DATA / "caliscope_charuco_cam0.mp4"
    return RealSequence("caliscope_charuco_cam0", Camera.load_yaml(DATA / "caliscope_cam0.yml"),
                        lambda: _limited(video_frames(video), limit), [_anchors(DATA / "caliscope_anchors.json")],
                        inverted=True, note="fixed webcam, inverted ChArUco held by hand, 1280x720, calibrated")


def apriltag_clipboard() -> RealSequence:
    folder = DATA / "apriltag_clipboard"
    files = sorted((folder / "frames").glob("*.png"))
    return RealSequence("apriltag_clipboard", estimated_camera(320, 240), lambda: photo_frames(files),
                        _tag_runs(folder / "anchors.json"),
                        note="desk webcam, 30 tags on a clipboard (each its own world), 320x240, estimated camera")


def apriltag_room() -> RealSequence:
    folder = DATA / "apriltag_room"
    files = sorted((folder / "frames").glob("*.JPG"))
    return RealSequence("apriltag_room", Camera.load_yaml(folder / "calibration.yml"), lambda: photo_frames(files),
                        _tag_runs(folder / "anchors.json"),
                        note="phone photos walking round a room, tags on the walls (each its own world), 816x612")


SEQUENCES = {"deepcharuco_screen_board": deepcharuco, "caliscope_charuco_cam0": caliscope,
             "apriltag_clipboard": apriltag_clipboard, "apriltag_room": apriltag_room}
