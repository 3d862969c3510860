"""Live display of a running track: Update Timeline Every Frame and Update 2D View Every Frame.

Tracking runs in a worker thread and changes nothing until its command is
pushed when it ends.  While it runs, the engines publish the samples of each
frame they finish (:meth:`carapost.core.progress.Progress.publish`);
:class:`LivePreview` collects them and the displays read it *in addition to* the
project, as a read-only overlay:

- with **Update Timeline Every Frame** (Tracker settings) the Continuity chart and
  the Selected Point pane colour the frames tracked so far from it;
- with **Update 2D View Every Frame** the current frame follows the track, and the
  camera views and the 3D view draw the tracked points of the frame shown from it.

The worker only stores a reference to each frame's arrays; the GUI thread takes
them at most every :data:`INTERVAL_MS` (so a fast track is drawn at about 20
frames a second, not once per frame), and less often when redrawing takes more
than :data:`BUDGET` of the time.  When the job ends the overlay is cleared:
the pushed command holds the same data by then, and a cancel leaves the project
as it was.  The project is never written here.
"""
from __future__ import annotations

import dataclasses
import threading
import time
import weakref
from types import SimpleNamespace
from typing import Callable

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from ..core.continuity import C_PAD, channel_codes, point_codes
from ..core.points import ST_NONE

#: Shortest time between two redraws of the overlay, in milliseconds.
INTERVAL_MS = 50
#: Largest share of the time the redraws may take: slower displays (big charts, the views' images)
#: are redrawn less often, so that tracking is not slowed down much.
BUDGET = 0.05
#: ... but at least once a second.
MAX_INTERVAL_MS = 1000

_previews: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def of(session) -> "LivePreview":
    """The live preview of ``session`` (created on first use)."""
    lp = _previews.get(session)
    if lp is None:
        lp = _previews[session] = LivePreview(session)
    return lp


def existing(session) -> "LivePreview | None":
    """The session's live preview if one was ever made (displays that only read it)."""
    return _previews.get(session)


