"""The still-background test for a lone marker held before a still camera (`anchor_motion.background_shift`):
the background's ORB matches between two frames, outside the anchors' outline, measured in pixels without any
pose. Oracle: images made here with a known shift (np.roll of a random texture), not the tracker's output."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.default_intrinsics import estimated_camera
from tracking.slam.anchor_motion import MIN_BACKGROUND, STILL_PX, background_shift
from tracking.slam.features import FeatureExtractor

W, H = 640, 480
CARD = (260, 180, 120, 120)   # x, y, w, h of the card in the first image


def _texture(seed: int, shape) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _frame(room_dx: int, card_dx: int) -> tuple[np.ndarray, np.ndarray]:
    """A wall texture moved `room_dx` px (the camera turned) with a card pasted on it moved `card_dx` px;
    the image and the card's outline in it (4,2 px)."""
    wall = np.roll(_texture(1, (H, W)), room_dx, axis=1)
    card = _texture(2, (CARD[3], CARD[2]))
    x, y = CARD[0] + card_dx, CARD[1]
    wall[y:y + CARD[3], x:x + CARD[2]] = card
    outline = np.array([[x, y], [x + CARD[2], y], [x + CARD[2], y + CARD[3]], [x, y + CARD[3]]], np.float32)
    return wall, outline


@pytest.fixture(scope="module")
def extractor():
    return FeatureExtractor(estimated_camera(W, H), n_features=800)


def _shift(extractor, before, now):
    (a, ra), (b, rb) = before, now
    return background_shift((extractor.extract(a), None, ra), (extractor.extract(b), None, rb))


def test_background_stands_still_while_the_card_moves(extractor):
    """A still camera, the card moved 25 px: the background's matches (away from both outlines) moved 0 px."""
    n, shift, still = _shift(extractor, _frame(0, 0), _frame(0, 25))
    assert n >= 3 * MIN_BACKGROUND
    assert shift <= 0.25 and still >= 0.95, (shift, still)


def test_background_moves_with_the_camera(extractor):
    """The camera turned (the whole wall moved 6 px) with the card still in the image: the matches moved 6 px,
    none of them under STILL_PX."""
    n, shift, still = _shift(extractor, _frame(0, 0), _frame(6, 0))
    assert n >= 3 * MIN_BACKGROUND
    assert abs(shift - 6.0) <= 0.5 and still <= 0.05, (shift, still)
    assert STILL_PX < 6.0


def test_too_little_background_gives_no_verdict(extractor):
    """An image almost all card (the outline covers it): fewer than MIN_BACKGROUND matches, no shift."""
    img, _ = _frame(0, 0)
    whole = np.array([[0, 0], [W, 0], [W, H], [0, H]], np.float32)
    n, shift, _ = background_shift((extractor.extract(img), None, whole), (extractor.extract(img), None, whole))
    assert n < MIN_BACKGROUND and np.isnan(shift)


def test_points_near_the_anchors_outline_as_opencv_measures_them():
    """`_inside` (all points at once) says what cv2.pointPolygonTest(region, p, measureDist=True) > -grow says of
    each point: inside, or outside by less than `grow` px; on a convex outline (what outline_region gives) and on
    a concave one, with points spread over and around it."""
    import cv2

    from tracking.slam.anchor_motion import _inside

    rng = np.random.default_rng(11)
    hull = cv2.convexHull(rng.uniform(100, 400, (12, 2)).astype(np.float32)).reshape(-1, 2)
    concave = np.array([[100, 100], [400, 100], [400, 400], [250, 200], [100, 400]], np.float32)
    for region in (hull, concave):
        px = rng.uniform(50, 450, (3000, 2))
        for grow in (0.5, 12.0):
            want = np.array([cv2.pointPolygonTest(region.reshape(-1, 1, 2), (float(x), float(y)), True) > -grow
                             for x, y in px])
            got = _inside(px, region, grow)
            # (a point within a micro-pixel of the grown edge may fall either way in float32 against float64)
            d = np.array([cv2.pointPolygonTest(region.reshape(-1, 1, 2), (float(x), float(y)), True) for x, y in px])
            tie = np.abs(d + grow) < 1e-3
            assert want.any() and (~want).any() and (got == want)[~tie].all()
    assert not _inside(np.zeros((5, 2)), None, 12.0).any() and _inside(np.zeros((0, 2)), hull, 12.0).shape == (0,)
