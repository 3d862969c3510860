"""The blob commands of the Process and Edit menus, as undoable operations.

- Process > Detect Blobs [Current Frame]  -> :func:`detect_blobs_current_frame`
- Process > Detect Blobs [Active Range]   -> :func:`detect_blobs_range`
- Edit > Remove Unused Detections         -> :func:`remove_unused_detections`
- Edit > Read Blob Parameters From Pico Files -> :func:`read_blob_parameters_from_pico`
- Blob Preview (Ctrl+B)                    -> :func:`blob_preview`

Each operation computes first and returns a command; nothing in the project
changes until the command is run (``UndoStack.push`` or ``cmd.do``), so a
cancelled detection leaves the project untouched.

Re-detecting a frame keeps the points attached to it: each attached
detection is re-attached to the new detection nearest its old centre within
1 px (its ``uv`` and ``det`` follow), else the point is detached from that
sensor on that frame (its 3D position is kept).
"""
from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from contextlib import contextmanager
from typing import Iterable

import numpy as np

from .blobs import blob_settings, detect_with_properties, detect_with_settings
from .commands import Command
from .edits import SetFrameDetections, SetProperties
from .errors import CaraError
from .heap import keep_freed_memory
from .points import SRC_DETECTION, SRC_NONE
from .progress import Progress
from .properties import property_def

BLOB_KEYS = ("blob.white_min_radius", "blob.white_max_radius", "blob.black_min_radius", "blob.black_max_radius",
             "blob.find_black_blobs", "blob.find_white_blobs", "blob.black_threshold", "blob.white_threshold")
#: Re-detected detections within this distance (px) of an attached one keep its points.
REATTACH_PX = 1.0

# ----------------------------------------------------------------- commands
class DetectBlobs(SetFrameDetections):
    """Replace the detections of (sensor, frame) cells and keep points attached.

    ``do`` re-attaches every point attached to a replaced detection to the new
    detection nearest its old centre within :data:`REATTACH_PX`, else detaches
    it; the changed point samples are kept for undo.
    """

    def __init__(self, cells, name: str = "Detect Blobs"):
        super().__init__(cells, name)
        self._points_old: list[tuple[int, int, int, tuple]] = []

    def do(self, project) -> None:
        # Remap before the records change: the old centres are needed.
        changes = []
        for (s, f), rec in self.cells.items():
            old = project.detections[s].frame(f)
            for p in project.points.values():
                if p.src[f, s] != SRC_DETECTION or not 0 <= p.det[f, s] < len(old):
                    continue
                o = old[p.det[f, s]]
                j = -1
                if len(rec):
                    d = np.hypot(rec["x"].astype(np.float64) - o["x"], rec["y"].astype(np.float64) - o["y"])
                    k = int(np.argmin(d))
                    j = k if d[k] <= REATTACH_PX else -1
                changes.append((p.id, f, s, j))
        super().do(project)
        self._points_old = []
        for pid, f, s, j in changes:
            p = project.points[pid]
            self._points_old.append((pid, f, s, (p.src[f, s], p.det[f, s], p.uv[f, s].copy(), p.score[f, s])))
            if j >= 0:
                r = self.cells[(s, f)][j]
                p.det[f, s] = j
                p.uv[f, s] = (r["x"], r["y"])
            else:
                p.src[f, s], p.det[f, s] = SRC_NONE, -1
                p.uv[f, s] = np.nan
                p.score[f, s] = np.nan

    def undo(self, project) -> None:
        for pid, f, s, (src, det, uv, score) in reversed(self._points_old):
            p = project.points[pid]
            p.src[f, s], p.det[f, s], p.uv[f, s], p.score[f, s] = src, det, uv, score
        super().undo(project)


