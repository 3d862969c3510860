"""Progress reporting and cancellation for long operations.

Algorithms take a :class:`Progress`; they call :meth:`Progress.step` as they go
and stop with :class:`Cancelled` when the user cancels.  They change nothing in
the project themselves, so a cancel leaves the project untouched.
"""
from __future__ import annotations

import threading
from typing import Callable


class Cancelled(Exception):
    """Raised inside an algorithm when its progress object was cancelled."""


class Progress:
    """Progress/cancel object shared between a worker and the GUI or CLI.

    Parameters
    ----------
    total : int
        Number of steps expected.
    callback : callable, optional
        ``fn(done, total, message)``; called from the worker thread.
    """

    def __init__(self, total: int = 0, callback: Callable[[int, int, str], None] | None = None):
        self.total = int(total)
        self.done = 0
        self.message = ""
        self._cancel = threading.Event()
        self._callback = callback
        self._lock = threading.Lock()

    def start(self, total: int, message: str = "") -> None:
        """Begin a (new) stage of ``total`` steps."""
        with self._lock:
            self.total, self.done, self.message = int(total), 0, message
        self._emit()

    def step(self, n: int = 1, message: str | None = None) -> None:
        """Count ``n`` steps done; raise :class:`Cancelled` if cancelled."""
        if self._cancel.is_set():
            raise Cancelled()
        with self._lock:
            self.done += n
            if message is not None:
                self.message = message
        self._emit()

    def check(self) -> None:
        """Raise :class:`Cancelled` if cancelled."""
        if self._cancel.is_set():
            raise Cancelled()

    def cancel(self) -> None:
        """Ask the worker to stop at its next step."""
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    @property
    def fraction(self) -> float:
        return self.done / self.total if self.total else 0.0

    def _emit(self) -> None:
        if self._callback is not None:
            self._callback(self.done, self.total, self.message)


NULL_PROGRESS_FACTORY = Progress
