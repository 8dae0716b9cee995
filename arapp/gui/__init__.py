"""The desktop app (PySide6): live view, replay, models, tracking, printing. All Qt code of arapp lives here.

Entry point: `arapp.gui.app.run_gui` (what `arapp gui` and plain `arapp` call).
"""