class RemoveUnusedDetections(Command):
    """Delete detections no point is attached to, on every frame and sensor.

    Stores only the frames that change (their old records) and the attached
    ``det`` indices it renumbers.
    """

    name = "Remove Unused Detections"

    def __init__(self):
        self._old_cells: dict[tuple[int, int], tuple[np.ndarray, bool]] = {}
        self._new_cells: dict[tuple[int, int], np.ndarray] = {}
        self._det_old: list[tuple[int, int, np.ndarray, np.ndarray]] = []   # pid, sensor, frames, old det
        self._det_new: list[tuple[int, int, np.ndarray, np.ndarray]] = []

    def do(self, project) -> None:
        if not self._new_cells and not self._old_cells:
            self._plan(project)
        for (s, f), rec in self._new_cells.items():
            project.detections[s].set_frame(f, rec, bool(project.detections[s].detected[f]))
        for pid, s, frames, det in self._det_new:
            project.points[pid].det[frames, s] = det

    def undo(self, project) -> None:
        for pid, s, frames, det in self._det_old:
            project.points[pid].det[frames, s] = det
        for (s, f), (rec, detected) in self._old_cells.items():
            project.detections[s].set_frame(f, rec, detected)

    def _plan(self, project) -> None:
        pts = list(project.points.values())
        for s, table in enumerate(project.detections):
            counts = table.counts()
            frames = np.flatnonzero(counts)
            if len(frames) == 0:
                continue
            if pts:
                D = np.stack([p.det[:, s] for p in pts])                        # (P, F)
                att = np.stack([p.src[:, s] == SRC_DETECTION for p in pts]) & (D >= 0) & (D < counts[None, :])
            else:
                D = att = None
            remap: dict[int, np.ndarray] = {}
            for f in frames.tolist():
                used = np.unique(D[att[:, f], f]) if pts else np.zeros(0, np.int32)
                if len(used) == counts[f]:
                    continue
                old = table.frame(f)
                self._old_cells[(s, f)] = (old.copy(), bool(table.detected[f]))
                self._new_cells[(s, f)] = old[used].copy()
                m = np.full(counts[f], -1, np.int32)
                m[used] = np.arange(len(used), dtype=np.int32)
                remap[f] = m
            if not remap or not pts:
                continue
            for i, p in enumerate(pts):
                fr = np.array([f for f in remap if att[i, f]], np.int64)
                if len(fr) == 0:
                    continue
                old = p.det[fr, s].copy()
                new = np.array([remap[f][d] for f, d in zip(fr.tolist(), old.tolist())], np.int32)
                if np.array_equal(old, new):
                    continue
                self._det_old.append((p.id, s, fr, old))
                self._det_new.append((p.id, s, fr, new))


# --------------------------------------------------------------- operations
def blob_preview(image, properties) -> np.ndarray:
    """What the current Blob Parameters would find in ``image`` (the project is not changed).

    Parameters
    ----------
    image : ndarray
        Grey uint8 image (colour / 16-bit are converted).
    properties : Properties
        ``project.properties``.

    Returns
    -------
    numpy.ndarray
        Detection records.
    """
    return detect_with_properties(image, properties)


def _sensors(project, sensors) -> list[int]:
    out = list(project.selected_channels()) if sensors is None else [int(s) for s in sensors]
    for s in out:
        if not 0 <= s < project.sensor_count:
            raise CaraError(f"no sensor {s} (the take has {project.sensor_count})")
    return out


def _open(project, s, decode_threads: int | None = None):
    from ..io.media import open_source  # io depends on core, not the reverse: import late

    m = project.sensors[s].media
    if not m.path:
        raise CaraError(f"sensor {s} has no media to detect blobs on")
    return open_source(m.path, decode_threads=decode_threads)


def detect_blobs_current_frame(project, frame: int, sensors: Iterable[int] | None = None,
                               images: dict[int, np.ndarray] | None = None) -> DetectBlobs:
    """Process > Detect Blobs [Current Frame].

    Parameters
    ----------
    project : Project
    frame : int
        Take frame.
    sensors : iterable of int, optional
        Default: the explicit channel selection, else every sensor.
    images : dict sensor -> image, optional
        Images already in memory (e.g. the viewer's); others are read from the media.

    Returns
    -------
    DetectBlobs
        The undoable command (not yet run).
    """
    project.check_range(frame, frame)
    cells = {}
    for s in _sensors(project, sensors):
        img = None if images is None else images.get(s)
        if img is None:
            m = frame - project.sensors[s].image_offset
            src = _open(project, s)
            try:
                if not 0 <= m < src.frame_count:
                    continue  # no image on this frame: nothing to detect
                img = src.read(m)
            finally:
                src.close()
        cells[(s, frame)] = detect_with_properties(img, project.properties)
    return DetectBlobs(cells, name="Detect Blobs [Current Frame]")


