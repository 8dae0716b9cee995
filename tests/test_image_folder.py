"""A folder of images plays as a video in every command (tracking/sources/images.py), and anchor discovery
does not offer a board that no pose can fit (tracking/anchors/discover.py `_upright`).

Oracles: the real clipboard photos (tests/data/realvideo/SOURCES.md: 30 AprilTags 36h11, numbered up
their columns, so no OpenCV GridBoard) with OpenCV's own detector on each photo; images written by the test
with known grey levels and sizes; OpenCV's GridBoard corner order (corner 0 -> 1 along the board's x).
"""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from arapp.cli import main
from tracking.anchors.discover import Discovery, board_from_markers
from tracking.errors import SessionError
from tracking.sources import ImageFolderSource, open_source

CLIPBOARD = Path(__file__).resolve().parent / "data" / "realvideo" / "apriltag_clipboard"


def test_images_play_in_natural_name_order_at_30_fps(tmp_path):
    for name, grey in (("img10.png", 100), ("img2.png", 20), ("img1.png", 10), ("notes.txt", None)):
        if grey is None:
            (tmp_path / name).write_text("not an image")
        else:
            cv2.imwrite(str(tmp_path / name), np.full((24, 32), grey, np.uint8))
    with open_source(str(tmp_path)) as src:
        assert isinstance(src, ImageFolderSource)
        frames = list(src)
        assert src.error is None
        assert src.notes == [f"image folder {tmp_path} (3 images): played at 30 fps (a folder of images has no "
                             "frame rate)"]
    assert [int(f.image[0, 0, 0]) for f in frames] == [10, 20, 100]   # img1, img2, img10: not name order
    assert [f.t for f in frames] == pytest.approx([0.0, 1 / 30, 2 / 30])
    assert all(f.image.shape == (24, 32, 3) for f in frames)


def test_16_bit_and_grey_images_come_as_8_bit_colour(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.full((24, 32), 40000, np.uint16))   # 16-bit grey
    cv2.imwrite(str(tmp_path / "b.png"), np.full((24, 32, 4), 7, np.uint8))     # with alpha
    with open_source(str(tmp_path)) as src:
        frames = list(src)
    assert [f.image.dtype for f in frames] == [np.uint8, np.uint8]
    assert [f.image.shape for f in frames] == [(24, 32, 3), (24, 32, 3)]
    assert int(frames[0].image[0, 0, 0]) == 40000 >> 8 and int(frames[1].image[0, 0, 0]) == 7


def test_an_image_of_another_size_ends_the_stream_saying_which(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((24, 32), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((24, 32), np.uint8))
    cv2.imwrite(str(tmp_path / "c.png"), np.zeros((30, 40), np.uint8))
    with pytest.warns(RuntimeWarning):
        with open_source(str(tmp_path)) as src:
            frames = list(src)
    assert len(frames) == 2
    assert src.error == (f"{tmp_path / 'c.png'}: 40x30, but the folder's first image is 32x24; frames 0..1 were "
                         "delivered (every image must have one size)")


def test_a_folder_without_images_or_session_says_both(tmp_path):
    (tmp_path / "readme.txt").write_text("x")
    with pytest.raises(SessionError, match="no session.json, so not a recording folder, and no images"):
        open_source(str(tmp_path))


def _opencv_sees(frames_dir: Path, dictionary: str, marker_id: int) -> list[bool]:
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)))
    out = []
    for f in sorted(frames_dir.glob("*.png")):
        _c, ids, _r = det.detectMarkers(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE))
        out.append(ids is not None and marker_id in ids.ravel().tolist())
    return out


def test_replay_of_the_clipboard_photos_offers_a_tag_that_then_tracks(tmp_path, capsys):
    frames = CLIPBOARD / "frames"
    assert main(["replay", str(frames), "--out", str(tmp_path / "a"), "--no-video", "--no-slam"]) == 0
    out = capsys.readouterr().out
    assert f"image folder {frames} (10 images): played at 30 fps" in out
    # the tags are numbered up the sheet's columns: their centres fit a 5-column grid, but turned against the
    # markers, which no OpenCV board is; a lone tag is offered instead of a board no pose fits
    (found,) = json.loads((tmp_path / "a" / "anchors-found.json").read_text())
    assert found["kind"] == "aruco" and found["dictionary"] == "DICT_APRILTAG_36h11"
    assert main(["replay", str(frames), "--anchors", str(tmp_path / "a" / "anchors-found.json"),
                 "--out", str(tmp_path / "b"), "--no-video", "--no-slam"]) == 0
    states = [line.split(",")[2] for line in (tmp_path / "b" / "tracking.csv").read_text().splitlines()[1:]]
    seen = _opencv_sees(frames, found["dictionary"], found["id"])
    assert sum(seen) >= 8   # the tag offered is one OpenCV sees in most photos
    assert all(state == "marker" for state, s in zip(states, seen) if s)


