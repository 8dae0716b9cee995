"""Camera sources, calibration, anchors, SLAM and evaluation. No Qt, no rendering.

Conventions: metres, seconds, radians. Poses are 4x4 `world_from_camera`
matrices with OpenCV's camera frame (x right, y down, z forward).
"""

# TEMPORARY (issue 28 merge): tracking/tracker.py (split by the `fusion` step) still says
# `from tracking.recording.schema import AnchorSpec`; running house_rewrite.py over the merged tree rewrites it.
# Until then `tracking.recording.schema` resolves to tracking.recording.schema. Delete this block after that run.
import importlib as _importlib
import importlib.abc as _abc
import importlib.util as _util
import sys as _sys


class _MovedModule(_abc.MetaPathFinder, _abc.Loader):
    MOVED = {"tracking." + "session": "tracking.recording.schema"}  # split: house_rewrite.py leaves it

    def find_spec(self, name, path=None, target=None):
        return _util.spec_from_loader(name, self) if name in self.MOVED else None

    def create_module(self, spec):
        return _importlib.import_module(self.MOVED[spec.name])

    def exec_module(self, module):
        pass


_sys.meta_path.append(_MovedModule())