def default_workers() -> int:
    """Detection threads: every core."""
    return max(1, os.cpu_count() or 1)


@contextmanager
def _one_opencv_thread():
    """OpenCV's own threads off while the pool runs: the pool already uses every core."""
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


def detect_frames(frames: Iterable[tuple[object, np.ndarray]], properties, workers: int | None = None,
                  progress: Progress | None = None) -> dict:
    """Detect blobs on a stream of ``(key, image)`` with a pool of ``workers`` threads.

    Threads, not processes: the detector's compiled kernels, OpenCV and the media
    decoder release the GIL, so two threads detected as many frames per second as two
    processes (~180 frames/s on 2 cores) without the processes' start-up (~2 s of
    spawning, imports and loading the kernels) or copying every frame to them.  At
    most ``2 * workers`` frames are in flight, so a long take streams through memory.
    Returns ``{key: records}``; raises :class:`Cancelled` (pending frames are
    dropped).  The C heap is first told to keep freed memory
    (:func:`~carapost.core.heap.keep_freed_memory`): every frame allocates and
    frees the same ~1 MB images, and page faults otherwise cost ~1 ms per frame
    and make the threads queue on the process's memory map.
    """
    keep_freed_memory()
    workers = workers or default_workers()
    settings = blob_settings(properties)
    out: dict = {}
    if workers <= 1:
        for key, img in frames:
            if progress is not None:
                progress.check()
            out[key] = detect_with_settings(img, settings)
            if progress is not None:
                progress.step()
        return out
    pending: deque = deque()

    def collect_one():
        key, fut = pending.popleft()
        out[key] = fut.result()
        if progress is not None:
            progress.step()            # raises Cancelled when cancelled

    with _one_opencv_thread():
        pool = ThreadPoolExecutor(workers, thread_name_prefix="detect-blobs")
        try:
            for key, img in frames:
                if progress is not None:
                    progress.check()
                pending.append((key, pool.submit(detect_with_settings, img, settings)))
                while len(pending) >= 2 * workers:
                    collect_one()
            while pending:
                collect_one()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    return out


#: Detect Blobs [Active Range]: a worker decodes and detects runs of about this many frames of one channel.
RUN_FRAMES = 48


def _runs(source, m0: int, m1: int, size: int = RUN_FRAMES) -> list[tuple[int, int]]:
    """``[a, b)`` runs covering frames ``m0 .. m1-1`` of ``source``, each after the first starting at a keyframe.

    A run that starts at a keyframe decodes nothing before its first frame; runs of
    ``size`` frames keep both workers busy on one channel as on four.
    """
    starts = [m0]
    for a in range(m0 + size, m1, size):
        g = source.gop_start(a)
        if g > starts[-1]:
            starts.append(g)
    return list(zip(starts, starts[1:] + [m1]))


