"""A shared, memory-bounded cache of decoded frames.

Decoding a frame of a long-GOP video (``.pico`` files are H.264 with an
I-frame every 24 or so frames) means decoding every frame from its GOP's
I-frame.  The cache keeps all frames decoded on the way, so after one random
access the neighbouring frames — in particular stepping backwards — cost a
dictionary lookup.  It is least-recently-used, bounded in megabytes, shared
by all channels and threads, and can decode ahead in worker threads
(:meth:`FrameCache.prefetch`; PyAV releases the GIL while decoding, so
channels decode in parallel).
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Iterable

import numpy as np


def _key(source) -> int:
    return getattr(source, "uid", None) or id(source)


class FrameCache:
    """LRU cache of decoded frames keyed by (source, frame index).

    Parameters
    ----------
    max_mb : float
        Memory bound of the cached frames in megabytes (MiB).
    workers : int
        Threads used by :meth:`prefetch`.

    Notes
    -----
    Sources must provide ``read(index)``, ``gop_start(index)`` and
    ``read_range(start, stop)`` (see :class:`carapost.io.media.FrameSource`);
    a source is identified by its ``uid`` attribute.  Frames handed out are
    read-only arrays shared with the cache: copy before modifying.
    """

    def __init__(self, max_mb: float = 512, workers: int = 2):
        self.max_bytes = int(max_mb * 1024 * 1024)
        self._frames: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()               # guards the dictionary and counters
        self._source_locks: dict[int, threading.Lock] = {}
        self._workers = max(1, int(workers))
        self._pool: ThreadPoolExecutor | None = None
        self._hits = self._misses = self._decoded = self._runs = self._evictions = 0

    # ---- internals -------------------------------------------------------------------------

    def _lookup(self, k: tuple[int, int]) -> np.ndarray | None:
        with self._lock:
            img = self._frames.get(k)
            if img is not None:
                self._frames.move_to_end(k)
            return img

    def _put(self, k: tuple[int, int], img: np.ndarray) -> np.ndarray:
        img.flags.writeable = False
        with self._lock:
            old = self._frames.pop(k, None)
            if old is not None:
                self._bytes -= old.nbytes
            self._frames[k] = img
            self._bytes += img.nbytes
            while self._bytes > self.max_bytes and self._frames:
                _, ev = self._frames.popitem(last=False)
                self._bytes -= ev.nbytes
                self._evictions += 1
        return img

    def _source_lock(self, sk: int) -> threading.Lock:
        with self._lock:
            lk = self._source_locks.get(sk)
            if lk is None:
                lk = self._source_locks[sk] = threading.Lock()
            return lk

    # ---- public ------------------------------------------------------------------------------

    def get(self, source, index: int) -> np.ndarray:
        """Frame ``index`` of ``source``, decoding (and caching) its GOP run when missing.

        On a miss, the frames from the first uncached frame at or after the
        GOP start up to ``index`` are decoded in one sequential run and all
        kept, so stepping backwards through the GOP is free afterwards and
        stepping forwards continues the source's decoder.

        Raises
        ------
        CaraError
            When the frame cannot be decoded (from ``source.read``).
        """
        index = int(index)
        sk = _key(source)
        k = (sk, index)
        img = self._lookup(k)
        if img is not None:
            with self._lock:
                self._hits += 1
            return img
        # One decoder run per source at a time; another thread may have decoded our frame meanwhile.
        with self._source_lock(sk):
            img = self._lookup(k)
            if img is not None:
                with self._lock:
                    self._hits += 1
                return img
            start = source.gop_start(index)
            with self._lock:
                self._misses += 1
                j = index
                while j > start and (sk, j - 1) not in self._frames:
                    j -= 1
            got = None
            decoded = 0
            for i, frame in source.read_range(j, index + 1):
                decoded += 1
                stored = self._put((sk, i), frame)
                if i == index:
                    got = stored
            with self._lock:
                self._decoded += decoded
                self._runs += 1
            if got is None:
                # Not produced by the run (damaged?): read() raises the reason naming file and frame.
                got = self._put(k, source.read(index))
                with self._lock:
                    self._decoded += 1
            return got

    def prefetch(self, source, indices: Iterable[int]) -> Future:
        """Decode frames into the cache in a worker thread.

        Parameters
        ----------
        source : FrameSource
        indices : iterable of int
            Frames wanted soon, most urgent first.

        Returns
        -------
        concurrent.futures.Future
            Done when all are cached; its result is the number of frames that
            could not be decoded.
        """
        wanted = [int(i) for i in indices]
        if self._pool is None:
            with self._lock:
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(self._workers, thread_name_prefix="framecache")
        return self._pool.submit(self._prefetch, source, wanted)

    def _prefetch(self, source, wanted: list[int]) -> int:
        from ..core.errors import CaraError

        failed = 0
        sk = _key(source)
        for i in wanted:
            if (sk, i) in self._frames:
                continue
            try:
                self.get(source, i)
            except (CaraError, IndexError):
                failed += 1
        return failed

    def contains(self, source, index: int) -> bool:
        """Whether frame ``index`` of ``source`` is cached (without touching its LRU rank)."""
        return (_key(source), int(index)) in self._frames

    def stats(self) -> dict:
        """Counters: hits, misses, frames decoded, decode runs, evictions, entries, bytes, max_bytes."""
        with self._lock:
            return {"hits": self._hits, "misses": self._misses, "decoded": self._decoded,
                    "runs": self._runs, "evictions": self._evictions, "entries": len(self._frames),
                    "bytes": self._bytes, "max_bytes": self.max_bytes}

    def clear(self, source=None) -> None:
        """Forget all cached frames, or only those of ``source``."""
        with self._lock:
            if source is None:
                self._frames.clear()
                self._bytes = 0
                return
            sk = _key(source)
            for k in [k for k in self._frames if k[0] == sk]:
                self._bytes -= self._frames.pop(k).nbytes

    def close(self) -> None:
        """Stop the worker threads (waits for running prefetches)."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
