"""The live view's picture made from the frame scaled ahead, with the overlay laid on afterwards
(arapp.render.composite.over_scaled, arapp.engine.processor.Processor._picture): the same picture as scaling
the composite (the oracle: the crop composited at full size with over_bgr, then cv2.resize), up to rounding."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from arapp.engine.processor import to_bgra
from arapp.render.composite import over_bgr, over_scaled

W, H = 640, 360


def _scene():
    """A smooth random frame and a premultiplied RGBA crop (120x90) with a soft-edged round alpha."""
    rng = np.random.default_rng(1)
    frame = cv2.GaussianBlur(rng.integers(0, 256, (H, W, 3), np.uint8), (0, 0), 1.5)
    yy, xx = np.mgrid[0:90, 0:120]
    alpha = np.clip(765 * (1.2 - np.hypot((xx - 60) / 50, (yy - 45) / 38)), 0, 255).astype(np.uint8)
    rgb = cv2.GaussianBlur(rng.integers(0, 256, (90, 120, 3)).astype(np.float64), (0, 0), 2)
    crop = np.dstack([(rgb * alpha[..., None] / 255).round().astype(np.uint8), alpha])
    return frame, crop


def _scaled(image, size):
    return image if size == (W, H) else cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)


@pytest.mark.parametrize("scale", [0.5, 0.73, 0.92, 1.0, 1.37])
@pytest.mark.parametrize("at", [(200, 100), (0, 0), (W - 120, H - 90)])
def test_the_overlay_laid_on_the_scaled_frame_is_the_scaled_composite(scale, at):
    frame, crop = _scene()
    size = (round(W * scale), round(H * scale))
    composite = frame.copy()
    over_bgr(composite, crop, *at)
    expected = to_bgra(_scaled(composite, size))
    picture = to_bgra(_scaled(frame, size))
    over_scaled(picture, crop, *at, (size[0] / W, size[1] / H))
    d = np.abs(picture.astype(int) - expected.astype(int))
    # measured: at most 2 levels, 0.007 on average (the two resamplings round apart); exact at scale 1
    assert d.max() <= 2 and d.mean() < 0.02, (d.max(), d.mean())
    assert (picture[..., 3] == 255).all()
    # the crop left a mark where it has alpha, and nothing anywhere else
    assert (d.max(axis=2) == 0).mean() > 0.9


def test_the_processor_scales_the_frame_ahead_and_lays_the_overlay_on_it():
    from arapp.engine.pipeline import FrameResult
    from arapp.engine.player import Captured
    from arapp.engine.processor import Processor
    from arapp.engine.slots import LatestSlot

    frame, crop = _scene()
    composite = frame.copy()
    over_bgr(composite, crop, 200, 100)

    class Pipeline:
        draw, status_line = True, False

        def __init__(self):
            self.overlay = []

        def process(self, image, t, index):
            self.overlay = [(crop, 200, 100)]
            return FrameResult(index, t, None, "lost", 0, 0, 0.0, 0.0, composite)

        def close(self):
            pass

    inbox, out = LatestSlot(), LatestSlot()
    proc = Processor(Pipeline, inbox, out)
    proc.display_size = (500, 400)   # the frame scaled to 500 x 281, its aspect kept
    proc.start()
    inbox.put(Captured(0, 0.0, frame, time.perf_counter()))
    shown = out.take(timeout=5.0)
    proc.stop()
    proc.join(2.0)
    assert shown is not None and shown.display.shape == (281, 500, 4)
    expected = to_bgra(_scaled(composite, (500, 281)))
    d = np.abs(shown.display.astype(int) - expected.astype(int))
    assert d.max() <= 2 and 0 < (d > 0).mean() < 0.05, (d.max(), (d > 0).mean())
    assert shown.result.image is composite   # the full-size composite goes on as the pipeline made it
