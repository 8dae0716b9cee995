"""The tuning and test recordings (TUNING, TEST): the recordings bundled in recordings/ and the other
presets the tests and benchmarks read, rendered on demand into the recordings cache.

TUNING presets are the recordings the tracker's parameters were chosen on; TEST presets (names starting
with test_) were made later, from seeds never used for tuning, with webcam effects, and are only ever
measured (recordings/README.md).
"""

from __future__ import annotations

from tracking.synth.presets.parts import BOARD, MILD_DIST, fast_pan_twin, webcam_effects

PRESETS: dict[str, dict] = {
    # Easy: a GridBoard seen from an orbit over 80 degrees, mild distortion and noise.
    "board_orbit": {
        "name": "board_orbit", "seed": 1, "fps": 30, "duration": 3.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [BOARD],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 11},
        "trajectory": {"kind": "orbit", "azimuth_start": -130, "azimuth_end": -50, "distance": 0.45,
                       "elevation": 55, "elevation_swing": 8},
        "effects": {"noise": 0.6},
        "video": {"fourcc": "MJPG", "quality": 85},
    },
    # The same board at 1280x720 (wider lens), short.
    "board_orbit_720p": {
        "name": "board_orbit_720p", "seed": 2, "fps": 30, "duration": 1.5,
        "camera": {"width": 1280, "height": 720, "hfov_deg": 70, "dist": MILD_DIST},
        "anchors": [BOARD],
        "desk": {"size": [1.5, 1.2], "ppm": 2500, "seed": 12},
        "trajectory": {"kind": "orbit", "azimuth_start": -60, "azimuth_end": -120, "distance": 0.5,
                       "elevation": 60, "elevation_swing": 6},
        "effects": {"noise": 0.6},
        "video": {"fourcc": "MJPG", "quality": 75},
        "supersample": 2,
    },
    # One marker: a hand covers it (fully from 1.0 s to 3.0 s), then the camera pans away so it is
    # out of view from 3.8 s to 5.83 s, and back. For SLAM: the desk texture carries the pose.
    "marker_occluded": {
        "name": "marker_occluded", "seed": 3, "fps": 30, "duration": 7.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 7, "length": 0.06}],
        "desk": {"size": [1.8, 1.4], "ppm": 1800, "seed": 13},
        "trajectory": {"kind": "keyframes", "keys": [
            {"t": 0.0, "eye": [-0.12, -0.32, 0.38], "target": [0.0, 0.0, 0.0]},
            {"t": 1.5, "eye": [-0.02, -0.33, 0.37], "target": [0.01, 0.01, 0.0]},
            {"t": 3.0, "eye": [0.08, -0.31, 0.38], "target": [0.02, 0.0, 0.0]},
            {"t": 4.0, "eye": [0.24, -0.26, 0.38], "target": [0.42, 0.10, 0.0]},
            {"t": 5.6, "eye": [0.28, -0.22, 0.36], "target": [0.46, 0.14, 0.0]},
            {"t": 6.4, "eye": [0.10, -0.30, 0.38], "target": [0.02, 0.0, 0.0]},
            {"t": 7.0, "eye": [0.02, -0.32, 0.38], "target": [0.0, 0.0, 0.0]}],
            "shake": {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.5}},
        "effects": {"noise": 0.8, "occluder": {"start": 0.8, "end": 3.2, "ramp": 0.2, "anchor": 0}},
        "video": {"fourcc": "MJPG", "quality": 80},
    },
    # A QR code as the world anchor, hand-held orbit.
    "qr_anchor": {
        "name": "qr_anchor", "seed": 4, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 60, "dist": MILD_DIST},
        "anchors": [{"kind": "qr", "text": "arapp anchor 1", "length": 0.08}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 14},
        "trajectory": {"kind": "orbit", "azimuth_start": -110, "azimuth_end": -70, "distance": 0.42,
                       "elevation": 62, "shake": {"pos_mm": 2.0, "rot_deg": 0.3, "freq_hz": 2.0}},
        "effects": {"noise": 0.6},
        "video": {"fourcc": "MJPG", "quality": 85},
    },
    # Fast pans (up to ~80 deg/s) with motion blur, exposure changes and JPEG artefacts.
    "fast_motion": {
        "name": "fast_motion", "seed": 5, "fps": 30, "duration": 2.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [BOARD],
        "desk": {"size": [2.0, 1.6], "ppm": 1600, "seed": 15},
        "trajectory": {"kind": "pan", "azimuth": -90, "distance": 0.5, "elevation": 58, "pan_deg": 22,
                       "cycles": 1.5, "shake": {"pos_mm": 3.0, "rot_deg": 0.6, "freq_hz": 3.0}},
        "effects": {"noise": 1.5, "motion_blur": 0.8, "blur_samples": 7,
                    "exposure": {"amplitude": 0.15, "period": 1.7}, "jpeg_quality": 75, "vignette": 0.15},
        "video": {"fourcc": "MJPG", "quality": 85},
        "supersample": 2,
    },
    # A camera on a tripod: only sensor noise changes between frames (for pose jitter).
    "static_camera": {
        "name": "static_camera", "seed": 6, "fps": 30, "duration": 2.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 3, "length": 0.05}],
        "desk": {"size": [1.2, 1.0], "ppm": 2000, "seed": 16},
        "trajectory": {"kind": "static", "azimuth": -100, "distance": 0.4, "elevation": 60},
        "effects": {"noise": 2.5},
        "video": {"fourcc": "MJPG", "quality": 90},
    },
    # The AR print preview: a marker on a printer bed (first anchor = bed anchor), slow hand-held orbit.
    "printer_bed": {
        "name": "printer_bed", "seed": 7, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": MILD_DIST},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 42, "length": 0.04}],
        "desk": {"size": [0.9, 0.8], "ppm": 2200, "seed": 17, "style": "bed"},
        "trajectory": {"kind": "orbit", "azimuth_start": -120, "azimuth_end": -60, "distance": 0.35,
                       "elevation": 58, "target": [0.06, 0.06, 0.0],
                       "shake": {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.5}},
        "effects": {"noise": 0.6},
        "video": {"fourcc": "MJPG", "quality": 85},
    },
}


