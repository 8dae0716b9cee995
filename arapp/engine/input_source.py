"""What `arapp replay`, `record` and `scan` track: any source (a recording folder, a plain video, a
camera) with a camera and anchors, and the lines that tell the user where each came from.

The camera: the source's own (a recording's session.json, `--calibration FILE`, a DepthAI device's),
else one stored by the GUI's calibration wizard for this camera (arapp.store.camera_store), else the
estimated camera (tracking.default_intrinsics), said in one line with how to calibrate.
The anchors: `--anchors FILE` (a list as in session.json, or a session.json), else a recording's
own, else the recorder's default (one ArUco marker, what `arapp markers aruco` prints), said in one
line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tracking.camera import Camera
from tracking.default_intrinsics import DEFAULT_HFOV_DEG
from tracking.recording.writer import DEFAULT_ANCHORS
from tracking.anchors.kinds import AnchorSpec
from tracking.recording.schema import parse_anchors, read_anchor_blocks
from tracking.sources import open_source
from tracking.sources.base import Source

from arapp.store import camera_store


@dataclass
class Input:
    """An opened source with its camera and anchors. `anchor_blocks`: the session.json blocks of the
    anchors (what a recording made from it stores; None = the source recording's own). `notes`: one line
    each, for the user (the camera estimated, a calibration file read in another convention, the
    default anchor used)."""

    source: Source
    anchors: list[AnchorSpec]
    anchor_blocks: list | None
    notes: list[str] = field(default_factory=list)
    camera_kind: str = camera_store.OWN  # OWN, STORED or ESTIMATED
    default_anchors: bool = False  # no --anchors and no recording: the recorder's default anchor

    @property
    def camera(self) -> Camera:
        return self.source.camera

    def close(self) -> None:
        self.source.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def estimated_note(source: Source) -> str:
    """The line saying a source runs on the estimated camera, and how to calibrate it."""
    return (f"{source.describe()}: no calibration, so the estimated camera ({DEFAULT_HFOV_DEG:g} deg field of "
            "view across the long side, no distortion): sizes and distances are approximate. To calibrate: film the "
            "board `arapp markers charuco -o board` prints from many sides, run `arapp calibrate --source VIDEO "
            "--anchors board/*.anchors.json -o cam.yaml`, then add --calibration cam.yaml")


def describe_anchors(anchors: list[AnchorSpec]) -> str:
    """The anchors as a user checks them against the printed sheet ('ArUco DICT_... id 0, side 60 mm')."""
    return "; ".join(a.anchor_kind.describe(a) for a in anchors)


def unplaced_notes(blocks: list, where: str) -> list[str]:
    """The line for an anchors file whose anchors after the first lack `world_from_anchor` (docs/recording-
    format.md: every other anchor carries its place in the first one's world); [] when all have it."""
    unplaced = [i for i, b in enumerate(blocks) if i > 0 and isinstance(b, dict) and "world_from_anchor" not in b]
    if not unplaced:
        return []
    named = ", ".join(f"anchors[{i}]" for i in unplaced[:3]) + (", ..." if len(unplaced) > 3 else "")
    return [f"{where}: {named} ({len(unplaced)} of {len(blocks)}) have no world_from_anchor, so each is taken to "
            "lie where the first anchor does; give each its place in the first one's frame, or track one at a "
            "time (docs/recording-format.md)"]


def open_input(spec, calibration: str | None = None, anchors: str | None = None, realtime: bool = False,
               width: int | None = None, height: int | None = None, fps: float | None = None,
               default_anchor_note: bool = True) -> Input:
    """Open `spec` (a recording folder, a video file, 'v4l2:0', ...; see tracking.sources.SPEC_HELP) with
    the camera and anchors of the module doc. `calibration`, `anchors`: file paths or None. The anchors
    file is read before the source opens, so a bad one costs no camera start. default_anchor_note=False
    leaves the line on the default anchor to the caller (`Input.default_anchors` says it was used)."""
    blocks = parsed = None
    if anchors is not None:
        blocks = read_anchor_blocks(anchors)
        parsed = parse_anchors(blocks, where=f"{anchors}: anchors")
    source = open_source(spec, realtime=realtime, calibration=calibration, width=width, height=height, fps=fps)
    try:
        notes = list(getattr(source, "notes", []))
        kind = camera_store.attach_camera(source)
        if kind == camera_store.ESTIMATED:
            notes.append(estimated_note(source))
        elif kind == camera_store.STORED:
            notes.append(f"{source.describe()}: the calibration stored by the calibration wizard, "
                         f"{getattr(source, 'calibration_file', '')}")
        source.camera  # noqa: B018 - a source that still has no camera says so here, before any output
        session = getattr(source, "session", None)
        if parsed is not None:
            notes += unplaced_notes(blocks, anchors)
            if session is not None:
                notes.append(f"tracking the anchors of {anchors} ({describe_anchors(parsed)}) instead of the "
                             "recording's own")
        elif session is not None:
            parsed, blocks = session.anchors, None
        else:
            parsed, blocks = parse_anchors(DEFAULT_ANCHORS), DEFAULT_ANCHORS
            if default_anchor_note:
                notes.append(f"no --anchors: looking for the default anchor, {describe_anchors(parsed)} (what "
                             "`arapp markers aruco` prints); give --anchors anchors.json (a list of anchors as in "
                             "session.json) for another")
    except BaseException:
        source.close()
        raise
    return Input(source, parsed, blocks, notes, kind, blocks is DEFAULT_ANCHORS)
