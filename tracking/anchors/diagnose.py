"""Why the anchors of a session are not found (or found badly) in an image: plain-language hints.

`diagnose` checks one image: markers of another dictionary than declared; markers of the right
dictionary with other ids; QR codes with other texts; boards whose declared marker_length /
separation do not fit the image (large reprojection error); anchors whose declared size disagrees
with the others seen with them.

`why_untracked` words why a whole run (a replay, a GUI session) tracked nothing, from what anchor
discovery (anchors/discover.py) saw in its frames: no marker seen at all, markers of another
dictionary or polarity, markers of the right dictionary with other ids, QR codes with other text, or
the anchor list's default in use; `suggestion_line` offers what discovery found as `--anchors` JSON.
"""

from __future__ import annotations

import cv2
import numpy as np

import json

from tracking.anchors.detect import ARUCO_FAMILIES, ArucoDetection
from tracking.anchors.discover import DEFAULT_MARKER_M, Discovery, Suggestion, family_of, id_span
from tracking.anchors.kinds.base import mm
from tracking.anchors.kinds.charuco import is_legacy
from tracking.anchors.kinds.qr import normal_text
from tracking.anchors.model import build_models
from tracking.anchors.pose import solve_pose
from tracking.camera import Camera
from tracking.anchors.kinds import AnchorSpec
from tracking.anchors.kinds.base import aruco_dictionary_names

# the largest dictionary of each family: a marker of a smaller one is found in it with the same id
_FAMILIES = ["DICT_4X4_1000", "DICT_5X5_1000", "DICT_6X6_1000", "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL",
             "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10", "DICT_APRILTAG_36h11",
             "DICT_ARUCO_MIP_36h12"]


def _gray(image):
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def diagnose(anchors: list[AnchorSpec], camera: Camera, image: np.ndarray, max_board_rms: float = 2.0) -> list[str]:
    """Hints (strings naming `anchors[i].field`) about mismatches between the session and the image."""
    gray = _gray(image)
    models = build_models(anchors)
    obs = ArucoDetection(models, camera).detect(gray)
    seen = {o.anchor for o in obs}
    hints = _dictionary_hints(models, seen, _markers_by_family(gray))
    hints += _qr_hints(models, gray)
    alone, layout = _layout_hints(models, obs, camera, max_board_rms)
    return hints + layout + _scale_hints(models, alone)


def _markers_by_family(gray) -> dict[str, list[int]]:
    """The ids every predefined dictionary family finds in the image (families that find none left out)."""
    names = set(aruco_dictionary_names())
    params = cv2.aruco.DetectorParameters()
    found = {}
    for fam in _FAMILIES:
        if fam not in names:
            continue
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, fam))
        _, ids, _ = cv2.aruco.ArucoDetector(d, params).detectMarkers(gray)
        if ids is not None:
            found[fam] = sorted(set(ids.ravel().tolist()))
    return found


def _dictionary_hints(models, seen: set, found_by_family: dict) -> list[str]:
    """Marker anchors not seen while markers of the same family (other ids) or another family are."""
    hints = []
    for m in models:
        if m.anchor_kind.detector not in ARUCO_FAMILIES or m.index in seen:
            continue
        a = m.spec
        fam_declared = a.dictionary.split("_")[1] if a.dictionary.startswith("DICT_") else a.dictionary
        same = [f for f in found_by_family if f.split("_")[1] == fam_declared]
        others = {f: v for f, v in found_by_family.items() if f.split("_")[1] != fam_declared}
        want = sorted(m.markers)
        if same and found_by_family[same[0]]:
            hints.append(f"anchors[{m.index}]: no {a.dictionary} marker with id(s) {_ids(want)} found, but the image "
                         f"shows {a.dictionary.split('_')[1]} markers with ids {_ids(found_by_family[same[0]])}: "
                         f"check anchors[{m.index}].id / first_id (and that the ids fit {a.dictionary})")
        elif others:
            desc = "; ".join(f"{f} ids {_ids(v)}" for f, v in others.items())
            hints.append(f"anchors[{m.index}]: no {a.dictionary} markers found, but the image shows markers of "
                         f"another dictionary ({desc}): set anchors[{m.index}].dictionary to the one that was printed")
    return hints


