"""Camera sources, calibration, anchors, SLAM and evaluation. No Qt, no rendering.

Conventions: metres, seconds, radians. Poses are 4x4 `world_from_camera`
matrices with OpenCV's camera frame (x right, y down, z forward).
"""
