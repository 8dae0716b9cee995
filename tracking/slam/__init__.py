"""SLAM-style keypoint tracking in the anchors' metric world frame.

features (FAST+ORB, bucketed), map (keyframes, points), frame_pose (prediction,
projection matching, PnP, Huber refinement), mapping + ba (background local
mapping and bundle adjustment), fusion (anchors + keypoints, seamless
switching), relocalise (by keyframes). The pipeline uses tracking.fusion.Tracker.
"""
