"""Benchmark: arapp against plain OpenCV on real photos nobody on this project took (tests/data/realphotos).

Counts, over all photos: QR codes decoded by OpenCV's classic detector and by its ArUco-based (fastest)
one, and QR anchors arapp makes of them; ArUco markers found by cv2.aruco.ArucoDetector and by arapp
(same dictionary); board and marker poses against OpenCV's. The helpers (cameras, oracles) are the
tests' own: tests/realphotos_data.py.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import realphotos_data as rp  # noqa: E402


def _qr_counts() -> dict:
    """Per zxing photo: classic decodes, ArUco-based decodes, arapp anchors (and among the classic ones)."""
    out = {"photos": 0, "classic": 0, "aruco_qr": 0, "arapp": 0, "arapp_of_classic": 0, "ms": []}
    for name in rp.QR_PHOTOS:
        gray = cv2.imread(str(rp.DATA / name), cv2.IMREAD_GRAYSCALE)
        text = (rp.DATA / name).with_suffix(".txt").read_text(encoding="utf-8")
        try:
            ok, texts, _, _ = cv2.QRCodeDetectorAruco().detectAndDecodeMulti(gray)
            aruco_ok = bool(ok) and text in texts
        except (cv2.error, UnicodeDecodeError):
            aruco_ok = False
        c = rp.qr_anchor_check(name)
        out["ms"].append(c.ms)
        out["photos"] += 1
        out["classic"] += c.classic
        out["aruco_qr"] += aruco_ok
        out["arapp"] += c.arapp
        out["arapp_of_classic"] += c.arapp and c.classic
    return out


def run(quick: bool = False) -> str:
    qr = _qr_counts()
    rows = []
    tot_ocv = tot_single = tot_arapp = tot_extra = tot_missing = 0
    for name in sorted(rp.ARUCO_PHOTOS):
        m = rp.aruco_match(name)
        extra, missing = len(m.arapp - m.opencv_single), len(m.opencv_single - m.arapp)
        tot_ocv += len(m.opencv)
        tot_single += len(m.opencv_single)
        tot_arapp += len(m.arapp)
        tot_extra += extra
        tot_missing += missing
        rows.append(f"| {Path(name).name} | {len(m.opencv)} | {len(m.opencv_single)} | {len(m.arapp)} | {missing} | "
                    f"{extra} | {m.worst_corner_fraction * 100:.1f} % |")
    board = rp.board_pose_check()
    singles = rp.single_marker_checks()
    lines = [
        "## Real photos (tests/data/realphotos: OpenCV's and zxing's, Apache-2.0)",
        "",
        f"QR codes on {qr['photos']} zxing phone photos (one code each, 240 x 240, blur, glare, curved paper; the "
        "focal length estimated from the code's corners as the classic detector finds them):",
        "",
        "| | codes read / anchors |",
        "| --- | --- |",
        f"| OpenCV classic `QRCodeDetector.detectAndDecodeMulti` | {qr['classic']} |",
        f"| OpenCV ArUco-based `QRCodeDetectorAruco.detectAndDecodeMulti` (fastest) | {qr['aruco_qr']} |",
        f"| arapp QR anchors with a pose | {qr['arapp']} |",
        f"| of those the classic detector reads | {qr['arapp_of_classic']} of {qr['classic']} |",
        "| arapp time per photo (one frame: search, decode, pose; both detectors when needed), median | "
        f"{np.median(qr['ms']):.1f} ms |",
        "",
        "ArUco markers (each photo's own dictionary; OpenCV's ArucoDetector with CORNER_REFINE_SUBPIX against "
        "arapp's detection with every id of the dictionary as an anchor). An id OpenCV sees twice (the "
        "photos of four views side by side, the diamonds) is ambiguous and arapp drops it on purpose:",
        "",
        "| photo | OpenCV markers | OpenCV ids seen once | arapp | missed | extra | worst corner gap / side |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        f"| **all** | {tot_ocv} | {tot_single} | {tot_arapp} | {tot_missing} | {tot_extra} | |",
        "",
        "Poses against OpenCV's (matchImagePoints + solvePnP; sigma: OpenCV's own pose spread from its corner "
        "residuals, at least 0.5 px a corner):",
        "",
        "| target | markers arapp / OpenCV | position diff | sigma | rotation diff | sigma |",
        "| --- | --- | --- | --- | --- | --- |",
        f"| gbocclusion.jpg 5x7 GridBoard (custom dictionary) | {board.markers} / {board.opencv_markers} | "
        f"{board.position_diff * 1000:.2f} mm | {board.position_sigma * 1000:.2f} mm | "
        f"{board.rotation_diff_deg:.3f} deg | {board.rotation_sigma_deg:.3f} deg |",
        f"| singlemarkerssource.jpg, 6 lone 50 mm markers (worst) | 1 / 1 | "
        f"{max(c.position_diff for c in singles) * 1000:.2f} mm | "
        f"{min(c.position_sigma for c in singles) * 1000:.2f} mm | "
        f"{max(c.rotation_diff_deg for c in singles):.3f} deg | {min(c.rotation_sigma_deg for c in singles):.3f} deg |",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run(quick="--quick" in sys.argv))
