"""Long operations off the GUI thread, with progress and cancel.

:func:`run_in_background` runs ``fn(progress)`` in a worker thread while the
window keeps repainting; the progress bar under the play controls follows it
and its Cancel button cancels the :class:`~carapost.core.progress.Progress`.
Algorithms do not change the project: they return a command, which is pushed
on the undo stack in the GUI thread when they finish, so a cancel (or an
error) leaves the project untouched.
"""
from __future__ import annotations

import logging
import time
from typing import Callable

from PySide6.QtCore import QObject, QRunnable, QThreadPool, Signal

from ..core.errors import CaraError
from ..core.progress import Cancelled, Progress

log = logging.getLogger("carapost")


class _Signals(QObject):
    progress = Signal(int, int, str)
    finished = Signal(object, object)     # result, exception


class _Job(QRunnable):
    def __init__(self, fn, progress: Progress, signals: _Signals):
        super().__init__()
        self.fn, self.progress, self.signals = fn, progress, signals
        self.setAutoDelete(True)

    def run(self) -> None:
        try:
            result = self.fn(self.progress)
        except BaseException as e:  # noqa: BLE001 - reported in the GUI thread, never lost
            self.signals.finished.emit(None, e)
            return
        self.signals.finished.emit(result, None)


class BackgroundRunner(QObject):
    """Runs one job at a time for a session and drives its progress widgets.

    Parameters
    ----------
    session : Session
        Receives the resulting command; its ``busy`` flag blocks edits meanwhile.
    progress_widget : ProgressPanel, optional
        Shown while a job runs.
    """

    jobFinished = Signal(str, bool)   #: title, succeeded

    def __init__(self, session, progress_widget=None, parent=None):
        super().__init__(parent)
        self.session = session
        self.panel = progress_widget
        self.pool = QThreadPool(self)
        self.pool.setMaxThreadCount(1)
        self._job = None
        if self.panel is not None:
            self.panel.cancelRequested.connect(self.cancel)

    @property
    def running(self) -> bool:
        return self._job is not None

    def run(self, fn: Callable[[Progress], object], title: str, on_done: Callable | None = None,
            cancellable: bool = True, quiet: bool = False, preview=None) -> bool:
        """Start ``fn(progress)``; False when another job is running.

        Parameters
        ----------
        fn : callable
            ``fn(progress) -> Command | None``; runs in a worker thread and must
            not change the project.
        title : str
            Shown beside the progress bar and in the log.
        on_done : callable, optional
            ``on_done(result)`` in the GUI thread after a success (after the
            command, if any, was pushed).
        cancellable : bool
            Show the Cancel button.
        quiet : bool
            Log only failures (autosave).
        preview : LivePreview, optional
            Receives what the job publishes per frame (``progress.publish``)
            while it runs, when the Tracker settings ask for it; cleared when
            the job ends, after its command was pushed.
        """
        if self._job is not None:
            log.warning(f"{title}: wait until {self._job[0]} has finished")
            return False
        signals = _Signals(self)
        listener = preview.begin() if preview is not None else None
        progress = Progress(callback=lambda d, t, m: signals.progress.emit(d, t, m), listener=listener)
        self._job = (title, progress, signals, on_done, quiet, time.perf_counter(), preview)
        signals.finished.connect(self._finished)
        if self.panel is not None:
            signals.progress.connect(self.panel.set_progress)
            self.panel.start(title, cancellable)
        self.session.set_busy(True)
        if not quiet:
            log.info(f"{title}: started")
        self.pool.start(_Job(fn, progress, signals))
        return True

    def cancel(self) -> None:
        """Ask the running job to stop (it stops at its next progress step)."""
        if self._job is not None:
            self._job[1].cancel()
            if self.panel is not None:
                self.panel.set_progress(0, 0, "cancelling…")

    def wait(self, timeout_ms: int = 60000) -> bool:
        """Block until the worker finished (tests, exit); the result is delivered by the event loop."""
        return self.pool.waitForDone(timeout_ms)

    def _finished(self, result, error) -> None:
        title, _progress, signals, on_done, quiet, t0, preview = self._job
        self._job = None
        signals.deleteLater()
        if self.panel is not None:
            self.panel.stop()
        self.session.set_busy(False)
        secs = time.perf_counter() - t0
        ok = False
        if preview is not None and error is not None:
            preview.end(False)          # before any message box: the overlay goes with the failed job
        if isinstance(error, Cancelled):
            log.warning(f"{title}: cancelled; nothing was changed")
        elif isinstance(error, CaraError):
            self.session.error(f"{title}: {error}")
        elif error is not None:
            log.exception(f"{title} failed", exc_info=error)
            self.session.error(f"{title} failed: {type(error).__name__}: {error}")
        else:
            ok = True
            from ..core.commands import Command

            try:
                if isinstance(result, Command):
                    ok = self.session.run(result)
                elif not quiet:
                    log.info(f"{title}: done in {secs:.1f} s")
                if ok and on_done is not None:
                    on_done(result)
            finally:
                if preview is not None:
                    preview.end(ok)
        self.jobFinished.emit(title, ok)


def run_in_background(window, fn: Callable[[Progress], object], title: str, **kwargs) -> bool:
    """Run ``fn(progress) -> Command | None`` off the GUI thread of ``window``; see :meth:`BackgroundRunner.run`."""
    return window.runner.run(fn, title, **kwargs)