class LivePreview(QObject):
    """Per-frame results of the running track, for display only.

    Parameters
    ----------
    session : Session
        Whose project and current frame the preview is shown over.

    Attributes
    ----------
    timeline : bool
        Update Timeline Every Frame was on when the job started.
    views : bool
        Update 2D View Every Frame was on when the job started.
    frames : dict
        ``frame -> payload`` (:func:`carapost.core.progress.frame_payload`) taken so
        far, in tracking order.
    """

    #: The overlay changed (new frames, or cleared); displays redraw.
    changed = Signal()

    def __init__(self, session):
        super().__init__(session)
        self.session = session
        self.timeline = False
        self.views = False
        self.frames: dict[int, dict] = {}
        self.version = 0
        self._lock = threading.Lock()
        self._incoming: dict[int, dict] = {}
        self._last_received: int | None = None
        self._table = None
        self._fd_cache: tuple | None = None
        self._cost_ms: float | None = None        #: smoothed time a refresh takes
        self._paint_s = 0.0                       #: repaint time noted since the last refresh
        self._timer = QTimer(self)
        self._timer.setInterval(INTERVAL_MS)
        self._timer.timeout.connect(self.flush)

    # ------------------------------------------------------------------ job
    def begin(self) -> Callable[[int, dict], None] | None:
        """Arm for a new job from the project's Tracker settings.

        Returns
        -------
        callable or None
            The listener to give the job's Progress; None when both settings
            are off (then nothing is published, so tracking pays nothing).
        """
        self.end()
        p = self.session.project
        if p is None:
            return None
        self.timeline = bool(p.properties["tracker.update_timeline_every_frame"])
        self.views = bool(p.properties["tracker.update_2d_view_every_frame"])
        if not (self.timeline or self.views):
            return None
        self._table = _CodeTable() if self.timeline else None
        self._cost_ms, self._paint_s = None, 0.0
        self._timer.start(INTERVAL_MS)
        return self.receive

    def receive(self, frame: int, payload: dict) -> None:
        """Store one frame's results (called in the worker thread: no Qt, no copying)."""
        with self._lock:
            self._incoming[frame] = payload
            self._last_received = frame

    def flush(self) -> None:
        """Take the frames received since the last call; move the current frame along (timer, GUI thread)."""
        with self._lock:
            new, self._incoming = self._incoming, {}
        if not new:
            return
        t0 = time.perf_counter()
        self.frames.update(new)
        self.version += 1
        if self._table is not None:
            self._table.add(new)
        if self.views and self.session.doc is not None:
            self.session.doc.set_frame(next(reversed(new)))
        self.changed.emit()
        # Redrawing competes with the tracker for the CPU (and the GIL): keep it to a share of the time.
        # The cost of a refresh: this call, and the repaints the last one caused (noted by the displays).
        spent_ms = 1000 * (time.perf_counter() - t0 + self._paint_s)
        self._paint_s = 0.0
        self._cost_ms = spent_ms if self._cost_ms is None else 0.5 * (self._cost_ms + spent_ms)
        self._timer.setInterval(min(max(INTERVAL_MS, int(self._cost_ms / BUDGET)), MAX_INTERVAL_MS))

    def end(self, succeeded: bool = False) -> None:
        """The job ended: drop the overlay (the pushed command, if any, holds the data now).

        With Update 2D View Every Frame and a successful job the current frame
        moves to the last frame tracked.
        """
        self._timer.stop()
        with self._lock:
            self._incoming.clear()
            last, self._last_received = self._last_received, None
        shown = bool(self.frames)
        views, doc = self.views, self.session.doc
        self.frames = {}
        self._table = None
        self._fd_cache = None
        self.timeline = self.views = False
        self.version += 1
        if shown:
            self.changed.emit()
        if views and doc is not None:
            if succeeded and last is not None and last != doc.current_frame:
                doc.set_frame(last)
            elif shown:
                # the frame shown may have been drawn from the overlay: redraw it from the project
                self.session.frameChanged.emit(doc.current_frame)

    def note_paint(self, seconds: float) -> None:
        """A display spent ``seconds`` repainting the overlay (counts towards :data:`BUDGET`)."""
        self._paint_s += seconds

    @property
    def active(self) -> bool:
        """Whether frames are shown from the overlay now."""
        return bool(self.frames)

    # ------------------------------------------------------------- continuity
    def patch_codes(self, codes: np.ndarray, rows, bin_: int, first: int, model) -> None:
        """Put the overlay's continuity codes into a chart's ``codes`` (in place).

        Parameters
        ----------
        codes : ndarray (len(rows), C) uint8
            From :meth:`ContinuityModel.codes <carapost.core.continuity.ContinuityModel.codes>`.
        rows : list of (point id, channel)
        bin_, first : int
            Frames per column and the first frame of column 0.
        model : ContinuityModel
            The project's codes, to re-bin columns that mix tracked and other frames.
        """
        if self.timeline and self._table is not None:
            self._table.patch(codes, rows, bin_, first, model)

    # ------------------------------------------------------------------ views
    def frame_data(self, fd):
        """``fd`` (:class:`~carapost.gui.framedata.FrameData`) with the overlay's samples of its frame.

        Unchanged unless Update 2D View Every Frame is on and the frame was
        tracked; the points' projections use the cameras the track solved.
        """
        if fd is None or not self.views or fd.frame not in self.frames:
            return fd
        key = (self.version, fd.frame, id(fd))
        if self._fd_cache is not None and self._fd_cache[0] == key:
            return self._fd_cache[1]
        pl = self.frames[fd.frame]
        where = {int(pid): i for i, pid in enumerate(fd.ids)}
        rows = [(where[int(pid)], j) for j, pid in enumerate(pl["ids"]) if int(pid) in where]
        out = dataclasses.replace(fd, src=fd.src.copy(), uv=fd.uv.copy(), det=fd.det.copy(), pos=fd.pos.copy(),
                                  has3d=fd.has3d.copy(), proj=fd.proj.copy())
        if rows:
            i, j = (np.array(v, np.int64) for v in zip(*rows))
            out.src[i], out.uv[i] = pl["src"][j], pl["uv"][j]
            if "det" in pl:
                out.det[i] = pl["det"][j]
            if "pos" in pl:
                out.pos[i] = pl["pos"][j]
                out.has3d[i] = (pl["status"][j] != ST_NONE) & np.all(np.isfinite(out.pos[i]), axis=1)
            self._project(out, pl.get("cameras"))
        self._fd_cache = (key, out)
        return out

    def _project(self, fd, cameras) -> None:
        """Projections of ``fd``'s 3D points, with the frame's solved cameras when the track gave them."""
        rig = self.session.project.rig
        fd.proj[:] = np.nan
        if rig is None or not fd.has3d.any():
            return
        X = fd.pos[fd.has3d]
        for s in range(fd.proj.shape[1]):
            cam = rig.camera(s, fd.frame)
            if cameras is not None:
                cam = cam.with_pose(np.asarray(cameras[0][s], float), np.asarray(cameras[1][s], float))
            fd.proj[fd.has3d, s] = cam.project(X)


