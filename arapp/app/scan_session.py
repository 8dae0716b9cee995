"""Scan mode of the app: capture views around an object on the marker board, then reconstruct it. No Qt.

While scanning, every processed frame is offered to `ScanSession.offer`. Its
camera direction, seen from the board centre, falls into one cell of a
hemisphere of view directions (`Hemisphere`: rings of elevation bands split
into azimuth cells, 40 cells by default). A frame is captured when the
markers placed it (tracking state "marker"), it is sharp (variance of the
Laplacian at least half the median of the recent frames', the rule the scan
pipeline's view selection uses), it looks at the board centre, and its cell
is new, or the cell holds fewer than `per_cell` views all at least
`min_sep_deg` away (dense matching needs neighbours 6 to 25 degrees apart,
more than one view per 30-degree cell gives it them). A cell is covered once
it holds a view; `next_hint` names the nearest empty cell.

Frames (metres, world = the first anchor's frame): `BoardFrame` from
arapp.scan.fusion: `e1`, `e2` in the paper, `up` out of the printed side.
Azimuth is measured in the paper from `e1` toward `e2` (counter-clockwise
seen from above), elevation from the paper toward `up`, both in degrees, of
the direction from the board centre (on the paper) to the camera centre.

`reconstruct` runs arapp.scan.pipeline.scan on the captured frames through
the app's runner (a worker thread in the GUI) with progress and a cancel
event; the mesh (world frame, metres) is expressed in the placement frame
(millimetres) with a placement that maps it back onto itself, written as a
PLY file and loaded as the session's model, so it is drawn exactly over the
real object and is then placed, exported, sliced and printed like any model.

`dome_drawing` gives what the GUI draws over the frame: each cell's outline
projected with the camera (cv2.projectPoints through Camera.project), filled
or not, and the hint's arrow, in the frame's pixels.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from arapp.engine.editing import model_mesh
from arapp.engine.events import Events
from arapp.engine.pipeline import load_display_model
from arapp.geometry.placement import Placement, world_from_placement
from tracking.sources.base import Frame

# (elevation from, to (degrees), azimuth cells): 12 + 12 + 9 + 6 + 1 = 40 cells of roughly equal solid angle
RINGS = ((0.0, 20.0, 12), (20.0, 40.0, 12), (40.0, 60.0, 9), (60.0, 80.0, 6), (80.0, 90.0, 1))


def direction(az_deg, el_deg) -> np.ndarray:
    """Unit vector(s) (..., 3) in board coordinates (e1, e2, up) for azimuth/elevation in degrees."""
    az, el = np.radians(np.asarray(az_deg, float)), np.radians(np.asarray(el_deg, float))
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


class Hemisphere:
    """Cells of view directions over the paper: ring r spans elevations [lo, hi) degrees and is cut into
    n azimuth cells, the first starting at azimuth 0 (along e1). Cell ids run ring by ring."""

    def __init__(self, rings=RINGS):
        self.rings = tuple((float(lo), float(hi), int(n)) for lo, hi, n in rings)
        self.first = np.cumsum([0] + [n for _, _, n in self.rings])
        cells = []
        for lo, hi, n in self.rings:
            for k in range(n):
                cells.append((lo, hi, 360.0 * k / n, 360.0 * (k + 1) / n))
        self.cells = np.array(cells)  # (N, 4): el_lo, el_hi, az_lo, az_hi (degrees)

    def __len__(self) -> int:
        return len(self.cells)

    def cell_of(self, az_deg: float, el_deg: float) -> int | None:
        """The cell holding this direction; None below the paper (elevation < 0)."""
        if not el_deg >= 0.0:
            return None
        el = min(float(el_deg), 90.0)
        az = float(az_deg) % 360.0
        for r, (lo, hi, n) in enumerate(self.rings):
            if lo <= el < hi or (r == len(self.rings) - 1 and el <= hi):
                return int(self.first[r] + min(n - 1, int(az / (360.0 / n))))
        return None

    def centre(self, cell: int) -> tuple[float, float]:
        """(azimuth, elevation) degrees of the cell's centre (the top cap's centre is the zenith)."""
        el_lo, el_hi, az_lo, az_hi = self.cells[cell]
        if az_hi - az_lo >= 360.0:
            return 0.0, 90.0
        return (az_lo + az_hi) / 2.0, (el_lo + el_hi) / 2.0

    def outline(self, cell: int, steps: int = 4) -> np.ndarray:
        """(M, 2) azimuth, elevation degrees around the cell's border (a ring for the top cap)."""
        el_lo, el_hi, az_lo, az_hi = self.cells[cell]
        if az_hi - az_lo >= 360.0:
            az = np.linspace(0.0, 360.0, 4 * steps * 3, endpoint=False)
            return np.column_stack([az, np.full_like(az, el_lo)])
        a = np.linspace(az_lo, az_hi, steps + 1)
        return np.concatenate([np.column_stack([a, np.full_like(a, el_lo)]),
                               np.column_stack([a[::-1], np.full_like(a, el_hi)])])


