"""The desk's points found again against the reference image itself (issue 25.4, desk.DeskPlane).

Optical flow (pyramidal Lucas-Kanade) matches a point's square window as it is: it assumes the patch only
shifted. Between the reference frame and one a few centimetres away the desk's image is also scaled by a
percent or two and turned by a degree or so, and the auto-exposure has changed its brightness by some
percent; each point's patch is then matched a few tenths of a pixel off, by an amount that depends on its
own texture and grows with the warp and the gain, so the same for every frame that sees the desk alike.
Followed frame to frame the error builds up the same way (each step's warp adds up to the whole). Such an
error, common to the frames it is measured in, was what kept the tilt from the desk a half degree off on
the tuning recordings (0.3-0.4 px of residual at the true poses, 97 % correlated between frames).

`match_to_reference` warps the reference image onto this frame by the homography the followed points give
(so that every point's patch has this frame's scale, turn and shear), scales its brightness to this frame's
by a smooth gain field (the auto-exposure and vignetting), and matches each point there, from where
the flow put it: 0.07 px of residual at the true poses.
"""

from __future__ import annotations

import cv2
import numpy as np

_GAIN_CELL = 16   # pixels: the gain field's cells (gain_matched)
_LK = dict(winSize=(15, 15), maxLevel=0, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01))


def gain_matched(image: np.ndarray, like: np.ndarray, cell: int = 16) -> np.ndarray:
    """`image` (uint8 grey) times a smooth gain field that brings its local mean brightness (over cells of
    `cell` pixels) to that of `like` (same size): exposure and vignetting differences, not texture."""
    h, w = like.shape
    small = (max(w // cell, 1), max(h // cell, 1))
    a = cv2.resize(like.astype(np.float32), small, interpolation=cv2.INTER_AREA)
    b = cv2.resize(image.astype(np.float32), small, interpolation=cv2.INTER_AREA)
    gain = cv2.resize(a / np.maximum(b, 1.0), (w, h), interpolation=cv2.INTER_LINEAR)
    return np.clip(image * gain + 0.5, 0, 255).astype(np.uint8)


def match_to_reference(ref_gray: np.ndarray, ref_px: np.ndarray, gray: np.ndarray, guess: np.ndarray,
                       ok: np.ndarray, max_move: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The reference points `ref_px` (N,2 pixels in `ref_gray`) matched in `gray`, starting from `guess` (N,2,
    where the flow put them) and warping the reference by the homography from `ref_px[ok]` to `guess[ok]`
    (module docstring). Returns (pixels (N,2) float32, ok (N,) narrowed to those matched within `max_move`
    pixels of the guess). With fewer than 8 points `ok` the guess is returned as it is."""
    if ok.sum() < 8:
        return guess, ok
    H, _ = cv2.findHomography(ref_px[ok], guess[ok], 0)
    if H is None:
        return guess, ok
    # only the part of the frame around the points is warped and matched (a frame's worth every frame cost
    # milliseconds): their box grown by the matching window and a margin for the gain field's cells
    h, w = gray.shape
    pad = _LK["winSize"][0] + _GAIN_CELL
    x0, y0 = np.maximum(np.floor(guess[ok].min(axis=0)).astype(int) - pad, 0)
    x1, y1 = np.minimum(np.ceil(guess[ok].max(axis=0)).astype(int) + pad + 1, (w, h))
    shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]]) @ H
    crop = np.ascontiguousarray(gray[y0:y1, x0:x1])
    warped = cv2.warpPerspective(ref_gray, shift, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REPLICATE)
    warped = gain_matched(warped, crop, _GAIN_CELL)
    offset = np.array([x0, y0], np.float32)
    q = cv2.perspectiveTransform(ref_px.reshape(-1, 1, 2).astype(np.float64), shift).reshape(-1, 2).astype(np.float32)
    found, st, _ = cv2.calcOpticalFlowPyrLK(warped, crop, q, (guess - offset).astype(np.float32),
                                            flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **_LK)
    found = found + offset
    ok = ok & (st.ravel() == 1) & (np.linalg.norm(found - guess, axis=1) < max_move)
    return found, ok
