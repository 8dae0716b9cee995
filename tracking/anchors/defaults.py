"""Defaults for new printed anchors (no OpenCV import here, so `arapp --help` stays fast).

DEFAULT_DICTIONARY: the ArUco dictionary of new markers, boards and ChArUco
boards (`arapp markers`, the app's new anchors). Its codes are at least 12 of
36 bits apart, rotations included, so printed squares that are not markers (a
4x4 "fragile glass" icon on a parcel decodes as DICT_4X4_50 id 17) match one
far less often than in the 4x4 dictionaries; see docs/markers.md. Recordings
keep the dictionary they state.
"""

DEFAULT_DICTIONARY = "DICT_ARUCO_MIP_36h12"
