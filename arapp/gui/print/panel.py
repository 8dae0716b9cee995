"""The print dialog as a side panel of the main window: docked on the right beside the AR view (tabbed with
the Model panel, scrollable), so the bed preview it controls stays in sight. It can be floated off like
any dock. Closing the dialog (its window close, Escape) closes the panel; a new print replaces it."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QDockWidget, QScrollArea

MAX_SHARE = 0.45  # of the window's width at most: the AR view keeps the larger part


def show_print_panel(window, dlg) -> QDockWidget:
    """Show PrintDialog `dlg` in a dock of `window` (a MainWindow); its `placement_requested` (scale to
    fit) places the model anew in the session, so the AR view shows the size that is printed."""
    old = getattr(window, "print_dock", None)
    if old is not None:
        old_dlg = getattr(window, "print_dock_dialog", None)
        if old_dlg is not None and old_dlg is not dlg:
            old_dlg.close()  # done(): its bed preview ends with it
        old.close()
        window.removeDockWidget(old)
        old.deleteLater()
    dock = QDockWidget("Print", window)
    dock.setObjectName("dock_print")
    dock.setFeatures(QDockWidget.DockWidgetFeature.DockWidgetMovable
                     | QDockWidget.DockWidgetFeature.DockWidgetFloatable
                     | QDockWidget.DockWidgetFeature.DockWidgetClosable)
    dlg.setWindowFlags(Qt.WindowType.Widget)  # a panel inside the window, no longer a window of its own
    scroll = QScrollArea()
    scroll.setWidgetResizable(True)
    scroll.setFrameShape(QScrollArea.Shape.NoFrame)
    scroll.setWidget(dlg)
    dock.setWidget(scroll)
    dlg.scroll_area = scroll  # the dialog scrolls its Resume offer into sight (a stopped print)
    window.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
    model_dock = window.findChild(QDockWidget, "dock_model")
    if model_dock is not None and window.dockWidgetArea(model_dock) == Qt.DockWidgetArea.RightDockWidgetArea:
        window.tabifyDockWidget(model_dock, dock)
    # as wide as the print widgets want (no sideways scrolling), but never most of the window
    want = max(dlg.sizeHint().width(), dlg.minimumSizeHint().width()) + scroll.verticalScrollBar().sizeHint().width() + 8
    width = int(min(want, MAX_SHARE * window.width()))
    scroll.setMinimumWidth(width)  # resizeDocks does not widen a tabbed dock; its minimum does
    dlg.finished.connect(lambda _r: dock.close())
    dlg.placement_requested.connect(window.session.set_placement)
    dlg.show()
    dock.show()
    dock.raise_()
    window.print_dock, window.print_dock_dialog = dock, dlg
    return dock
