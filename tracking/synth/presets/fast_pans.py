"""Extra fast-pan tuning scenes (EXTRA_TUNING), rendered on demand, never bundled."""

from __future__ import annotations

from tracking.synth.presets.parts import fast_pan_twin

# Extra fast-pan tuning scenes (stop 15): rendered on demand (`arapp synth xt_fast_pan_f --out DIR`), not
# bundled (the tests and benchmarks do not run on them, and the repository keeps its size). They were made
# from the test recording's written description with fresh seeds (scene 311-318, desk 411-418) to judge the
# flow's changes on more than five pans; they are tuning data like the rest.
# (name, scene seed, desk seed, hfov_deg, dist, (markers_x, markers_y, length m, separation m, first_id),
#  azimuth deg, distance m, elevation deg, pan_deg, cycles, shake (pos_mm, rot_deg, freq_hz));
# j's board comes back as one sharp marker at a pan's turn (it took over from the flow, 62 mm off)
_EXTRA_PANS = [
    ("xt_fast_pan_f", 311, 411, 62, [-0.07, 0.04, 0.0003, -0.0003, 0.0], (4, 3, 0.035, 0.008, 36),
     -92, 0.48, 60, 20, 1.25, (2.5, 0.5, 2.6)),
    ("xt_fast_pan_g", 312, 412, 61, [-0.08, 0.045, -0.0003, 0.0004, 0.0], (4, 3, 0.034, 0.008, 0),
     -100, 0.47, 61, 21, 1.2, (2.4, 0.5, 2.4)),
    ("xt_fast_pan_h", 313, 413, 63, [-0.075, 0.035, 0.0004, 0.0003, 0.0], (4, 3, 0.035, 0.009, 12),
     -88, 0.49, 59, 19, 1.3, (2.6, 0.5, 2.5)),
    ("xt_fast_pan_i", 314, 414, 60, [-0.085, 0.04, -0.0004, -0.0004, 0.0], (4, 3, 0.036, 0.008, 24),
     -97, 0.48, 60, 20, 1.25, (2.5, 0.5, 2.5)),
    ("xt_fast_pan_j", 315, 415, 61, [-0.075, 0.04, 0.0005, -0.0002, 0.0], (4, 3, 0.035, 0.008, 38),
     -105, 0.48, 62, 20, 1.25, (2.5, 0.5, 2.5)),
    ("xt_fast_pan_k", 316, 416, 62, [-0.08, 0.04, -0.0005, 0.0005, 0.0], (4, 3, 0.035, 0.008, 5),
     -85, 0.5, 58, 21, 1.25, (2.6, 0.55, 2.7)),
    ("xt_fast_pan_l", 317, 417, 60, [-0.07, 0.035, 0.0002, 0.0005, 0.0], (4, 3, 0.034, 0.008, 16),
     -95, 0.47, 61, 20, 1.3, (2.4, 0.45, 2.4)),
    ("xt_fast_pan_m", 318, 418, 62, [-0.08, 0.04, 0.0005, -0.0005, 0.0], (4, 3, 0.035, 0.008, 28),
     -90, 0.48, 60, 20, 1.25, (2.5, 0.5, 2.5)),
    # n-q (stop 16): rendered after the flow's hand-over rule (tracker.FLOW_DRIFT_M) was chosen on the ones
    # above, as its first check on pans it had not seen
    ("xt_fast_pan_n", 319, 419, 61, [-0.07, 0.035, -0.0004, 0.0002, 0.0], (4, 3, 0.036, 0.008, 8),
     -94, 0.49, 59, 21, 1.2, (2.6, 0.5, 2.6)),
    ("xt_fast_pan_o", 320, 420, 63, [-0.085, 0.045, 0.0003, 0.0004, 0.0], (4, 3, 0.034, 0.009, 20),
     -102, 0.47, 61, 19, 1.3, (2.4, 0.5, 2.5)),
    ("xt_fast_pan_p", 321, 421, 60, [-0.075, 0.04, -0.0002, -0.0005, 0.0], (4, 3, 0.035, 0.008, 32),
     -87, 0.48, 60, 20, 1.25, (2.5, 0.55, 2.4)),
    ("xt_fast_pan_q", 322, 422, 62, [-0.08, 0.035, 0.0005, 0.0003, 0.0], (4, 3, 0.035, 0.008, 2),
     -98, 0.5, 62, 21, 1.25, (2.5, 0.5, 2.7)),
]
EXTRA_TUNING: dict[str, dict] = {
    name: fast_pan_twin(name, seed, desk, hfov_deg=hfov, dist=dist, board=board,
                         pan={"azimuth": az, "distance": d, "elevation": el, "pan_deg": pan, "cycles": cyc,
                              "shake": {"pos_mm": sh[0], "rot_deg": sh[1], "freq_hz": sh[2]}})
    for name, seed, desk, hfov, dist, board, az, d, el, pan, cyc, sh in _EXTRA_PANS
}
