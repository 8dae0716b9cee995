"""Why the anchors of a session are not found (or found badly) in an image: plain-language hints.

Checks: markers of another dictionary than declared; markers of the right
dictionary with other ids; QR codes with other texts; boards whose declared
marker_length / separation do not fit the image (large reprojection error);
anchors whose declared size disagrees with the others seen with them.
"""

from __future__ import annotations

import cv2
import numpy as np

from tracking.anchors.detect import ARUCO_FAMILIES, ArucoDetection
from tracking.anchors.model import build_models
from tracking.anchors.pose import solve_pose
from tracking.camera import Camera
from tracking.session import AnchorSpec, aruco_dictionary_names

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
    hints = []
    det = ArucoDetection(models, camera)
    obs = det.detect(gray)
    seen = {o.anchor for o in obs}
    names = set(aruco_dictionary_names())
    params = cv2.aruco.DetectorParameters()
    found_by_family = {}
    for fam in _FAMILIES:
        if fam not in names:
            continue
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, fam))
        _, ids, _ = cv2.aruco.ArucoDetector(d, params).detectMarkers(gray)
        if ids is not None:
            found_by_family[fam] = sorted(set(ids.ravel().tolist()))
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
    qr_models = [m for m in models if m.anchor_kind.detector == "qr"]
    if qr_models:
        ok, texts, _, _ = cv2.QRCodeDetector().detectAndDecodeMulti(gray)
        texts = [t for t in (texts if ok else []) if t]
        wanted = {m.spec.text for m in qr_models}
        for m in qr_models:
            if m.spec.text not in texts and texts and not (set(texts) & wanted):
                hints.append(f"anchors[{m.index}]: no QR code with text {m.spec.text!r}, but the image shows "
                             f"QR code(s) {texts}: set anchors[{m.index}].text to the printed text")
    # Geometry: each board alone must fit its own declared layout; anchors seen together must agree on scale.
    wfa = [m.world_from_anchor for m in models]
    alone = {}
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
    if len(alone) >= 2:
        # boards are the best scale reference, a lone square the worst
        ref = min(alone, key=lambda k: (models[k].anchor_kind.single_square, k))
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
