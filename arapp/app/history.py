"""Undo and redo of the user's edits to the shown model: control-point edits and placement. No Qt.

`History` watches a `Session`'s events and keeps snapshots of what the user
can change on a loaded model: the control-point edits ((surface, i, j) ->
((x, y, z) in model units, weight)) and the `Placement` (mm, degrees). Each
change the session announces (`placement_changed`, `model_edited`) pushes the
state before it onto the undo stack; a drag of the model counts as one step.
`undo()` / `redo()` put a snapshot back through the session (edits are
re-tessellated by its runner, the placement is sent to the engine). Loading a
model starts a fresh history.
"""

from __future__ import annotations

from dataclasses import dataclass

from arapp.engine.events import Events

MAX_STEPS = 200  # snapshots are small (a dict of edits and a placement); past this the oldest go


@dataclass(frozen=True)
class Snapshot:
    """What undo restores: the control-point edits and the placement (arapp.geometry.placement.Placement)."""

    edits: tuple  # sorted ((surface, i, j), ((x, y, z), weight)) pairs
    placement: object

    @classmethod
    def of(cls, session) -> "Snapshot":
        return cls(tuple(sorted(session.edits.items())), session.placement)


class History:
    """The undo and redo stacks of one session. Event `changed()` fires when either stack changes
    (the GUI enables its Undo and Redo actions from `can_undo` / `can_redo`)."""

    def __init__(self, session):
        self.session = session
        self.events = Events("changed")
        self.undo_stack: list[Snapshot] = []
        self.redo_stack: list[Snapshot] = []
        self.current: Snapshot | None = None
        self._restoring = False
        self._drag_pushed = None  # the drag (session._drag tuple) whose start is already on the stack
        ev = session.events
        ev.model_loaded.connect(self._loaded)
        ev.placement_changed.connect(lambda _p: self._changed())
        ev.model_edited.connect(lambda _m: self._changed())

    @property
    def can_undo(self) -> bool:
        return bool(self.undo_stack)

    @property
    def can_redo(self) -> bool:
        return bool(self.redo_stack)

    def _loaded(self, *_args) -> None:
        self.undo_stack.clear()
        self.redo_stack.clear()
        self.current = Snapshot.of(self.session)
        self.events.changed.emit()

    def _changed(self) -> None:
        if self.session.model is None:
            return
        now = Snapshot.of(self.session)
        if self._restoring or self.current is None:
            self.current = now
            return
        if now == self.current:
            return  # an event that changed nothing (a failed edit sends the fields back)
        drag = getattr(self.session, "_drag", None)
        if drag is not None and drag is self._drag_pushed:
            self.current = now  # the same drag goes on: one step in all
            return
        self._drag_pushed = drag
        self.undo_stack.append(self.current)
        del self.undo_stack[:-MAX_STEPS]
        self.redo_stack.clear()
        self.current = now
        self.events.changed.emit()

    def undo(self) -> bool:
        """Go back one step; False when there is none."""
        return self._move(self.undo_stack, self.redo_stack)

    def redo(self) -> bool:
        """Redo the step undone last; False when there is none."""
        return self._move(self.redo_stack, self.undo_stack)

    def _move(self, source: list, target: list) -> bool:
        if not source or self.session.model is None:
            return False
        snap = source.pop()
        target.append(self.current if self.current is not None else Snapshot.of(self.session))
        self._restore(snap)
        self.events.changed.emit()
        return True

    def _restore(self, snap: Snapshot) -> None:
        s = self.session
        self._restoring = True
        try:
            self.current = snap
            edits = dict(snap.edits)
            if edits != s.edits:
                s.edits = edits
                s._edit.send((s.base_model, dict(edits)))  # re-tessellated; model_edited follows
            if snap.placement != s.placement:
                s.set_placement(snap.placement)
        finally:
            self._restoring = False