def detect_media(project, plan, workers: int | None = None, progress: Progress | None = None) -> dict:
    """Detect blobs on the project's media: ``plan`` is ``[(sensor, image_offset, first, stop)]`` (media frames).

    Each worker thread decodes its own runs of frames (:func:`_runs`; its own
    decoder per channel, with one decoder thread) and detects them, so decoding is
    spread over the cores with the detection.  Measured on the 2-core machine, 120
    frames of a 35-marker ``carapost sample`` take (lossless: ~9.6 ms of CPU to decode
    a 1280x720 frame): 102-105 frames/s on 1.92 cores, where the calling thread
    decoding for a pool that detected (its decoder's two slice threads cost ~1.2x the
    CPU of one) gave 97-102 on 1.82, and the same detections.  Returns ``{(sensor,
    take frame): records}``; raises :class:`~carapost.core.progress.Cancelled` (the
    frames done are dropped) or the first error of a run (the others stop).
    """
    keep_freed_memory()
    workers = workers or default_workers()
    settings = blob_settings(project.properties)
    tasks, opened, spare = [], [], {}
    lock, local, stop = threading.Lock(), threading.local(), threading.Event()

    def source(s):
        cache = getattr(local, "sources", None)
        if cache is None:
            cache = local.sources = {}
        if s not in cache:
            with lock:
                src = spare.pop(s, None)
            if src is None:
                src = _open(project, s, decode_threads=1)
                with lock:
                    opened.append(src)
            cache[s] = src
        return cache[s]

    def run(s, off, a, b):
        out = {}
        for m, img in source(s).read_range(a, b):
            if stop.is_set():
                break                       # another run failed or was cancelled
            if progress is not None:
                progress.check()            # raises Cancelled
            out[(s, m + off)] = detect_with_settings(img, settings)
            if progress is not None:
                progress.step()
        return out

    cells: dict = {}
    try:
        for s, off, m0, m1 in plan:
            # Opened here for its keyframes, then the first worker's source of that sensor (a video's
            # opening demuxes the whole file).
            src = spare[s] = _open(project, s, decode_threads=1)
            opened.append(src)
            m0, m1 = max(0, m0), min(m1, src.frame_count)
            tasks += [(s, off, a, b) for a, b in (_runs(src, m0, m1) if m0 < m1 else [])]
        if workers <= 1:
            for t in tasks:
                cells.update(run(*t))
            return cells
        with _one_opencv_thread():
            pool = ThreadPoolExecutor(workers, thread_name_prefix="detect-blobs")
            try:
                futures = [pool.submit(run, *t) for t in tasks]
                # The first failure (a cancel, an unreadable file) ends the run: the others stop at their next frame.
                done, _ = wait(futures, return_when=FIRST_EXCEPTION)
                for f in futures:
                    if f in done and f.exception() is not None:
                        raise f.exception()
                for f in futures:
                    cells.update(f.result())
            finally:
                stop.set()
                pool.shutdown(wait=True, cancel_futures=True)
        return cells
    finally:
        for src in opened:
            src.close()


def detect_blobs_range(project, start: int, end: int, sensors: Iterable[int] | None = None,
                       progress: Progress | None = None, workers: int | None = None) -> DetectBlobs:
    """Process > Detect Blobs [Active Range]: every frame ``start..end`` (inclusive).

    Each of ``workers`` threads (default: every core) decodes and detects its own
    runs of frames (:func:`detect_media`).

    Parameters
    ----------
    project : Project
    start, end : int
        Inclusive take frames.
    sensors : iterable of int, optional
        Default: the explicit channel selection (``project.channel_selection``), else every sensor.
    progress : Progress, optional
        Counts frames; ``progress.cancel()`` stops the run with :class:`Cancelled`.
    workers : int, optional

    Returns
    -------
    DetectBlobs
        The undoable command (not yet run).
    """
    start, end = project.check_range(start, end)
    sens = _sensors(project, sensors)
    plan = []
    for s in sens:
        off = project.sensors[s].image_offset
        plan.append((s, off, start - off, end + 1 - off))
    if progress is not None:
        progress.start(len(sens) * (end - start + 1), "Detect Blobs")
    cells = detect_media(project, plan, workers, progress)
    return DetectBlobs(dict(sorted(cells.items())), name="Detect Blobs [Active Range]")


def remove_unused_detections(project) -> RemoveUnusedDetections:
    """Edit > Remove Unused Detections: the command (computed when first run)."""
    del project  # the plan is made against the project state the command is run on
    return RemoveUnusedDetections()


def read_blob_parameters_from_pico(project) -> SetProperties:
    """Edit > Read Blob Parameters From Pico Files.

    The Blob Parameters the pico files carried (``project.pico_blob_parameters``);
    parameters they did not carry (all, for picos without any) go back to their defaults.
    """
    stored = project.pico_blob_parameters or {}
    values = {k: (property_def(k).coerce(stored[k]) if k in stored else property_def(k).default) for k in BLOB_KEYS}
    return SetProperties(values, name="Read Blob Parameters From Pico Files")


__all__ = ["DetectBlobs", "RemoveUnusedDetections", "blob_preview", "detect_blobs_current_frame",
           "detect_blobs_range", "detect_frames", "detect_media", "remove_unused_detections",
           "read_blob_parameters_from_pico"]
