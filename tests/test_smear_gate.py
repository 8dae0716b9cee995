"""Flow frames of a fast pan that skip the marker detection pass (tracking.fusion.smear_gate, issue 29: CPU per
frame): the rule on its own, and on a tuning pan the passes saved without any frame's pose changing.

Oracles: the rule as written (a miss in a fast pan, no smaller motion after it, a pass at least every
`max_skip + 1` frames), the detector's own pass count (`ArucoDetection.passes`), and the tracker with the
gate off (`smear_skip=0`) on the same frames.
"""

import numpy as np

from scenes import bundled_recording
from tracking.camera import Camera
from tracking.fusion import Tracker
from tracking.fusion.smear_gate import SmearGate, view_share

CAM = Camera(np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]), np.zeros(5), 640, 480)


def test_a_miss_in_a_fast_pan_skips_no_slower_frames_up_to_max_skip():
    gate = SmearGate(CAM, smear_px=10.0, max_skip=2)
    assert not gate.skip((30.0, 1.0))             # no miss yet: every frame detects
    gate.passed(False, (25.0, 1.0))               # a pass read nothing at 25 px a frame
    assert gate.skip((25.0, 1.0)) and gate.skip((31.0, 1.0))
    assert not gate.skip((32.0, 1.0))             # the third frame in a row runs its pass
    gate.passed(False, (32.0, 1.0))
    assert not gate.skip((31.0, 1.0))             # slower than the last miss: read again
    gate.passed(True, None)                       # anchors read: nothing held any longer
    assert not gate.skip((40.0, 1.0))


def test_a_miss_says_nothing_when_slow_out_of_view_or_unknown():
    gate = SmearGate(CAM, smear_px=10.0, max_skip=3)
    for motion in [(8.0, 1.0), (25.0, 0.3), None]:   # under smear_px; mostly out of view; no velocity
        gate.passed(False, motion)
        assert not gate.skip((30.0, 1.0))
    gate.passed(False, (25.0, 0.6))
    assert not gate.skip((30.0, 0.9))             # much more of the anchors in view: they may be read
    assert gate.skip((30.0, 0.7))
    gate.reset()                                  # a lost frame
    assert not gate.skip((30.0, 0.7))


def test_view_share_of_a_box_half_outside_the_image():
    assert view_share(CAM, np.array([[100.0, 100.0], [300.0, 200.0]])) == 1.0
    assert abs(view_share(CAM, np.array([[540.0, 100.0], [740.0, 200.0]])) - 0.5) < 1e-9
    assert view_share(CAM, np.array([[-300.0, 100.0], [-100.0, 200.0]])) == 0.0


def test_a_tuning_pan_saves_passes_and_no_pose_changes():
    """tune_fast_pan (the board smeared past reading for a third of its frames): measured 68 detector passes
    with the gate off, 49 with it (smear_skip 3), every frame's pose the same."""
    frames, session = bundled_recording("tune_fast_pan")
    runs = {}
    for skip in (0, 3):
        with Tracker(session.camera, session.anchors, smear_skip=skip) as tr:
            poses = []
            for t, img, _ in frames:
                res = tr.process(img, t)
                tr.catch_up()
                poses.append(None if res.world_from_camera is None else res.world_from_camera)
            runs[skip] = (poses, tr.anchor_tracker.aruco.passes)
    (off, passes_off), (on, passes_on) = runs[0], runs[3]
    assert passes_on <= passes_off - 10, (passes_on, passes_off)
    assert [p is None for p in off] == [p is None for p in on]
    assert max(float(np.abs(a - b).max()) for a, b in zip(off, on) if a is not None) < 1e-9
