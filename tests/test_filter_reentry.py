"""The anchors' filter after a board comes back into view mid-pan (tracking.anchors.tracker): its first
frames show a few smeared markers at the image edge, centimetres off; the filter restarts on them. When a
well-spread board follows, smeared too, its measurement used to be down-weighted against that poor state
and the output lagged 23 mm behind it (tune_fast_pan_b). Oracle: the recordings' ground truth and the
tracker's own unfiltered measurement."""

import numpy as np
import pytest

from scenes import bundled_recording as recording
from tracking.anchors import AnchorTracker


@pytest.mark.parametrize("name", ["tune_fast_pan", "tune_fast_pan_b", "tune_fast_pan_c", "tune_fast_pan_d"])
def test_a_board_after_a_partial_return_is_not_held_back_by_the_filter(name):
    frames, session = recording(name)
    tracker = AnchorTracker(session.anchors, session.camera)
    lag = []
    for t, image, truth in frames:
        r = tracker.process(image, t)
        if r.world_from_camera is not None and r.markers >= 6:
            lag.append(np.linalg.norm(r.world_from_camera[:3, 3] - truth[:3, 3])
                       - np.linalg.norm(r.raw_world_from_camera[:3, 3] - truth[:3, 3]))
    # measured: at most 0.2 mm worse than the measurement itself (23 mm on tune_fast_pan_b before)
    assert len(lag) > 10 and max(lag) < 0.002, max(lag)
