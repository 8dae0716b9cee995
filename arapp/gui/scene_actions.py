"""File menu actions for saved scenes (docs/scene-format.md): open, save, save as, reopen the last one.

The work is the app model's (arapp.app.scene_keeper.SceneKeeper, `window.session.scenes`); this module only
asks for file names and shows what went wrong.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtGui import QAction
from PySide6.QtWidgets import QFileDialog

SCENE_FILTER = "arapp scenes (*.arscene)"


def add_scene_actions(w, file_menu) -> None:
    """Open scene..., Save scene, Save scene as..., Reopen last scene on `file_menu` of MainWindow `w`;
    sets w.reopen_scene_action (disabled when no last scene exists)."""
    keeper = w.session.scenes

    def guarded(fn, title):
        def run(*_):
            try:
                fn()
            except ValueError as exc:   # SceneError and a bad placement: one line in a dialog
                w.show_error(title, str(exc))
        return run

    def open_scene():
        path, _ = QFileDialog.getOpenFileName(w, "Open a scene", str(Path.cwd()), SCENE_FILTER)
        if path:
            keeper.open(path)
            update()

    def save_as():
        path, _ = QFileDialog.getSaveFileName(w, "Save the scene", keeper.path or str(Path.cwd() / "desk.arscene"),
                                              SCENE_FILTER)
        if path:
            keeper.save(path)
            update()

    def save():
        if keeper.path is None:
            save_as()
        else:
            keeper.save()
            update()

    def reopen():
        last = keeper.last()
        if last:
            keeper.open(last)

    def update():
        last = keeper.last()
        w.reopen_scene_action.setEnabled(last is not None)
        w.reopen_scene_action.setText(f"Reopen last scene ({Path(last).name})" if last else "Reopen last scene")

    for text, slot, title in (("Open scene...", open_scene, "Cannot open the scene"),
                              ("Save scene", save, "Cannot save the scene"),
                              ("Save scene as...", save_as, "Cannot save the scene")):
        a = QAction(text, w)
        a.triggered.connect(guarded(slot, title))
        file_menu.addAction(a)
    w.reopen_scene_action = QAction("Reopen last scene", w)
    w.reopen_scene_action.triggered.connect(guarded(reopen, "Cannot open the scene"))
    file_menu.addAction(w.reopen_scene_action)
    update()
