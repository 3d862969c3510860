"""Undoable commands and the one undo stack the GUI, scripts and CLI share.

A command records only what it changes (slices of arrays, single values), so
the history of a long take stays small.  ``do`` is called again on redo; it must
produce the same result each time, so commands capture their inputs (and, when
they compute something, the computed result) at construction or first run.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Callable

import numpy as np


class Command(ABC):
    """One user action: ``do``, ``undo`` and a ``name`` for the History pane."""

    name: str = "Command"

    @abstractmethod
    def do(self, project) -> None:
        """Apply the change to ``project`` (again, on redo)."""

    @abstractmethod
    def undo(self, project) -> None:
        """Restore exactly what :meth:`do` changed."""

    def nbytes(self) -> int:
        """Memory the command keeps for undo/redo (reported by the History pane)."""
        return _nbytes(self.__dict__)


def _nbytes(obj, depth: int = 0) -> int:
    if depth > 6:
        return 0
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, dict):
        return sum(_nbytes(v, depth + 1) for v in obj.values()) + 64 * len(obj)
    if isinstance(obj, (list, tuple)):
        return sum(_nbytes(v, depth + 1) for v in obj) + 8 * len(obj)
    if isinstance(obj, Command):
        return obj.nbytes()
    if hasattr(obj, "arrays") and isinstance(getattr(obj, "arrays"), dict):  # a Point kept for undo
        return sum(a.nbytes for a in obj.arrays.values())
    return 16


class CompoundCommand(Command):
    """Several commands as one history entry (e.g. Merge and Select Next Label)."""

    def __init__(self, name: str, commands: list[Command]):
        self.name = name
        self.commands = list(commands)

    def do(self, project) -> None:
        done = []
        try:
            for c in self.commands:
                c.do(project)
                done.append(c)
        except BaseException:
            for c in reversed(done):
                c.undo(project)
            raise

    def undo(self, project) -> None:
        for c in reversed(self.commands):
            c.undo(project)


class UndoStack:
    """The project's history.

    Parameters
    ----------
    project : Project
        What the commands act on.

    Notes
    -----
    Listeners (``add_listener``) are called as ``fn(event, command)`` with event
    ``"do"``, ``"undo"``, ``"redo"`` or ``"clear"`` after the change; the GUI
    refreshes from them.  A command that raises in ``do`` leaves the project as it
    was (commands restore what they changed) and is not pushed.
    """

    def __init__(self, project):
        self.project = project
        self._commands: list[Command] = []
        self._index = 0          # commands[:index] are done
        self._clean_index = 0    # index at the last save
        self._listeners: list[Callable] = []

    # ----------------------------------------------------------------- edits
    def push(self, command: Command) -> Command:
        """Run ``command`` and make it the newest history entry (discarding redo entries)."""
        command.do(self.project)
        del self._commands[self._index:]
        if self._clean_index > self._index:
            self._clean_index = -1  # the saved state can no longer be reached
        self._commands.append(command)
        self._index += 1
        self._notify("do", command)
        return command

    def undo(self) -> Command | None:
        """Undo the newest done command; ``None`` when there is nothing to undo."""
        if self._index == 0:
            return None
        self._index -= 1
        cmd = self._commands[self._index]
        cmd.undo(self.project)
        self._notify("undo", cmd)
        return cmd

    def redo(self) -> Command | None:
        """Redo the oldest undone command; ``None`` when there is nothing to redo."""
        if self._index >= len(self._commands):
            return None
        cmd = self._commands[self._index]
        cmd.do(self.project)
        self._index += 1
        self._notify("redo", cmd)
        return cmd

    def set_index(self, index: int) -> None:
        """Undo or redo until ``index`` commands are done (History pane click)."""
        index = max(0, min(len(self._commands), index))
        while self._index > index:
            self.undo()
        while self._index < index:
            self.redo()

    def clear(self) -> None:
        """Forget the history (Edit > Clear History) to free memory."""
        self._commands.clear()
        self._clean_index = 0 if self._clean_index == self._index else -1
        self._index = 0
        self._notify("clear", None)

    # ----------------------------------------------------------------- state
    @property
    def index(self) -> int:
        return self._index

    def __len__(self) -> int:
        return len(self._commands)

    def names(self) -> list[str]:
        """Names of every entry, oldest first (entries at ``index`` and after are undone)."""
        return [c.name for c in self._commands]

    def can_undo(self) -> bool:
        return self._index > 0

    def can_redo(self) -> bool:
        return self._index < len(self._commands)

    def undo_name(self) -> str:
        return self._commands[self._index - 1].name if self.can_undo() else ""

    def redo_name(self) -> str:
        return self._commands[self._index].name if self.can_redo() else ""

    def memory_bytes(self) -> int:
        """Memory the history keeps."""
        return sum(c.nbytes() for c in self._commands)

    def mark_clean(self) -> None:
        """Record that the project was saved in its current state."""
        self._clean_index = self._index

    def is_clean(self) -> bool:
        """No change since the last save."""
        return self._clean_index == self._index

    def add_listener(self, fn: Callable) -> None:
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    def _notify(self, event: str, cmd: Command | None) -> None:
        for fn in list(self._listeners):
            fn(event, cmd)
