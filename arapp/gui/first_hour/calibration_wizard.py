"""The camera calibration wizard: print the board, show it to the camera, compute, save and use.

Three pages: (1) the ChArUco board to print at true scale (saved as PDF/PNG);
(2) frames from the source with the board corners found drawn on them, the
image coverage shaded, the tilt bins and the views kept so far; (3) the
solve (in a worker thread, cancellable), the RMS and a verdict, and "Save and
use", which stores the calibration per camera and resolution in the user's
config folder (arapp.store.camera_store) and emits `calibrated(path, camera)`.

The logic is arapp.app.calibration_session (no Qt); this module only shows it.
Frames are read in a worker thread (opening a camera can take seconds);
the view shows the newest frame only, so a fast file never queues images.
"""

from __future__ import annotations

import threading
from typing import Callable

import numpy as np
from tracking.printables import sheet
from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import (
    QDialog,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QStackedWidget,
    QVBoxLayout,
    QWidget,
)

from arapp.store import camera_store
from arapp.app.calibration_session import (TILT_BINS, board_anchor, CalibrationSession, SessionResult, collect_from_source, corners_wanted, describe_board, draw_feedback, write_board_sheet)
from arapp.gui.tasks import Task


def bgr_to_qimage(img: np.ndarray) -> QImage:
    """A QImage owning a copy of a BGR uint8 image."""
    rgb = np.ascontiguousarray(img[..., ::-1]) if img.ndim == 3 else np.ascontiguousarray(img)
    h, w = rgb.shape[:2]
    fmt = QImage.Format.Format_RGB888 if rgb.ndim == 3 else QImage.Format.Format_Grayscale8
    return QImage(rgb.data, w, h, rgb.strides[0], fmt).copy()


def _wrapped(text: str) -> QLabel:
    label = QLabel(text)
    label.setWordWrap(True)
    return label


class _Signals(QObject):
    """Emitted from the reader thread; Qt queues them to the UI thread."""

    frame = Signal()
    finished = Signal(str)  # "" when the source ended or was stopped, else an error message


