"""The headless app model: what the desktop app holds and does, without Qt (as napari's ViewerModel under
its `_qt` layer).

- `session.Session`: source, model, edits, placement, display mode, print preview, print and tracking state,
  with change events (arapp.engine.events.Event); it steers the live engine (arapp.engine.live) only through
  arapp.engine.commands;
- one session per workflow: `print_session.PrintSession` (one print, from the placed solid through slicing
  and the bed preview to the printer job, `printlink`), `scan_session.ScanSession`,
  `calibration_session.CalibrationSession` (the calibration wizard's steps);
- the small sub-models the window shows: `history` (undo), `window_state`, `overlay_marks`, `orbit`,
  `paint_stats`, `first_picture`, `guidance` (words for a user who sees no model).

Imports the engine and the layers below it; nothing here imports arapp.gui (docs/architecture.md).
"""