@dataclass
class CapturedView:
    """One captured frame: index and time in the source, the BGR image as captured, its pose
    (4x4 world_from_camera, metres), sharpness (variance of the Laplacian, half-scale grey) and cell."""

    index: int
    t: float
    image: np.ndarray
    pose: np.ndarray
    sharpness: float
    cell: int
    dir: np.ndarray  # unit direction board centre -> camera, board coordinates


@dataclass
class Hint:
    """Where to go next: the nearest empty cell, its centre (degrees), the turn from the current direction
    (azimuth change, positive = counter-clockwise seen from above; elevation change, positive = higher)
    and a sentence for the user."""

    cell: int
    azimuth_deg: float
    elevation_deg: float
    turn_deg: float
    climb_deg: float
    text: str


@dataclass
class DomeDrawing:
    """The dome as seen in one frame, in that frame's pixels (u right, v down, pixel centres at integers):
    per cell an (M, 2) polygon or None where any corner is behind the camera, whether it is covered, whether
    its outside faces the camera (the near side of the dome; the far side shows through it); the hint's
    arrow (from, to) or None; the text for the user."""

    polygons: list
    covered: list
    arrow: tuple | None
    text: str
    facing: list = field(default_factory=list)


@dataclass
class ScanSettings:
    """per_cell: views kept per cell at most; min_sep_deg: least angle between views of one cell;
    sharp_ratio: sharpness at least this times the recent frames' median; history: frames in that median;
    max_off_axis_deg: the board centre within this angle of the optical axis; max_views, refine, voxel:
    the pipeline's ScanOptions (voxel None: object extent / 90)."""

    per_cell: int = 3
    min_sep_deg: float = 8.0
    sharp_ratio: float = 0.5
    history: int = 15
    max_off_axis_deg: float = 30.0
    max_views: int = 20
    refine: bool = True
    voxel: float | None = None


class CapturedFrames:
    """The captured frames as a source for arapp.scan.pipeline.scan (recording order, a camera's K)."""

    live = False
    error = None

    def __init__(self, views: list[CapturedView], camera):
        self.camera = camera
        self._frames = [Frame(v.index, v.t, v.image) for v in sorted(views, key=lambda v: (v.t, v.index))]
        self.frame_count = len(self._frames)

    def __iter__(self):
        return iter(self._frames)


def registered_placement(mesh_mm_bounds: np.ndarray) -> Placement:
    """The placement under which a mesh given in the placement frame (mm, these (2, 3) bounds) stays where
    it is: Model.placement_matrix centres x, y, puts the lowest z at 0 and scales the largest extent to
    size_mm; this undoes each (offset = the box's x, y centre and lowest z; size = its largest extent)."""
    lo, hi = np.asarray(mesh_mm_bounds, float)
    return Placement(float(np.max(hi - lo)), ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]), (0.0, 0.0, 0.0))


