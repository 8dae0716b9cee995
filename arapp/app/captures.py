"""The app model's captures: recording the live source, screenshots, the AR video and the model export.
No Qt.

    captures = Captures(session)
    captures.start_recording()      # the live source into a new recordings/gui-... folder
    captures.save_screenshot()      # the composited view into captures/screenshot-*.png
    captures.start_ar_recording()   # what is on screen into captures/ar-*.mp4
    captures.export_model("part.stl")

The Session exposes these under the same names; failures reach the user through `session.report`.
"""

from __future__ import annotations

from pathlib import Path

from arapp.app.model_export import export_model
from arapp.engine import commands as cmd
from arapp.engine import recording
from arapp.engine.capture import VIDEO_CODECS, new_capture_path, save_screenshot


class Captures:
    """What the session is recording (`recording_folder`, `ar_video_path`) and how it saves what it shows."""

    def __init__(self, session):
        self.session = session
        self.recording_folder: Path | None = None  # the live source being recorded
        self.ar_video_path: Path | None = None  # the AR video being recorded (arapp.engine.capture)

    # -- recording a live source -----------------------------------------------------------
    @property
    def can_record(self) -> bool:
        s = self.session
        return s.engine is not None and s.source_info is not None and not s.source_info.seekable

    def start_recording(self, folder=None):
        """Record the live source into `folder` (default: a new recordings/gui-... folder); None when the
        source is not live."""
        if not self.can_record:
            return None
        folder = Path(folder) if folder is not None else recording.new_recording_folder()
        self.recording_folder = folder
        self.session.send(cmd.RecordStart(str(folder)))
        self.session.status(f"Recording to {folder}", 5000)
        return folder

    def stop_recording(self) -> None:
        self.recording_folder = None
        self.session.send(cmd.RecordStop())

    def recorded(self, folder: str) -> None:
        """The engine saved a recording (a folder, remembered as a recent source) or the AR video (a file)."""
        s = self.session
        if Path(folder).suffix.lower() in VIDEO_CODECS:  # the AR video: a file to watch, not a source
            s.status(f"Saved the AR video {folder}", 8000)
            s.events.recorded.emit(folder)
            return
        s.status(f"Saved the recording {folder}", 8000)
        s.remember("recent_sources", folder)
        s.events.recorded.emit(folder)

    # -- screenshot and AR video ----------------------------------------------------------
    def save_screenshot(self, path=None) -> Path | None:
        """Save the composited view (model over the camera) as an image; default captures/screenshot-*.png.
        None (reported) when nothing is shown or the file cannot be written."""
        s = self.session
        try:
            saved = save_screenshot(s.last_shown, path if path is not None else new_capture_path("screenshot", ".png"))
        except ValueError as exc:
            s.report("Cannot save the screenshot", str(exc))
            return None
        s.status(f"Saved the screenshot {saved}", 8000)
        return saved

    @property
    def can_record_ar(self) -> bool:
        return self.session.engine is not None and self.session.source_info is not None

    def start_ar_recording(self, path=None) -> Path | None:
        """Record what is on screen (camera + model) to a video (.mp4 or .avi; default captures/ar-*.mp4)."""
        if not self.can_record_ar or self.ar_video_path is not None:
            return None
        s = self.session
        path = Path(path) if path is not None else new_capture_path("ar", ".mp4")
        self.ar_video_path = path
        s.send(cmd.ArRecordStart(str(path)))
        s.status(f"Recording the AR view to {path}", 5000)
        s.events.ar_recording_changed.emit(True)
        return path

    def stop_ar_recording(self) -> None:
        if self.ar_video_path is None:
            return
        self.ar_video_path = None
        self.session.send(cmd.ArRecordStop())
        self.session.events.ar_recording_changed.emit(False)

    # -- the model as a file ------------------------------------------------------------------
    def export_model(self, path) -> Path | None:
        """Write the edited model as placed (STL/3MF/OBJ/PLY/GLB, mm) or as NURBS JSON (model units);
        None (reported) on failure."""
        s = self.session
        if s.model is None:
            s.report("Nothing to export", "Open a model first (Model panel or File > Open model)")
            return None
        try:
            saved = export_model(s.model, s.placement, path)
        except (ValueError, OSError) as exc:
            s.report("Cannot export the model", str(exc))
            return None
        s.status(f"Exported {saved}", 8000)
        return saved
