"""The pose shown: seamless across changes of its source (anchors / fused / map), the step at a seam
faded by `tracking.slam.fusion.PoseBlender` over `blend_frames`, `precise_blend_frames` (onto a board) or
`fast_blend_frames` (in a fast pan)."""

from __future__ import annotations

import numpy as np

from tracking.camera import Camera
from tracking.fusion.config import TrackerConfig
from tracking.fusion.state import FrameState
from tracking.poses import invert
from tracking.slam.frame_pose import MotionModel
from tracking.slam.fusion import PoseBlender


class Output:
    """The output pose: the last one shown (`last`, world_from_camera), its `source`, and the fade."""

    def __init__(self, config: TrackerConfig, camera: Camera, motion: MotionModel):
        self.config = config
        self.camera = camera
        self.motion = motion
        self.blender = PoseBlender(config.blend_frames)
        self.source: str | None = None
        self.last: np.ndarray | None = None

    def lose(self) -> None:
        """Nothing shown this frame: the next pose is shown as it is."""
        self.blender.reset()

    def show(self, pose, pred, source: str, frame: FrameState, lost: int, precise: bool = False,
             seam_from: np.ndarray | None = None) -> np.ndarray:
        """The pose to show for `pose` from `source`: fade the step when the source changes; a switch to
        precise anchors, or precise anchors arriving during a fade, fades over `precise_blend_frames`.
        The step is from where the output would have gone: the last output moved by the predicted motion
        (`pred`), or, given `seam_from`, the old source's own pose this frame (with the fade's offset so
        far). `lost`: frames lost before this one (then nothing is faded)."""
        cfg = self.config
        changed = source != self.source
        self.source = source
        # after lost frames nothing was shown: the new pose is taken as it is, not faded from a stale one;
        # nor is it faded while the velocity rests on a single frame difference (just started: a first pose
        # off by centimetres makes the predicted target as far off as the step it is meant to hide)
        if self.last is not None and pred is not None and lost == 0 and changed and self.motion.steps >= 2:
            # where the output would have gone: the last output moved by the predicted camera motion
            if seam_from is None:
                target = self.last @ np.linalg.inv(self.motion.last) @ pred
            else:
                target = np.asarray(seam_from, float) @ self.blender.current_offset()
            if self.view_motion(pred, frame) >= cfg.smear_px:
                # a fast pan hides a step of a few pixels; fading it would keep the old error for frames
                self.blender.switch(pose, target, cfg.fast_blend_frames, at_once=True)
            else:
                # onto precise anchors the fade starts on this very frame: they are the better pose
                self.blender.switch(pose, target, cfg.precise_blend_frames if precise else None, at_once=precise)
        elif precise:
            # the same source turned precise mid-fade (a board coming back into view after a lone marker
            # carried it): no reason left to keep showing the old offset for long
            self.blender.hurry(cfg.precise_blend_frames)
        self.last = self.blender.apply(pose)
        return self.last

    def view_motion(self, pred: np.ndarray, frame: FrameState) -> float:
        """How far (pixels) the view moved since the last frame: the most of the motion model's (`pred`, the
        motion of five image points, the centre and halfway to each corner, at the depth of the world
        origin) and, when the flow ran this frame, its points' median motion (`Tracks.image_motion`). Not this
        frame's pose: its motion holds the very step a seam is about."""
        followed = frame.followed if frame.flow_ran else None
        moved = None if followed is None else followed[1].image_motion()
        return max(0.0 if moved is None else float(np.linalg.norm(moved)), self.model_motion(pred))

    def model_motion(self, pose: np.ndarray) -> float:
        """Pixels the view moves from `motion.last` to `pose` (see `view_motion`)."""
        w, h = self.camera.size
        px = np.array([[w / 2, h / 2], [w / 4, h / 4], [3 * w / 4, h / 4], [w / 4, 3 * h / 4], [3 * w / 4, 3 * h / 4]])
        last = self.motion.last
        depth = max(float(invert(last)[2, 3]), 0.05)   # the world origin's depth in the camera
        world = self.camera.unproject(px, depth) @ last[:3, :3].T + last[:3, 3]
        return float(np.linalg.norm(self.camera.project_world(world, pose) - px, axis=1).max())