def sharpness_of(image: np.ndarray) -> float:
    """Variance of the Laplacian of the half-scale grey image (grey levels squared): cheap per frame."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    small = cv2.resize(gray, (max(1, gray.shape[1] // 2), max(1, gray.shape[0] // 2)), interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(small, cv2.CV_32F).var())


class ScanSession:
    """Scan mode over an app `Session`: coverage, captures, reconstruction, the result as the model.

    Events (on the session's thread): changed() (coverage or state), progress(stage, done, total),
    finished(model, stats), failed(message). `state`: "idle", "scanning", "reconstructing", "done".
    """

    def __init__(self, session, settings: ScanSettings | None = None, work_dir=None, hemisphere=None):
        self.session = session
        self.settings = settings or ScanSettings()
        self.work_dir = Path(work_dir) if work_dir is not None else Path.cwd() / "scans"
        self.hemi = hemisphere or Hemisphere()
        self.events = Events("changed", "progress", "finished", "failed")
        self.state = "idle"
        self.views: list[CapturedView] = []
        self.counts = np.zeros(len(self.hemi), int)
        self.frame = None     # BoardFrame of the first anchor
        self.centre = None    # board centre on the paper, world metres
        self.radius = 0.1     # drawn dome radius, metres
        self.camera = None
        self.anchors = None
        self.last_pose = None
        self.last_stage = ""
        self.result_path: Path | None = None
        self.stats: dict = {}
        self._sharp = deque(maxlen=self.settings.history)
        self._job = None
        self._cancel: threading.Event | None = None
        session.events.frame.connect(self._frame)

    # -- geometry ------------------------------------------------------------------------
    def set_board(self, camera, anchors) -> None:
        """The camera (tracking.camera.Camera) and anchors (AnchorSpec list) of the source being scanned."""
        from arapp.scan.fusion import board_frame  # arapp.scan (scipy.ndimage, trimesh): loaded when scanning

        self.camera, self.anchors = camera, list(anchors)
        self.frame = board_frame(self.anchors)
        c = self.frame.outline.mean(axis=0)
        self.centre = self.frame.to_world(np.array([[c[0], c[1], 0.0]]))[0]
        ext = self.frame.outline.max(axis=0) - self.frame.outline.min(axis=0)
        self.radius = 0.5 * float(np.min(ext))

    def angles(self, pose: np.ndarray) -> tuple[float, float]:
        """(azimuth, elevation) degrees of the camera centre seen from the board centre (module doc)."""
        d = self.frame.to_local(np.asarray(pose, float)[:3, 3][None])[0] - self.frame.to_local(self.centre[None])[0]
        d /= np.linalg.norm(d)
        return float(np.degrees(np.arctan2(d[1], d[0])) % 360.0), float(np.degrees(np.arcsin(np.clip(d[2], -1, 1))))

    def _local_dir(self, pose) -> np.ndarray:
        az, el = self.angles(pose)
        return direction(az, el)

    # -- scanning ------------------------------------------------------------------------
    @property
    def scanning(self) -> bool:
        return self.state == "scanning"

    def start(self) -> bool:
        """Start capturing on the open source (False, reported, when there is none yet)."""
        info = self.session.source_info
        if info is None or info.camera is None or not info.anchors:
            self.session.report("Cannot scan", "Open a recording or a camera that sees the marker board first")
            return False
        self.set_board(info.camera, info.anchors)
        self.reset()
        self.state = "scanning"
        self.events.changed.emit()
        return True

    def reset(self) -> None:
        self.views.clear()
        self.counts[:] = 0
        self._sharp.clear()
        self.last_pose = None

    def stop(self) -> None:
        """Leave scan mode (a running reconstruction is cancelled); the captured views are dropped."""
        self.cancel()
        self.state = "idle"
        self.reset()
        self.events.changed.emit()

    @property
    def coverage(self) -> float:
        """Fraction of the hemisphere's cells holding at least one view."""
        return float(np.count_nonzero(self.counts)) / len(self.hemi)

    def _frame(self, shown) -> None:
        if self.state not in ("scanning", "done"):  # after a reconstruction: capture on, then reconstruct again
            return
        r = shown.result
        self.offer(shown.frame, r.world_from_camera, r.state, r.index, r.t)

    def offer(self, image, pose, state: str, index: int = 0, t: float = 0.0) -> bool:
        """A processed frame (BGR image as captured, or None; its pose; the tracking state): captured or not
        by the rule of the module doc. Returns whether it was captured."""
        if self.state not in ("scanning", "done") or pose is None:
            return False
        pose = np.asarray(pose, float)
        self.last_pose = pose
        if state != "marker" or image is None:
            self.events.changed.emit()  # the hint follows the camera
            return False
        s = sharpness_of(image)
        self._sharp.append(s)
        captured = self._accept(image, pose, s, index, t)
        self.events.changed.emit()
        return captured

    def _accept(self, image, pose, s, index, t) -> bool:
        st = self.settings
        if s < st.sharp_ratio * float(np.median(self._sharp)):
            return False
        to_centre = self.centre - pose[:3, 3]
        off = np.degrees(np.arccos(np.clip(pose[:3, 2] @ to_centre / np.linalg.norm(to_centre), -1, 1)))
        if off > st.max_off_axis_deg:
            return False
        az, el = self.angles(pose)
        cell = self.hemi.cell_of(az, el)
        if cell is None or self.counts[cell] >= st.per_cell:
            return False
        d = direction(az, el)
        for v in self.views:
            if v.cell == cell and np.degrees(np.arccos(np.clip(d @ v.dir, -1, 1))) < st.min_sep_deg:
                return False
        self.views.append(CapturedView(int(index), float(t), np.array(image, copy=True), pose.copy(), s, cell, d))
        self.counts[cell] += 1
        return True

    def next_hint(self, pose=None) -> Hint | None:
        """The empty cell nearest (by angle) to the camera's direction (`pose`, default the last one); None
        when every cell is covered or there is no pose."""
        pose = self.last_pose if pose is None else pose
        empty = np.nonzero(self.counts == 0)[0]
        if pose is None or len(empty) == 0 or self.frame is None:
            return None
        az, el = self.angles(pose)
        d = direction(az, el)
        centres = np.array([self.hemi.centre(c) for c in empty])
        dirs = direction(centres[:, 0], centres[:, 1])
        k = int(np.argmax(dirs @ d))
        caz, cel = centres[k]
        turn = float((caz - az + 180.0) % 360.0 - 180.0) if cel < 90.0 else 0.0
        climb = float(cel - el)
        parts = []
        if abs(turn) >= 5.0:
            parts.append(f"{abs(turn):.0f}° {'counter-clockwise' if turn > 0 else 'clockwise'} around the object")
        if abs(climb) >= 5.0:
            parts.append(f"{abs(climb):.0f}° {'higher' if climb > 0 else 'lower'}")
        text = "Move " + " and ".join(parts) if parts else "Hold still here"
        return Hint(int(empty[k]), float(caz), float(cel), turn, climb, text)

    def dome_drawing(self, pose=None, camera=None) -> DomeDrawing | None:
        """The dome and the hint projected into the frame seen from `pose` (default: the last)."""
        pose = self.last_pose if pose is None else pose
        camera = camera or self.camera
        if pose is None or camera is None or self.frame is None:
            return None
        cam_from_world = np.linalg.inv(pose)
        polys, facing = [], []
        eye = self.frame.to_local(pose[:3, 3][None])[0] - self.frame.to_local(self.centre[None])[0]
        for c in range(len(self.hemi)):
            polys.append(self._project(self.hemi.outline(c), cam_from_world, camera))
            n = direction(*self.hemi.centre(c))  # the cell's outward normal; its point is radius * n
            facing.append(bool((eye - self.radius * n) @ n > 0))
        hint = self.next_hint(pose)
        arrow = None
        if hint is not None:
            # from the dome point in the camera's own direction toward the empty cell's centre
            az, el = self.angles(pose)
            ends = self._project(np.array([[az, max(el, 0.0)], [hint.azimuth_deg, hint.elevation_deg]]),
                                 cam_from_world, camera)
            if ends is not None:
                arrow = (tuple(ends[0]), tuple(ends[1]))
        text = hint.text if hint is not None else "Every direction is covered: Reconstruct"
        return DomeDrawing(polys, [bool(n) for n in self.counts], arrow, text, facing)

    def _project(self, az_el: np.ndarray, cam_from_world: np.ndarray, camera):
        L = direction(az_el[:, 0], az_el[:, 1]) * self.radius
        X = self.frame.to_world(L + self.frame.to_local(self.centre[None])[0])
        pc = X @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
        if np.any(pc[:, 2] <= 0.01):
            return None
        return camera.project(pc)

    # -- reconstruction ------------------------------------------------------------------
    @property
    def reconstructing(self) -> bool:
        return self.state == "reconstructing"

    def reconstruct(self) -> None:
        """Run the scan pipeline on the captured views through the session's runner (progress, cancel)."""
        if len(self.views) < 3:
            self.session.report("Cannot reconstruct", f"only {len(self.views)} views are captured; circle the "
                                "object until the dome is at least a third full")
            return
        if self.state == "reconstructing":
            return
        self.state = "reconstructing"
        self._cancel = cancel = threading.Event()
        runner = self.session.run
        views, camera, anchors = list(self.views), self.camera, self.anchors
        self.events.changed.emit()

        def progress(stage, done, total):
            runner.post(lambda v: self._progress(cancel, *v), (stage, done, total))

        self._job = runner.run(self._reconstruct_job, views, camera, anchors, progress, cancel,
                               done=lambda r: self._done(cancel, r), failed=lambda e: self._failed(cancel, e),
                               name="arapp-scan")

    def _progress(self, cancel, stage, done, total) -> None:
        if cancel is self._cancel and not cancel.is_set():
            self.last_stage = stage
            self.events.progress.emit(stage, done, total)

    def _reconstruct_job(self, views, camera, anchors, progress, cancel):
        """Worker thread: pipeline -> mesh in the placement frame (mm) -> PLY file -> loaded model."""
        from arapp.scan.pipeline import ScanOptions, scan, write_mesh  # the scan engines: only to reconstruct

        st = self.settings
        t0 = time.perf_counter()
        opts = ScanOptions(max_views=st.max_views, refine=st.refine, voxel=st.voxel)
        result = scan(CapturedFrames(views, camera), camera, anchors, opts, progress=progress, cancel=cancel)
        mm_from_world = np.diag([1000.0, 1000.0, 1000.0, 1.0]) @ np.linalg.inv(world_from_placement(anchors[0]))
        self.work_dir.mkdir(parents=True, exist_ok=True)
        path = self.work_dir / time.strftime("scan-%Y%m%d-%H%M%S.ply")
        write_mesh(result.mesh, path, transform=mm_from_world)
        model = load_display_model(str(path))
        model.placement = registered_placement(model.bounds())
        stats = dict(result.stats, seconds=time.perf_counter() - t0, views_captured=len(views), path=str(path))
        return model, model_mesh(model), str(path), stats

    def _done(self, cancel, r) -> None:
        if cancel is not self._cancel or cancel.is_set():
            return
        model, mesh_lines, path, stats = r
        self.state, self.result_path, self.stats = "done", Path(path), stats
        # the model is the mesh where it was measured: drawn over the real object by the same poses
        self.session.set_model(model, mesh_lines, path)
        self.events.finished.emit(model, stats)
        self.events.changed.emit()

    def _failed(self, cancel, exc) -> None:
        from arapp.scan.views import ScanCancelled  # arapp.scan.views loads the tracker: only after a scan ran

        if cancel is not self._cancel:
            return
        self.state = "scanning"  # the captured views are kept: capture more, try again
        self.events.changed.emit()
        if isinstance(exc, ScanCancelled) or cancel.is_set():
            self.session.status("Reconstruction cancelled", 3000)
            return
        message = str(exc) or type(exc).__name__
        self.events.failed.emit(message)
        self.session.report("Cannot reconstruct the scan", message)

    def cancel(self) -> None:
        """Stop a running reconstruction (the pipeline checks the event between steps); nothing is loaded."""
        if self._cancel is not None and self.state == "reconstructing":
            self._cancel.set()
            self._cancel = None
            self.state = "scanning"
            self.session.status("Reconstruction cancelled", 3000)
            self.events.changed.emit()

    def finish(self) -> None:
        """Leave scan mode keeping the reconstructed model (it stays the session's model)."""
        self.state = "idle"
        self.reset()
        self.events.changed.emit()