class CalibrationWizard(QDialog):
    """Calibrate the camera that `opener()` opens (a tracking.sources source). `every`: look at every
    Nth frame. `calibrated(path, camera)` fires after "Save and use"."""

    calibrated = Signal(str, object)

    def __init__(self, opener: Callable[[], object], every: int = 1, session: CalibrationSession | None = None,
                 parent=None):
        super().__init__(parent)
        self.setWindowTitle("Calibrate the camera")
        self.opener, self.every = opener, max(1, int(every))
        self.session = session or CalibrationSession()
        self.camera_name: str | None = None
        self.result: SessionResult | None = None
        self.saved_path: str | None = None
        self.errors: list[str] = []
        self._cancel = threading.Event()
        self._reader: threading.Thread | None = None
        self._latest = None  # (drawn image, feedback, index, total), newest wins
        self._lock = threading.Lock()
        self._signals = _Signals()
        self._signals.frame.connect(self._show_latest)
        self._signals.finished.connect(self._reader_finished)
        self._solve_task: Task | None = None
        self._solve_gen = 0

        self.pages = QStackedWidget()
        self.pages.addWidget(self._board_page())
        self.pages.addWidget(self._collect_page())
        self.pages.addWidget(self._result_page())
        lay = QVBoxLayout(self)
        lay.addWidget(self.pages)
        self.resize(760, 620)

    # -- page 1: the board ------------------------------------------------------------------
    def _board_page(self) -> QWidget:
        page = QWidget()
        lay = QVBoxLayout(page)
        lay.addWidget(_wrapped(f"<b>1. Print the calibration board</b><br>{describe_board(self.session.board)}, "
                               "on an A4 page in landscape. Print at 100 % (no fit-to-page), check the ruler "
                               "measures 100 mm, and glue or tape the sheet flat on something stiff."))
        self.board_preview = QLabel()
        self.board_preview.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.board_preview.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.board_preview.setMinimumSize(200, 150)
        self._set_board_preview()
        lay.addWidget(self.board_preview, 1)
        row = QHBoxLayout()
        self.save_sheet_button = QPushButton("Save the sheet (PDF, PNG)...")
        self.save_sheet_button.clicked.connect(self.choose_sheet_folder)
        self.to_collect_button = QPushButton("I have the board: next")
        self.to_collect_button.setDefault(True)
        self.to_collect_button.clicked.connect(lambda: self.pages.setCurrentIndex(1))
        row.addWidget(self.save_sheet_button)
        row.addStretch(1)
        row.addWidget(self.to_collect_button)
        lay.addLayout(row)
        return page

    def _set_board_preview(self) -> None:
        img, _ = sheet(board_anchor(self.session.board), dpi=50.0, page="A4")
        self.board_preview.setPixmap(QPixmap.fromImage(bgr_to_qimage(img)))

    def choose_sheet_folder(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Save the calibration board to")
        if folder:
            self.save_sheet(folder)

    def save_sheet(self, folder: str) -> list:
        paths = write_board_sheet(folder, self.session.board)
        self.sheet_label_text = "Saved " + ", ".join(p.name for p in paths) + f" in {folder}"
        self.save_sheet_button.setToolTip(self.sheet_label_text)
        return paths

    # -- page 2: collecting views --------------------------------------------------------------
    def _collect_page(self) -> QWidget:
        page = QWidget()
        lay = QVBoxLayout(page)
        lay.addWidget(_wrapped("<b>2. Show the board to the camera</b><br>Hold it still at many places: near each "
                               "edge and corner of the picture, close and far, facing the camera and tilted "
                               "towards each side. Green squares show where views have reached; the image corners "
                               "outlined in orange still need a view (the lens's outer distortion is measured "
                               "there)."))
        self.view = QLabel("Press Start")
        self.view.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.view.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Ignored)
        self.view.setMinimumSize(320, 200)
        lay.addWidget(self.view, 1)
        self.stats = QLabel("")
        self.stats.setWordWrap(True)
        lay.addWidget(self.stats)
        self.progress = QProgressBar()
        self.progress.setFormat("%v / %m views")
        self.progress.setRange(0, self.session.min_views)
        lay.addWidget(self.progress)
        row = QHBoxLayout()
        self.start_button = QPushButton("Start")
        self.start_button.clicked.connect(self.start)
        self.stop_button = QPushButton("Stop")
        self.stop_button.setEnabled(False)
        self.stop_button.clicked.connect(self.stop)
        self.solve_button = QPushButton("Calibrate")
        self.solve_button.setEnabled(False)
        self.solve_button.clicked.connect(self.solve)
        back = QPushButton("Back")
        back.clicked.connect(lambda: self.pages.setCurrentIndex(0))
        row.addWidget(back)
        row.addStretch(1)
        for b in (self.start_button, self.stop_button, self.solve_button):
            row.addWidget(b)
        lay.addLayout(row)
        return page

    @property
    def collecting(self) -> bool:
        return self._reader is not None and self._reader.is_alive()

    def start(self) -> None:
        """Open the source and look at its frames in a worker thread."""
        if self.collecting:
            return
        self.pages.setCurrentIndex(1)
        self._cancel.clear()
        self.start_button.setEnabled(False)
        self.stop_button.setEnabled(True)
        self.view.setText("Opening the camera...")
        self._reader = threading.Thread(target=self._read, name="arapp-calibration-reader", daemon=True)
        self._reader.start()

    def stop(self) -> None:
        """Stop reading frames (the views kept so far stay)."""
        self._cancel.set()

    def _read(self) -> None:
        try:
            source = self.opener()
        except Exception as exc:  # noqa: BLE001 - shown in the wizard, one line
            self._signals.finished.emit(f"cannot open the camera: {exc}")
            return
        try:
            self.camera_name = camera_store.camera_name(source)
            collect_from_source(source, self.session, self.every, self._cancel, self._progress)
            error = getattr(source, "error", None) or ""
        except Exception as exc:  # noqa: BLE001 - a frame the detector or collector refused: say why
            error = str(exc)
        finally:
            source.close()
        self._signals.finished.emit(error)

    def _progress(self, index: int, total: int | None, fb) -> None:
        """Reader thread: keep the newest frame's drawing; wake the UI only if it has shown the last one."""
        with self._lock:
            pending = self._latest is not None
            self._latest = (fb, index, total)
        if not pending:
            self._signals.frame.emit()

    def _show_latest(self) -> None:
        with self._lock:
            latest, self._latest = self._latest, None
        if latest is None:
            return
        fb, index, total = latest
        self._update_stats(fb, index, total)

    def _update_stats(self, fb, index: int, total: int | None) -> None:
        s = self.session
        tilts = "  ".join(f"{'[x]' if s.tilts[b] else '[ ]'} {b}" for b in TILT_BINS)
        where = f"frame {index + 1} of {total}" if total else f"frame {index + 1}"
        missing = s.missing_corners
        wanted = (f"\nStill needed: the board near {corners_wanted(missing)} (outlined in orange)"
                  if missing else "")
        self.stats.setText(f"{where}: {fb.verdict}.  Views kept {fb.kept} (need {s.min_views}); image covered "
                           f"{fb.coverage * 100:.0f} %; tilts {tilts}{wanted}")
        self.progress.setRange(0, max(s.min_views, fb.kept))
        self.progress.setValue(fb.kept)
        self.solve_button.setEnabled(s.ready)
        if fb.image is not None:
            pix = QPixmap.fromImage(bgr_to_qimage(draw_feedback(fb.image, s, fb)))
            self.view.setPixmap(pix.scaled(self.view.size(), Qt.AspectRatioMode.KeepAspectRatio,
                                           Qt.TransformationMode.SmoothTransformation))

    def _reader_finished(self, error: str) -> None:
        self._show_latest()
        self.start_button.setEnabled(True)
        self.start_button.setText("Continue")
        self.stop_button.setEnabled(False)
        self.solve_button.setEnabled(self.session.ready)
        if error:
            self.errors.append(error)
            self.stats.setText(error)
        elif not self.session.ready:
            self.stats.setText(self.stats.text() + f"\nOnly {self.session.kept} views kept; "
                               f"{self.session.min_views} are needed. Press Continue and show the board again.")

    # -- page 3: the result ---------------------------------------------------------------------
    def _result_page(self) -> QWidget:
        page = QWidget()
        lay = QVBoxLayout(page)
        lay.addWidget(QLabel("<b>3. The calibration</b>"))
        self.busy = QProgressBar()
        self.busy.setRange(0, 0)
        lay.addWidget(self.busy)
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.result_label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.result_label.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        lay.addWidget(self.result_label, 1)
        row = QHBoxLayout()
        self.cancel_solve_button = QPushButton("Cancel")
        self.cancel_solve_button.clicked.connect(self.cancel_solve)
        self.more_button = QPushButton("Add more views")
        self.more_button.clicked.connect(lambda: self.pages.setCurrentIndex(1))
        self.save_button = QPushButton("Save and use")
        self.save_button.setEnabled(False)
        self.save_button.clicked.connect(self.save_and_use)
        row.addWidget(self.cancel_solve_button)
        row.addStretch(1)
        row.addWidget(self.more_button)
        row.addWidget(self.save_button)
        lay.addLayout(row)
        return page

    @property
    def solving(self) -> bool:
        return self._solve_task is not None and self._solve_task.running

    def solve(self) -> None:
        """Stop reading and run the calibration in a worker thread (Cancel drops its result)."""
        self.stop()
        if self._reader is not None:
            self._reader.join(5.0)
        self.pages.setCurrentIndex(2)
        self.busy.setVisible(True)
        self.save_button.setEnabled(False)
        self.cancel_solve_button.setEnabled(True)
        self.result_label.setText(f"Computing from {self.session.kept} views...")
        self._solve_gen += 1
        gen = self._solve_gen
        self._solve_task = Task(self.session.solve, done=lambda r, g=gen: self._solved(g, r),
                                failed=lambda e, g=gen: self._solve_failed(g, e), name="arapp-calibrate",
                                owner=self).start()

    def cancel_solve(self) -> None:
        self._solve_gen += 1  # the running solve's result will be dropped
        self.busy.setVisible(False)
        self.result_label.setText("Cancelled.")
        self.pages.setCurrentIndex(1)

    def _solved(self, gen: int, res: SessionResult) -> None:
        if gen != self._solve_gen:
            return
        self.result = res
        self.busy.setVisible(False)
        self.cancel_solve_button.setEnabled(False)
        cam = res.camera
        self.result_label.setText(
            f"<b>{res.quality.capitalize()}</b>: {res.advice}.<br>"
            f"RMS reprojection error {res.rms:.3f} px over {len(res.result.used)} views "
            f"({len(res.result.dropped)} dropped).<br>"
            f"Focal length {cam.fx:.1f} x {cam.fy:.1f} px (+/- {res.result.std.get('fx', 0):.1f}), centre "
            f"({cam.cx:.1f}, {cam.cy:.1f}) px, image {cam.width} x {cam.height}.<br>"
            + "".join(f"{line}.<br>" for line in res.result.report().splitlines()
                      if line.startswith(("projection uncertainty", "k3 held")))
            + f"Camera: {self.camera_name}")
        self.save_button.setEnabled(True)

    def _solve_failed(self, gen: int, exc: BaseException) -> None:
        if gen != self._solve_gen:
            return
        self.busy.setVisible(False)
        self.errors.append(str(exc))
        self.result_label.setText(f"Cannot calibrate: {exc}")

    def save_and_use(self) -> str | None:
        """Store the calibration for this camera and resolution; emits `calibrated`."""
        if self.result is None:
            return None
        path = camera_store.save_camera(self.camera_name or "camera", self.result.camera, self.result.rms,
                                        len(self.result.result.used))
        self.saved_path = str(path)
        self.result_label.setText(self.result_label.text() + f"<br>Saved to {path}; it is used from now on.")
        self.save_button.setEnabled(False)
        self.calibrated.emit(str(path), self.result.camera)
        return self.saved_path

    def closeEvent(self, event):  # noqa: N802
        self._cancel.set()
        self._solve_gen += 1
        if self._reader is not None:
            self._reader.join(2.0)
        super().closeEvent(event)

    def reject(self) -> None:
        self._cancel.set()
        self._solve_gen += 1
        super().reject()