TUNING_TWINS: dict[str, dict] = {
    # A single 5 cm marker at ~0.42 m; fingertips come from the other side onto its white border.
    "tune_hand_border": {
        "name": "tune_hand_border", "seed": 301, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 63, "dist": [-0.07, 0.035, -0.0003, 0.0004, 0.0]},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 11, "length": 0.05}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 401},
        "trajectory": {"kind": "orbit", "azimuth_start": -78, "azimuth_end": -96, "distance": 0.42,
                       "elevation": 60, "shake": {"pos_mm": 1.8, "rot_deg": 0.3, "freq_hz": 1.7}},
        "effects": webcam_effects(occluder={"start": 0.5, "end": 2.0, "ramp": 0.5, "style": "border", "approach_deg": 170,
                                     "reach": 0.015, "offset": 0.01}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A single 5.5 cm marker at ~0.44 m; fingertips reach across the white border onto the black edge
    # (the case tune_hand_border lacks: a corner's edges partly covered, not just the paper around it).
    "tune_hand_edge": {
        "name": "tune_hand_edge", "seed": 305, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 61, "dist": [-0.05, 0.02, 0.0002, 0.0003, 0.0]},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 23, "length": 0.055}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 405},
        "trajectory": {"kind": "orbit", "azimuth_start": -70, "azimuth_end": -88, "distance": 0.44,
                       "elevation": 61, "shake": {"pos_mm": 1.6, "rot_deg": 0.28, "freq_hz": 1.6}},
        "effects": webcam_effects(occluder={"start": 0.5, "end": 2.1, "ramp": 0.5, "style": "border", "approach_deg": 100,
                                     "reach": 0.027, "offset": -0.011}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A single 5.8 cm marker at ~0.44 m; a hand slides in from the right (the side neither twin above
    # covers), its fingertips on the white border and the foremost ~2 mm onto the black edge near a
    # corner, held there, then gone (the third hand twin, made for issue 13's border jitter).
    "tune_hand_border_b": {
        "name": "tune_hand_border_b", "seed": 307, "fps": 30, "duration": 3.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": [-0.065, 0.03, -0.0002, 0.0003, 0.0]},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 29, "length": 0.058}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 407},
        "trajectory": {"kind": "orbit", "azimuth_start": -62, "azimuth_end": -76, "distance": 0.44,
                       "elevation": 61, "shake": {"pos_mm": 1.6, "rot_deg": 0.27, "freq_hz": 1.6}},
        "effects": webcam_effects(occluder={"start": 0.55, "end": 2.35, "ramp": 0.55, "style": "border", "approach_deg": -6,
                                     "reach": 0.0163, "offset": 0.0105}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A 4x4 GridBoard (36h12, 3.5 cm markers): over-exposed start, focus hunting, noisy sensor.
    "tune_webcam_board": {
        "name": "tune_webcam_board", "seed": 302, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 64, "dist": [-0.09, 0.05, 0.0005, -0.0004, 0.0]},
        "anchors": [{"kind": "aruco_board", "dictionary": "DICT_ARUCO_MIP_36h12", "markers_x": 4, "markers_y": 4,
                     "marker_length": 0.035, "separation": 0.007, "first_id": 4}],
        "desk": {"size": [1.5, 1.2], "ppm": 2000, "seed": 402},
        "trajectory": {"kind": "orbit", "azimuth_start": -120, "azimuth_end": -70, "distance": 0.46,
                       "elevation": 59, "elevation_swing": 5, "shake": {"pos_mm": 2.2, "rot_deg": 0.3, "freq_hz": 1.8}},
        "effects": webcam_effects(sensor={"full_well": 2200, "read_noise": 2.0}, rolling_shutter=0.028,
                           auto_exposure={"target": 112, "speed": 0.13, "initial_gain": 1.6},
                           defocus={"radius": 0.7, "swing": 0.5, "period": 1.6}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A QR code on a webcam, hand-held orbit at ~0.38 m.
    "tune_qr_webcam": {
        "name": "tune_qr_webcam", "seed": 303, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 60, "dist": [-0.06, 0.025, 0.0002, -0.0002, 0.0]},
        "anchors": [{"kind": "qr", "text": "arapp tuning anchor 3", "length": 0.07}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 403},
        "trajectory": {"kind": "orbit", "azimuth_start": -105, "azimuth_end": -72, "distance": 0.38,
                       "elevation": 61, "shake": {"pos_mm": 2.2, "rot_deg": 0.3, "freq_hz": 2.0}},
        "effects": webcam_effects(),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # Fast pans over a 5x3 GridBoard: motion blur along the true motion, rolling-shutter skew.
    "tune_fast_pan": fast_pan_twin(
        "tune_fast_pan", 304, 404, hfov_deg=61, dist=[-0.07, 0.03, -0.0004, 0.0005, 0.0],
        board=(5, 3, 0.032, 0.008, 20),
        pan={"azimuth": -85, "distance": 0.5, "elevation": 58, "pan_deg": 22,
             "cycles": 1.5, "shake": {"pos_mm": 2.8, "rot_deg": 0.55, "freq_hz": 2.8}}),
    # Fast pans over a 4x3 GridBoard (3.4 cm markers), 1.25 cycles: the second fast-pan twin (made in stop 13).
    "tune_fast_pan_b": fast_pan_twin(
        "tune_fast_pan_b", 306, 406, hfov_deg=60, dist=[-0.06, 0.035, 0.0003, -0.0004, 0.0],
        board=(4, 3, 0.034, 0.008, 35),
        pan={"azimuth": -90, "distance": 0.49, "elevation": 59, "pan_deg": 21,
             "cycles": 1.25, "shake": {"pos_mm": 2.6, "rot_deg": 0.5, "freq_hz": 2.6}}),
    # Fast pans over a 4x3 GridBoard (3.6 cm markers): the third fast-pan twin (made in stop 14), where the
    # board leaves with three markers in a row at the image edge that fit well and read 2 cm off.
    "tune_fast_pan_c": fast_pan_twin(
        "tune_fast_pan_c", 308, 408, hfov_deg=61, dist=[-0.075, 0.035, -0.0004, 0.0004, 0.0],
        board=(4, 3, 0.036, 0.008, 0),
        pan={"azimuth": -80, "distance": 0.47, "elevation": 61, "pan_deg": 20,
             "cycles": 1.25, "shake": {"pos_mm": 2.4, "rot_deg": 0.5, "freq_hz": 2.7}}),
    # Fast pans over a 4x3 GridBoard (3.4 cm markers), 1.3 cycles: the fourth fast-pan twin (stop 14), whose
    # first sighting is one marker at the image edge, sharp enough to start the pose 5 cm off.
    "tune_fast_pan_d": fast_pan_twin(
        "tune_fast_pan_d", 309, 409, hfov_deg=63, dist=[-0.07, 0.03, 0.0003, 0.0002, 0.0],
        board=(4, 3, 0.034, 0.009, 12),
        pan={"azimuth": -100, "distance": 0.49, "elevation": 59, "pan_deg": 19,
             "cycles": 1.3, "shake": {"pos_mm": 2.6, "rot_deg": 0.5, "freq_hz": 2.4}}),
    # Fast pans over a 4x3 GridBoard (3.5 cm markers), 1.2 cycles: the fifth fast-pan twin (stop 14), whose pose
    # starts on four smeared markers 18 mm off and whose velocity then rests on that start.
    "tune_fast_pan_e": fast_pan_twin(
        "tune_fast_pan_e", 310, 410, hfov_deg=60, dist=[-0.085, 0.045, 0.0004, -0.0003, 0.0],
        board=(4, 3, 0.035, 0.008, 24),
        pan={"azimuth": -110, "distance": 0.48, "elevation": 62, "pan_deg": 21,
             "cycles": 1.2, "shake": {"pos_mm": 2.5, "rot_deg": 0.5, "freq_hz": 2.5}}),
}
PRESETS.update(TUNING_TWINS)


TEST_PRESETS: dict[str, dict] = {
    # A single 6 cm marker seen from ~0.45 m; a hand's fingertips slide onto its white border (one
    # finger onto the black edge near a corner) from 0.6 s to 2.4 s and leave.
    "test_hand_border": {
        "name": "test_hand_border", "seed": 101, "fps": 30, "duration": 3.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 60, "dist": [-0.06, 0.03, 0.0003, -0.0004, 0.0]},
        "anchors": [{"kind": "aruco", "dictionary": "DICT_4X4_50", "id": 5, "length": 0.06}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 201},
        "trajectory": {"kind": "orbit", "azimuth_start": -100, "azimuth_end": -85, "distance": 0.45,
                       "elevation": 62, "shake": {"pos_mm": 1.5, "rot_deg": 0.25, "freq_hz": 1.5}},
        "effects": webcam_effects(occluder={"start": 0.6, "end": 2.4, "ramp": 0.6, "style": "border", "approach_deg": 10,
                                     "reach": 0.017, "offset": -0.012}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A 5x4 GridBoard (36h12 dictionary, 3 cm markers) on a webcam: starts over-exposed (auto-exposure
    # settles), focus hunts, white balance drifts, rolling shutter, noisy sensor.
    "test_webcam_board": {
        "name": "test_webcam_board", "seed": 102, "fps": 30, "duration": 3.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 66, "dist": [-0.1, 0.06, -0.0004, 0.0006, 0.0]},
        "anchors": [{"kind": "aruco_board", "dictionary": "DICT_ARUCO_MIP_36h12", "markers_x": 5, "markers_y": 4,
                     "marker_length": 0.03, "separation": 0.006, "first_id": 0}],
        "desk": {"size": [1.5, 1.2], "ppm": 2000, "seed": 202},
        "trajectory": {"kind": "orbit", "azimuth_start": -65, "azimuth_end": -125, "distance": 0.5,
                       "elevation": 57, "elevation_swing": 6, "shake": {"pos_mm": 2.0, "rot_deg": 0.3, "freq_hz": 2.0}},
        "effects": webcam_effects(sensor={"full_well": 2000, "read_noise": 2.0}, rolling_shutter=0.03,
                           auto_exposure={"target": 110, "speed": 0.12, "initial_gain": 1.7},
                           defocus={"radius": 0.8, "swing": 0.6, "period": 1.9}),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # A QR code on a webcam, hand-held orbit at ~0.4 m.
    "test_qr_webcam": {
        "name": "test_qr_webcam", "seed": 103, "fps": 30, "duration": 2.5,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": [-0.05, 0.02, 0.0, 0.0003, 0.0]},
        "anchors": [{"kind": "qr", "text": "arapp test anchor 2", "length": 0.075}],
        "desk": {"size": [1.4, 1.1], "ppm": 2000, "seed": 203},
        "trajectory": {"kind": "orbit", "azimuth_start": -75, "azimuth_end": -110, "distance": 0.4,
                       "elevation": 64, "shake": {"pos_mm": 2.0, "rot_deg": 0.35, "freq_hz": 2.2}},
        "effects": webcam_effects(),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
    # Fast pans over a GridBoard: motion blur along the true motion and rolling-shutter skew.
    "test_fast_pan": {
        "name": "test_fast_pan", "seed": 104, "fps": 30, "duration": 2.0,
        "camera": {"width": 640, "height": 480, "hfov_deg": 62, "dist": [-0.08, 0.04, 0.0005, -0.0005, 0.0]},
        "anchors": [{"kind": "aruco_board", "dictionary": "DICT_4X4_50", "markers_x": 4, "markers_y": 3,
                     "marker_length": 0.035, "separation": 0.008, "first_id": 10}],
        "desk": {"size": [2.0, 1.6], "ppm": 1600, "seed": 204},
        "trajectory": {"kind": "pan", "azimuth": -95, "distance": 0.48, "elevation": 60, "pan_deg": 20,
                       "cycles": 1.25, "shake": {"pos_mm": 2.5, "rot_deg": 0.5, "freq_hz": 2.5}},
        "effects": webcam_effects(motion_blur=0.6, blur_samples=7, rolling_shutter=0.03),
        "video": {"fourcc": "MJPG", "quality": 70},
        "supersample": 2,
    },
}
TUNING = list(PRESETS)
TEST = list(TEST_PRESETS)
PRESETS.update(TEST_PRESETS)