def _grid_quads(nx: int, ny: int, side: float = 30.0, pitch: float = 40.0) -> np.ndarray:
    """Pixel corners of an nx x ny grid of upright markers, ids row by row from the top left, in OpenCV's
    corner order (0 top-left, 1 top-right, 2 bottom-right, 3 bottom-left), as a GridBoard seen head-on."""
    quads = []
    for k in range(nx * ny):
        x, y = 50 + pitch * (k % nx), 60 + pitch * (k // nx)
        quads.append([[x, y], [x + side, y], [x + side, y + side], [x, y + side]])
    return np.array(quads, float)


def test_a_grid_of_turned_markers_is_no_board():
    quads = _grid_quads(4, 3)
    board = board_from_markers("DICT_4X4_1000", "normal", np.arange(12), quads)
    assert board is not None and (board.block["markers_x"], board.block["markers_y"]) == (4, 3)
    # the same centres with every marker turned half round (corner 0 at the bottom right): ids that run
    # against the markers' own axes, as on a sheet numbered the other way
    turned = np.roll(quads, 2, axis=1)
    assert board_from_markers("DICT_4X4_1000", "normal", np.arange(12), turned) is None
    # mirrored (corners in the other sense): no pose turns a board into its mirror image
    mirrored = quads[:, ::-1]
    assert board_from_markers("DICT_4X4_1000", "normal", np.arange(12), mirrored) is None


def test_discovery_on_the_clipboard_suggests_no_board():
    found = Discovery()
    for f in sorted((CLIPBOARD / "frames").glob("*.png"))[:4]:
        found.look_all(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE))
    kinds = {s.kind for s in found.suggestions()}
    assert kinds == {"aruco"}


def test_anchors_without_their_place_are_said(tmp_path, capsys):
    # the contract (docs/recording-format.md): every anchor after the first carries world_from_anchor; a list
    # of tags without it (the clipboard's anchors.json) is tracked as if they all lay on the first: said once
    anchors = CLIPBOARD / "anchors.json"
    assert main(["replay", str(CLIPBOARD / "frames"), "--anchors", str(anchors), "--out", str(tmp_path / "a"),
                 "--no-video", "--no-slam", "--frames", "2"]) == 0
    said = [ln for ln in capsys.readouterr().out.splitlines() if "world_from_anchor" in ln]
    assert said == [f"replay: {anchors}: anchors[1], anchors[2], anchors[3], ... (29 of 30) have no world_from_anchor, "
                    "so each is taken to lie where the first anchor does; give each its place in the first one's "
                    "frame, or track one at a time (docs/recording-format.md)"]
    placed = json.loads(anchors.read_text())
    for i, block in enumerate(placed[1:3], start=1):
        block["world_from_anchor"] = [[1, 0, 0, 0.04 * i], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    (tmp_path / "two.json").write_text(json.dumps(placed[:3]))
    assert main(["replay", str(CLIPBOARD / "frames"), "--anchors", str(tmp_path / "two.json"), "--out",
                 str(tmp_path / "b"), "--no-video", "--no-slam", "--frames", "2"]) == 0
    assert not [ln for ln in capsys.readouterr().out.splitlines() if "world_from_anchor" in ln]


PHOTOS = Path(__file__).resolve().parent / "data" / "realphotos" / "opencv"


def test_one_photo_replays_as_a_one_frame_video(tmp_path, capsys):
    # a photo of markers (OpenCV's singlemarkerssource.jpg, DICT_6X6_250) given as it is, as a user tries one:
    # one frame, the tag discovery offers, then tracked on it; OpenCV's own detector is the oracle for the tag
    photo = PHOTOS / "singlemarkerssource.jpg"
    assert main(["replay", str(photo), "--out", str(tmp_path / "a"), "--no-video"]) == 0
    out = capsys.readouterr().out
    assert f"replay: image {photo}: no calibration" in out and "frames 1, tracked_fraction 0" in out
    assert "played at" not in out   # one image: no frame rate to speak of
    (found,) = json.loads((tmp_path / "a" / "anchors-found.json").read_text())
    gray = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, found["dictionary"]))
    _, ids, _ = cv2.aruco.ArucoDetector(dictionary).detectMarkers(gray)
    assert found["id"] in ids.ravel().tolist()
    assert main(["replay", str(photo), "--anchors", str(tmp_path / "a" / "anchors-found.json"),
                 "--out", str(tmp_path / "b"), "--no-video"]) == 0
    assert "frames 1, tracked_fraction 1" in capsys.readouterr().out


def test_a_video_that_stops_decoding_is_said_once_in_one_line(tmp_path, capsys):
    # an MJPG AVI cut at 60 %: its header promises 30 frames, 15-odd decode; Python's own warning (two lines,
    # one of them arapp's code) is not shown beside replay's line, and a stream that gave frames says which
    video = tmp_path / "cut.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, (160, 120))
    for i in range(30):
        writer.write(np.full((120, 160, 3), 8 * i, np.uint8))
    writer.release()
    video.write_bytes(video.read_bytes()[:int(video.stat().st_size * 0.6)])
    assert main(["replay", str(video), "--out", str(tmp_path / "r"), "--no-video", "--no-slam"]) == 0
    captured = capsys.readouterr()
    warned = [line for line in captured.out.splitlines() + captured.err.splitlines() if "decoding stopped" in line]
    assert len(warned) == 1 and warned[0].startswith("replay: warning: ")
    assert "SourceWarning" not in captured.err and "for frame in" not in captured.err
    n = json.loads((tmp_path / "r" / "report.json").read_text())["frames"]
    assert 0 < n < 30 and warned[0].endswith(f"of 30 (truncated or corrupt file); frames 0..{n - 1} were delivered")
    # the other commands show a source's warning in one line naming the command
    assert main(["calibrate", "--source", str(video), "-o", str(tmp_path / "c.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"arapp calibrate: warning: {video}: decoding stopped at frame {n} of 30" in err
    assert "SourceWarning" not in err


def test_a_stream_that_gave_nothing_says_so():
    from tracking.sources.base import Source

    assert Source._delivered(0) == "no frame was delivered"
    assert Source._delivered(3) == "frames 0..2 were delivered"
