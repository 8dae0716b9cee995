"""The main window's menus and keyboard shortcuts, and its recent-files menus."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QKeySequence

from arapp.gui.scene_actions import add_scene_actions


def _action(window, text: str, slot, shortcut=None, menu=None) -> QAction:
    a = QAction(text, window)
    if shortcut is not None:
        a.setShortcut(QKeySequence(shortcut))
        a.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
    a.triggered.connect(slot)
    window.addAction(a)
    if menu is not None:
        menu.addAction(a)
    return a


def build_menus(w) -> None:
    """File, View and Tracking menus of MainWindow `w`; sets w.print_action, w.play_action,
    w.fullscreen_action, w.reset_action, w.recent_sources_menu, w.recent_models_menu."""
    mb = w.menuBar()
    file_menu = mb.addMenu("&File")
    _action(w, "Open source...", w.choose_source, QKeySequence.StandardKey.Open, file_menu)
    _action(w, "Open recording folder...", w.choose_recording, None, file_menu)
    _action(w, "Open video or photo with calibration...", w.choose_video, None, file_menu)
    _action(w, "Open model...", w.choose_model, "Ctrl+M", file_menu)
    w.recent_sources_menu = file_menu.addMenu("Recent sources")
    w.recent_models_menu = file_menu.addMenu("Recent models")
    file_menu.addSeparator()
    add_scene_actions(w, file_menu)   # saved scenes: open, save, save as, reopen the last one
    file_menu.addSeparator()
    w.print_action = _action(w, "Print...", w.open_print_dialog, "P", file_menu)
    file_menu.addSeparator()
    _action(w, "Quit", w.close, QKeySequence.StandardKey.Quit, file_menu)
    view_menu = mb.addMenu("&View")
    w.play_action = _action(w, "Play / pause", w.toggle_play, "Space", view_menu)
    _action(w, "Step", w.step, ".", view_menu)
    w.fullscreen_action = _action(w, "Full screen", w.toggle_fullscreen, "F", view_menu)
    track_menu = mb.addMenu("&Tracking")
    w.reset_action = _action(w, "Reset tracking", w.session.reset_tracking, "R", track_menu)
    _action(w, "Anchors...", w.edit_anchors, None, track_menu)
    update_recent_menus(w)


def update_recent_menus(w) -> None:
    """Fill the recent sources and models menus from the session's lists."""
    for menu, key, slot in ((w.recent_sources_menu, "recent_sources", w.open_source),
                            (w.recent_models_menu, "recent_models", w.open_model)):
        menu.clear()
        items = w.session.recent(key)
        for item in items:
            a = menu.addAction(item)
            a.triggered.connect(lambda _c=False, x=item, s=slot: s(x))
        menu.setEnabled(bool(items))
