"""The Help menu's pieces: the keyboard shortcuts (read from the window's own actions, so the list is
always what the keys do) and the About box (version, libraries, where settings and calibrations live)."""

from __future__ import annotations

import platform

import cv2
import numpy as np
import PySide6
from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QHeaderView,
    QMenu,
    QMessageBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from arapp import __version__
from arapp.store.user_config import config_dir

# what the pointer does in the view (not actions, so not in the window's action list)
POINTER_HELP = [
    ("Drag the model", "move it on the marker, under the pointer"),
    ("Shift+drag or right-drag", "turn it"),
    ("Mouse wheel", "scale it"),
]


def shortcuts(window: QWidget) -> list[tuple[str, str]]:
    """(key, what it does) for every action of `window` that has a shortcut, in menu order, plus the
    pointer gestures of the view."""
    out = []
    for action in window.findChildren(QAction):
        seq = action.shortcut()
        if seq.isEmpty() or not action.text():
            continue
        key = seq.toString(QKeySequence.SequenceFormat.NativeText)
        text = action.text().replace("&", "").rstrip(".").strip()
        if (key, text) not in out:
            out.append((key, text))
    return out + POINTER_HELP


class ShortcutsDialog(QDialog):
    """A two-column table: key, action."""

    def __init__(self, rows: list[tuple[str, str]], parent=None):
        super().__init__(parent)
        self.setWindowTitle("Keyboard shortcuts")
        self.table = QTableWidget(len(rows), 2)
        self.table.setHorizontalHeaderLabels(["Key", "Does"])
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        for r, (key, text) in enumerate(rows):
            self.table.setItem(r, 0, QTableWidgetItem(key))
            self.table.setItem(r, 1, QTableWidgetItem(text))
        self.table.horizontalHeader().setSectionResizeMode(1, QHeaderView.ResizeMode.Stretch)
        self.table.resizeColumnToContents(0)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addWidget(self.table)
        lay.addWidget(buttons)
        self.resize(460, 420)


def about_text() -> str:
    """The About box's text (rich text): version, the libraries doing the work, the config folder."""
    return (f"<h3>arapp {__version__}</h3>"
            "<p>Augmented reality on printed markers: track the camera, show a NURBS model on the marker, "
            "edit it, and print it at the size seen.</p>"
            f"<p>OpenCV {cv2.__version__}, NumPy {np.__version__}, Qt for Python {PySide6.__version__}, "
            f"Python {platform.python_version()}</p>"
            f"<p>Settings, camera calibrations and printer keys: <tt>{config_dir()}</tt></p>")


def show_about(parent: QWidget) -> QMessageBox:
    box = QMessageBox(parent)
    box.setWindowTitle("About arapp")
    box.setTextFormat(Qt.TextFormat.RichText)
    box.setText(about_text())
    box.setStandardButtons(QMessageBox.StandardButton.Ok)
    box.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose, True)
    box.open()
    return box


def add_help_menu(window, extra: list[tuple[str, object]] | None = None) -> QMenu:
    """A Help menu on `window`'s menu bar: `extra` (text, slot) entries first, then Keyboard shortcuts
    (F1) and About. Returns the menu."""
    menu = window.menuBar().addMenu("&Help")
    for text, slot in extra or []:
        a = QAction(text, window)
        a.triggered.connect(slot)
        menu.addAction(a)
    if extra:
        menu.addSeparator()
    keys = QAction("Keyboard shortcuts", window)
    keys.setShortcut(QKeySequence("F1"))
    keys.triggered.connect(lambda: ShortcutsDialog(shortcuts(window), window).open())
    window.addAction(keys)
    menu.addAction(keys)
    about = QAction("About arapp", window)
    about.triggered.connect(lambda: show_about(window))
    menu.addAction(about)
    return menu
