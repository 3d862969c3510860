"""Progress reporting and cancellation for long operations.

Algorithms take a :class:`Progress`; they call :meth:`Progress.step` as they go
and stop with :class:`Cancelled` when the user cancels.  They change nothing in
the project themselves, so a cancel leaves the project untouched.

Frame-by-frame algorithms (tracking) may also hand out what they found on each
frame with :meth:`Progress.publish`, for a live display (the GUI's Update
Timeline / 2D View Every Frame).  Publishing is read-only: the listener gets the
arrays of the frame just done and must not change them.  Algorithms build the
payload only when :attr:`Progress.publishing` is True, so nobody listening costs
nothing.
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
    listener : callable, optional
        ``fn(frame, payload)``: receives :meth:`publish` calls, in the worker thread.
    """

    def __init__(self, total: int = 0, callback: Callable[[int, int, str], None] | None = None,
                 listener: Callable[[int, dict], None] | None = None):
        self.total = int(total)
        self.done = 0
        self.message = ""
        self._cancel = threading.Event()
        self._callback = callback
        self._listener = listener
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

    def listen(self, listener: Callable[[int, dict], None] | None) -> None:
        """Set (None: remove) the receiver of :meth:`publish`."""
        self._listener = listener

    @property
    def publishing(self) -> bool:
        """Whether anyone listens to :meth:`publish` (build no payload otherwise)."""
        return self._listener is not None

    def publish(self, frame: int, payload: dict) -> None:
        """Hand the results of ``frame`` to the listener, if any (read-only; see :func:`frame_payload`)."""
        listener = self._listener
        if listener is not None:
            listener(int(frame), payload)

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    @property
    def fraction(self) -> float:
        return self.done / self.total if self.total else 0.0

    def _emit(self) -> None:
        if self._callback is not None:
            self._callback(self.done, self.total, self.message)


def frame_payload(ids, status, src, uv, score, pos=None, residual=None, det=None, cameras=None) -> dict:
    """The payload of :meth:`Progress.publish`: point-major arrays of one frame.

    Parameters
    ----------
    ids : (N,) int
        The points the rows are about.
    status : (N,) uint8
        ``ST_*`` of each point's 3D sample.
    src : (N, S) uint8
        ``SRC_*`` of each 2D sample.
    uv : (N, S, 2)
        Raw pixels of the 2D samples.
    score : (N, S)
        Match scores.
    pos : (N, 3), optional
        3D positions (NaN without).
    residual, det : optional
        ``(N,)`` RMS reprojection errors, ``(N, S)`` attached detections.
    cameras : tuple, optional
        ``(R, C)``: ``(S, 3, 3)`` rotations and ``(S, 3)`` centres solved for the frame.

    Returns
    -------
    dict
        The arrays by name (those not given are left out).
    """
    out = {"ids": ids, "status": status, "src": src, "uv": uv, "score": score, "pos": pos,
           "residual": residual, "det": det, "cameras": cameras}
    return {k: v for k, v in out.items() if v is not None}


NULL_PROGRESS_FACTORY = Progress
