"""The headless app model: what the desktop app holds and does, without Qt (as napari's ViewerModel under
its `_qt` layer).

- `session.Session`: source, model, edits, placement, display mode, print preview, print and tracking state,
  with change events (`events.Event`);
- `live.LiveEngine`: the capture (`player`) and processing (`processor`) threads of one open source, steered
  by the `commands` dataclasses, which both GUI engines (threads, child process) apply;
- `print_session.PrintSession`: one print, from the placed solid through slicing and the bed preview to the
  printer job (`printlink`);
- `headless`: a Session driven from a plain thread (tests, scripts).

arapp.gui binds widgets to these; nothing here imports arapp.gui (docs/architecture.md).
"""