class _CodeTable:
    """Continuity codes of the frames received so far, grown as frames come in.

    ``codes[0, t, k]`` is the point-bar code of point column ``k`` on the
    ``t``-th frame received, ``codes[1 + s, t, k]`` its channel ``s`` code
    (:data:`~carapost.core.continuity.C_PAD` where a frame said nothing of the point).
    """

    def __init__(self):
        self.col: dict[int, int] = {}          #: point id -> column
        self.frames = np.zeros(0, np.int64)
        self.codes = np.zeros((0, 0, 0), np.uint8)      # (1 + sensors, capacity, points)
        self.n = 0                             #: frames taken
        self._last = (None, None)              #: (ids array, columns) of the last payload
        self._rows = (None,)                   #: the chart rows last patched, and their indices

    def _columns(self, ids) -> np.ndarray:
        last_ids, last_k = self._last
        if last_ids is not None and (ids is last_ids or np.array_equal(ids, last_ids)):
            return last_k
        k = np.fromiter((self.col.setdefault(int(pid), len(self.col)) for pid in ids), np.int64, len(ids))
        self._last = (ids, k)
        return k

    def add(self, frames: dict[int, dict]) -> None:
        """Take new frames (``frame -> payload``, in tracking order)."""
        todo = list(frames.items())
        if not todo:
            return
        ks = [self._columns(pl["ids"]) for _f, pl in todo]
        T, N, S = len(todo), len(self.col), todo[0][1]["src"].shape[1]
        src = np.zeros((T, N, S), np.uint8)
        status = np.full((T, N), ST_NONE, np.uint8)
        score = np.full((T, N, S), np.nan, np.float32)
        known = np.zeros((T, N), bool)
        for t, ((_f, pl), k) in enumerate(zip(todo, ks)):
            src[t, k], status[t, k], score[t, k], known[t, k] = pl["src"], pl["status"], pl["score"], True
        # the core's colour rules on all (frame, point) pairs at once: each pair is one "frame"
        flat = SimpleNamespace(src=src.reshape(T * N, S), status=status.reshape(T * N),
                               score=score.reshape(T * N, S), keyframes={}, frames=T * N, sensors=S)
        new = np.empty((S + 1, T, N), np.uint8)
        new[0] = point_codes(flat).reshape(T, N)
        new[1:] = channel_codes(flat).reshape(S, T, N)
        new[:, ~known] = C_PAD
        self._append(np.array([f for f, _pl in todo], np.int64), new)

    def _append(self, frames: np.ndarray, new: np.ndarray) -> None:
        P, T, N = new.shape
        _p, cap_t, cap_n = self.codes.shape
        if self.n + T > cap_t or N > cap_n:
            grown = np.full((P, max(2 * cap_t, self.n + T, 64), max(N, cap_n)), C_PAD, np.uint8)
            if self.n:
                grown[:, :self.n, :cap_n] = self.codes[:, :self.n]
            self.codes = grown
            self.frames = np.resize(self.frames, grown.shape[1])
        self.codes[:, self.n:self.n + T, :N] = new
        self.frames[self.n:self.n + T] = frames
        self.n += T

    def patch(self, codes: np.ndarray, rows, bin_: int, first: int, model) -> None:
        """See :meth:`LivePreview.patch_codes`."""
        if not self.n:
            return
        key = (tuple(rows), len(self.col))
        if self._rows[0] != key:
            P = self.codes.shape[0]
            sel = [(r, pid, ch) for r, (pid, ch) in enumerate(rows) if pid in self.col and ch + 1 < P]
            self._rows = (key, sel, np.array([r for r, _p, _c in sel], np.int64),
                          np.array([self.col[pid] for _r, pid, _c in sel], np.int64),
                          np.array([ch + 1 for _r, _p, ch in sel], np.int64))
        _key, sel, r_idx, k, plane = self._rows
        if not sel:
            return
        frames = self.frames[:self.n]
        new = self.codes[plane[:, None], np.arange(self.n)[None, :], k[:, None]]      # (rows, frames)
        c = (frames - first) // bin_
        inside = (c >= 0) & (c < codes.shape[1])
        rr, tt = np.nonzero((new != C_PAD) & inside[None, :])
        if not len(rr):
            return
        if bin_ == 1:
            codes[r_idx[rr], c[tt]] = new[rr, tt]
            return
        # Binned columns: re-bin them from the frames' codes with the tracked frames put in, so the
        # most important code of each column still wins (as ContinuityModel's pyramid does).
        c0, c1 = int(c[inside].min()), int(c[inside].max()) + 1
        lo, width = first + c0 * bin_, (c1 - c0) * bin_
        seg = np.full((len(sel), width), C_PAD, np.uint8)
        for i, (_r, pid, ch) in enumerate(sel):
            base = model.row(pid, ch, 0)[lo:lo + width]
            seg[i, :len(base)] = base
        seg[rr, frames[tt] - lo] = new[rr, tt]
        codes[r_idx, c0:c1] = seg.reshape(len(sel), c1 - c0, bin_).min(axis=2)