def _qr_hints(models, gray) -> list[str]:
    """QR anchors whose text no code in the image carries, while codes with other texts are seen."""
    qr_models = [m for m in models if m.anchor_kind.detector == "qr"]
    if not qr_models:
        return []
    ok, texts, _, _ = cv2.QRCodeDetector().detectAndDecodeMulti(gray)
    texts = [t for t in (texts if ok else []) if t]
    read = {normal_text(t) for t in texts}
    wanted = {normal_text(m.spec.text) for m in qr_models}
    return [f"anchors[{m.index}]: no QR code with text {m.spec.text!r}, but the image shows "
            f"QR code(s) {texts}: set anchors[{m.index}].text to the printed text"
            for m in qr_models if normal_text(m.spec.text) not in read and texts and not (read & wanted)]


def _layout_hints(models, obs, camera: Camera, max_board_rms: float) -> tuple[dict, list[str]]:
    """Each seen anchor's pose on its own (by anchor index), and hints for boards that do not fit their
    declared layout (reprojection error over `max_board_rms` px)."""
    wfa = [m.world_from_anchor for m in models]
    alone, hints = {}, []
    for o in obs:
        sol = solve_pose([o], wfa, camera, outlier_px=1e3)
        if sol is None:
            continue
        alone[o.anchor] = sol
        kind = models[o.anchor].kind
        fields = models[o.anchor].anchor_kind.layout_fields
        if fields and sol.rms > max_board_rms:
            hints.append(f"anchors[{o.anchor}]: the {kind} does not fit its declared layout (reprojection error "
                         f"{sol.rms:.1f} px): check anchors[{o.anchor}].{fields.replace(' and ', ' and .')} "
                         f"against the printed board ({fields} in metres)")
    return alone, hints


def _scale_hints(models, alone: dict) -> list[str]:
    """Anchors seen together must agree on scale: each against the best reference (boards before lone squares)."""
    if len(alone) < 2:
        return []
    ref = min(alone, key=lambda k: (models[k].anchor_kind.single_square, k))
    hints = []
    for k, sol in alone.items():
        if k == ref:
            continue
        # Scale error of anchor k shows as its own distance estimate disagreeing with the reference.
        dk = np.linalg.norm(sol.camera_from_world[:3, :3] @ models[k].world_from_anchor[:3, 3] + sol.camera_from_world[:3, 3])
        dr = np.linalg.norm(alone[ref].camera_from_world[:3, :3] @ models[k].world_from_anchor[:3, 3]
                            + alone[ref].camera_from_world[:3, 3])
        ratio = dk / dr if dr > 0 else 1.0
        if abs(ratio - 1.0) > 0.05:
            field = models[k].anchor_kind.size_fields
            hints.append(f"anchors[{k}] looks {ratio:.2f} times as far as anchors[{ref}] says it is: its "
                         f"declared size is probably wrong by that factor (check anchors[{k}].{field}, metres, "
                         f"and its world_from_anchor)")
    return hints


def _ids(ids) -> str:
    ids = list(ids)
    return ", ".join(map(str, ids[:8])) + (", ..." if len(ids) > 8 else "")


