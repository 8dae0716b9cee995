"""The desktop app (PySide6): live view, replay, models, tracking, printing. All Qt code of arapp lives here.

Entry point: `arapp.gui.app.run_gui` (what `arapp gui` and plain `arapp` call).
"""

from arapp.gui.refcount_guard import immortalize_singletons as _immortalize

_immortalize()  # PySide6 6.12.0 on Python 3.11 leaks references to None/True: see refcount_guard
