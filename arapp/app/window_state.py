"""What the main window shows about the session, decided without Qt: its title and which controls can act.

`window_title(session)` names the source, the model and the print state;
`control_state(session)` says, per control, whether it can act now (the GUI
enables and disables its widgets from it after each session event).
"""

from __future__ import annotations

from pathlib import Path

APP_NAME = "arapp"


def print_state(session) -> str:
    """'printing 34 %', 'print paused', 'sliced', ... for the print of `session`; '' when there is none."""
    ps = getattr(session, "print_session", None)
    if ps is None:
        return ""
    if getattr(ps, "printing", False):
        progress = getattr(ps, "last_progress", None)
        pct = getattr(progress, "percent", None)
        return f"printing {pct:.0f} %" if pct is not None else "printing"
    if getattr(ps, "result", None) is not None:
        return "sliced"
    return ""


def window_title(session) -> str:
    """'source - model - print state - arapp', leaving out what is not there."""
    parts = []
    if session.source_spec:
        info = session.source_info
        parts.append(info.name if info is not None else Path(str(session.source_spec)).name)
    if session.model is not None:
        name = getattr(session.model, "name", "") or (Path(session.model_path).stem if session.model_path else "")
        edited = " (edited)" if session.edits else ""
        parts.append(f"{name}{edited}")
    state = print_state(session)
    if state:
        parts.append(state)
    if getattr(session, "ar_video_path", None) is not None:
        parts.append("recording AR video")
    parts.append(APP_NAME)
    return " \u2014 ".join(parts)


def control_state(session) -> dict[str, bool]:
    """Per control, whether it can act now:

    play/step/reset/screenshot/record_ar need an open source; record a live
    one; print/export/placement/undo need a model (undo/redo a step to go to).
    """
    source = session.engine is not None and session.source_info is not None
    model = session.model is not None
    history = getattr(session, "history", None)
    seekable = source and bool(session.source_info.seekable)
    return {
        "play": source,
        "step": seekable,
        "seek": seekable,
        "record": bool(session.can_record),
        "record_ar": source,
        "reset": source,
        "screenshot": source and session.last_shown is not None,
        "print": model,
        "export": model,
        "placement": model,
        "undo": model and history is not None and history.can_undo,
        "redo": model and history is not None and history.can_redo,
    }