# -- a run that tracked nothing ---------------------------------------------------------------------
def why_untracked(anchors: list[AnchorSpec], found: Discovery, default_anchors: bool = False) -> list[str]:
    """One-line reasons why a run with `anchors` tracked nothing, from what `found` saw in its frames
    (discover.Discovery); the first is the likeliest. `default_anchors`: the anchors are the default
    the command used because none were given (a plain video, `arapp record` without --anchors)."""
    reasons = []
    seen = found.markers_seen
    texts = found.texts_seen
    looked = f"{found.frames_looked} frame{'s' if found.frames_looked != 1 else ''} looked at"
    if default_anchors:
        what = " or ".join(a.anchor_kind.describe(a) for a in anchors)
        reasons.append(f"no anchors were given, so the default ({what}) was looked for")
    for i, a in enumerate(anchors):
        if a.anchor_kind.detector == "qr":
            other = [t for t in texts if normal_text(t) != normal_text(a.text)]
            if other and len(other) == len(texts):
                shown = ", ".join(repr(t) for t in other[:3])
                reasons.append(f"QR codes with other text seen ({shown}), not anchors[{i}].text {a.text!r}")
            continue
        family = family_of(a.dictionary)
        want = set(a.marker_ids())
        for (fam, pol), ids in seen.items():
            if fam != family:
                continue
            hit = want & set(ids)
            if pol != a.polarity and a.polarity != "auto" and hit:
                reasons.append(f"{a.dictionary} markers seen printed {pol}"
                               f"{' (white on black)' if pol == 'inverted' else ''}, but anchors[{i}].polarity is "
                               f"{a.polarity!r}: set it to {pol!r} or \"auto\"")
            elif hit:
                reasons.append(_pattern_hint(a, i, found, hit) or
                               f"anchors[{i}]'s markers were seen (ids {id_span(sorted(hit))}) but gave no pose: "
                               f"too few, too small or too blurred (hold the sheet closer and steadier)")
            else:
                reasons.append(f"{a.dictionary.rsplit('_', 1)[0] if family else a.dictionary} markers seen with ids "
                               f"{id_span(ids)}, not anchors[{i}]'s ids {id_span(sorted(want))}: check "
                               f"anchors[{i}].id / first_id")
    ours = {family_of(a.dictionary) for a in anchors if a.dictionary}
    others = {k: v for k, v in seen.items() if k[0] not in ours}
    if others:
        shown = "; ".join(f"{fam.rsplit('_', 1)[0] if fam[5:6].isdigit() else fam} ids {id_span(ids)}"
                          + (" (printed inverted)" if pol == "inverted" else "") for (fam, pol), ids in others.items())
        dicts = ", ".join(sorted({a.dictionary for a in anchors if a.dictionary})) or "QR codes"
        reasons.append(f"markers of another dictionary seen ({shown}), not the anchors' {dicts}")
    if texts and not any(a.anchor_kind.detector == "qr" for a in anchors):
        reasons.append(f"QR codes seen ({', '.join(repr(t) for t in texts[:3])}) but no QR anchor is set up")
    if not seen and not texts:
        reasons.append(f"no marker or QR code of any dictionary seen ({looked}, both polarities)")
    return reasons


def _pattern_hint(a: AnchorSpec, i: int, found: Discovery, hit: set) -> str | None:
    """For a ChArUco anchor (anchors[i]) whose markers were seen but gave no pose: what to change when discovery
    found the board printed in the other pattern (OpenCV's legacy one before 4.6, or today's); else None."""
    if a.kind != "charuco":
        return None
    for s in found.suggestions():
        b = s.block
        if s.kind == "charuco" and (b["squares_x"], b["squares_y"]) == (a.squares_x, a.squares_y) and \
                bool(b.get("legacy")) != is_legacy(a):
            change = 'add "legacy": true to it' if b.get("legacy") else 'drop its "legacy"'
            old = "the legacy pattern of OpenCV before 4.6" if b.get("legacy") else "today's pattern (OpenCV 4.6 on)"
            return (f"anchors[{i}]'s markers were seen (ids {id_span(sorted(hit))}), but the board is printed in "
                    f"{old}: {change}")
    return None


def why_line(anchors: list[AnchorSpec], found: Discovery, default_anchors: bool = False) -> str:
    """'nothing tracked: <reasons>' in one line (why_untracked)."""
    return "nothing tracked: " + "; ".join(why_untracked(anchors, found, default_anchors))


def suggestion_line(s: Suggestion, written: str | None = None) -> str:
    """'found a 4x3 DICT_4X4_50 board (ids 0-11); with 40 mm markers (measure yours) use --anchors FILE
    holding: [{...}]' for a discovery's suggestion; `written`: the path of a file that already holds that
    anchor list (`suggestion_anchors`), named instead of the JSON."""
    size = "a 50 mm code" if s.kind == "qr" else f"{mm(DEFAULT_MARKER_M)} markers"
    head = f"found {s.summary}; assuming {size} (measure yours and scale {s.size_field})"
    if written is not None:
        return f"{head}, use --anchors {written} (written with that anchor)"
    return f"{head}, use --anchors FILE holding: {json.dumps([s.block])}"


def suggestion_anchors(s: Suggestion) -> str:
    """The anchor list (JSON text, as `--anchors` files hold it) of a discovery's suggestion."""
    return json.dumps([s.block], indent=2) + "\n"
