"""The tracker's settings and state (tracking.fusion): settings are read from one `TrackerConfig`, the
per-frame state is a new `FrameState` each frame, and `reset()` leaves nothing of the session before.
Oracles: the rules written here (unknown names listed, counts at least 1), and a fresh tracker."""

import numpy as np
import pytest

from scenes import bundled_recording as recording
from tracking.fusion import Tracker, TrackerConfig
from tracking.fusion.config import make_config


def test_settings_come_from_one_config():
    cfg = make_config(TrackerConfig(marker_every=3), {"keypoint_every": 0, "max_lag": 2})
    assert (cfg.marker_every, cfg.keypoint_every, cfg.max_lag) == (3, 1, 2)   # a count below 1 is 1
    with pytest.raises(TypeError, match="unknown setting.*marker_evry.*TrackerConfig has"):
        make_config(None, {"marker_evry": 2})


def test_reset_tracks_as_a_fresh_tracker_does():
    """A tracker reset after 20 frames of board_orbit gives the same poses, to the bit, and builds the same
    map on the next 20 as a fresh one (mapping inline: deterministic)."""
    frames, session = recording("board_orbit", slice(0, 40))
    with Tracker(session.camera, session.anchors, threaded=False) as used, \
            Tracker(session.camera, session.anchors, threaded=False) as fresh:
        for t, img, _ in frames[:20]:
            used.process(img, t)
        used.reset()
        assert used.frame.index == 0 and len(used.map.points) == 0
        for k, (t, img, _) in enumerate(frames[20:], start=1):
            a, b = used.process(img, t), fresh.process(img, t)
            assert used.frame.index == k and used.frame.t == t   # this frame's state, made anew
            assert a.state == b.state and (a.world_from_camera is None) == (b.world_from_camera is None)
            assert a.world_from_camera is None or np.array_equal(a.world_from_camera, b.world_from_camera)
        kfs = [(k.t, k.pose) for k in used.map.keyframes.values()]
        assert len(kfs) >= 2 and [t for t, _ in kfs] == [k.t for k in fresh.map.keyframes.values()]
        assert all(np.array_equal(p, k.pose) for (_, p), k in zip(kfs, fresh.map.keyframes.values()))
