"""An open project in a session: the project, its undo stack, selection and current frame.

The GUI, the scripting API and the CLI all hold a :class:`Document`; the GUI
only adapts it (it observes the stack and the selection, it owns no state).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from .commands import Command, UndoStack
from .project import Project


@dataclass
class Selection:
    """What is selected: points (in selection order), detections, sensors, sticks."""

    points: list[int] = field(default_factory=list)
    #: ``(sensor, frame, index)`` of selected detections
    detections: list[tuple[int, int, int]] = field(default_factory=list)
    sensors: list[int] = field(default_factory=list)
    sticks: list[int] = field(default_factory=list)

    def clear(self) -> None:
        self.points.clear()
        self.detections.clear()
        self.sensors.clear()
        self.sticks.clear()

    def is_empty(self) -> bool:
        return not (self.points or self.detections or self.sensors or self.sticks)


class Document:
    """A project being worked on.

    Parameters
    ----------
    project : Project
        The take.
    """

    def __init__(self, project: Project):
        self.project = project
        self.stack = UndoStack(project)
        self.selection = Selection()
        self.current_frame = project.active_range[0]
        #: View > Toggle Show Stabilized: views show stabilised positions (a view setting, not an edit).
        self.show_stabilized = False
        self._listeners: list[Callable[[str], None]] = []
        self.stack.add_listener(lambda event, cmd: self._notify("project"))
        self.stack.add_listener(self._drop_stale_selection)

    # ------------------------------------------------------------------ edits
    def run(self, command: Command) -> Command:
        """Run a command and push it on the history."""
        return self.stack.push(command)

    def undo(self):
        return self.stack.undo()

    def redo(self):
        return self.stack.redo()

    @property
    def modified(self) -> bool:
        return not self.stack.is_clean()

    # ------------------------------------------------------------ navigation
    def set_frame(self, frame: int) -> int:
        """Go to ``frame`` (clamped to the take); returns the frame shown."""
        f = self.project.clamp_frame(frame)
        if f != self.current_frame:
            self.current_frame = f
            self._notify("frame")
        return f

    def set_show_stabilized(self, on: bool) -> None:
        """Show stabilised (True) or raw (False) positions; listeners hear ``"display"``."""
        if bool(on) != self.show_stabilized:
            self.show_stabilized = bool(on)
            self._notify("display")

    def select_points(self, ids, add: bool = False) -> None:
        """Select points (``add``: extend the selection, as Ctrl+click)."""
        if not add:
            self.selection.points.clear()
            self.selection.detections.clear()
        for pid in ids:
            if pid in self.project.points and pid not in self.selection.points:
                self.selection.points.append(pid)
        self._notify("selection")

    def set_selection(self, selection: Selection) -> None:
        self.selection = selection
        self._notify("selection")

    # -------------------------------------------------------------- listening
    def add_listener(self, fn: Callable[[str], None]) -> None:
        """``fn(what)`` with what in ``"project"``, ``"frame"``, ``"selection"``, ``"display"``."""
        self._listeners.append(fn)

    def remove_listener(self, fn) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _notify(self, what: str) -> None:
        for fn in list(self._listeners):
            fn(what)

    def _drop_stale_selection(self, event, cmd) -> None:
        pts = [p for p in self.selection.points if p in self.project.points]
        if pts != self.selection.points:
            self.selection.points[:] = pts
            self._notify("selection")
