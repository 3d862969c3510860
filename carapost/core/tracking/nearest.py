"""Nearest detections of predicted positions: a drop-in for the frame's ``cKDTree`` queries.

The tracker asks each frame's detections (~750 over 4 sensors, all sensors in one
index, see :class:`.engine.FrameData`) for the few nearest to ~100-700 predicted
positions, five or six times a frame.  ``cKDTree`` costs ~130 us to build and
~30 us per call before the first query; at this size a sorted sweep over x costs
less: the detections sorted by x once, each query scans the few whose x lies
within its bound.

The answers are ``cKDTree.query``'s to the bit: the same squared distance
``dx * dx + dy * dy`` in float64 (no fused multiply-add; ``JIT_EXACT``), the
same strict test against the bound squared, the same ``sqrt``, ``n`` and ``inf``
where fewer are found.  Only the order of exactly equal distances is the tree's
own (its traversal decides it), so a row with two equal squared distances among
its nearest ``k + 1`` is answered by a real ``cKDTree`` (built only then;
duplicated detections are the one way it happens).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ..jit import JIT_EXACT


@njit(**JIT_EXACT)
def _first_at_least(xs, v):
    """First index ``i`` with ``xs[i] >= v`` (``len(xs)`` if none) of the sorted ``xs``."""
    lo, hi = 0, len(xs)
    while lo < hi:
        mid = (lo + hi) // 2
        if xs[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(**JIT_EXACT)
def _knn(xs, ys, order, q, k, bound, d_out, i_out, tie):
    """The ``k`` nearest of (``xs``, ``ys``) (sorted by x; ``order``: their indices) to each row of ``q``.

    Fills ``d_out`` / ``i_out`` (n, k) as ``cKDTree.query(q, k, distance_upper_bound=bound)`` does and
    sets ``tie[r]`` where row ``r`` has equal squared distances among its ``k + 1`` nearest.
    """
    n = len(xs)
    ub = bound * bound
    m = k + 1
    best_s = np.empty(m)
    best_j = np.empty(m, np.int64)
    for r in range(q.shape[0]):
        x = q[r, 0]
        y = q[r, 1]
        cnt = 0
        # One pixel of slack: the window only has to hold every point the exact test below can accept.
        j = _first_at_least(xs, x - bound - 1.0)
        stop = x + bound + 1.0
        while j < n and xs[j] <= stop:
            dx = xs[j] - x
            dy = ys[j] - y
            s = dx * dx
            s += dy * dy
            if s < ub and (cnt < m or s < best_s[m - 1]):
                c = cnt if cnt < m else m - 1
                while c > 0 and best_s[c - 1] > s:
                    best_s[c] = best_s[c - 1]
                    best_j[c] = best_j[c - 1]
                    c -= 1
                best_s[c] = s
                best_j[c] = j
                if cnt < m:
                    cnt += 1
            j += 1
        t = False
        for c in range(1, cnt):
            if best_s[c] == best_s[c - 1]:
                t = True
        tie[r] = t
        for c in range(k):
            if c < cnt:
                d_out[r, c] = math.sqrt(best_s[c])
                i_out[r, c] = order[best_j[c]]
            else:
                d_out[r, c] = np.inf
                i_out[r, c] = n


class SortedSweep:
    """2-D points answering ``query(x, k, distance_upper_bound)`` exactly as a ``cKDTree`` of them would.

    Parameters
    ----------
    data : ndarray (n, 2)
        The points (float64; kept, not copied: do not change them).
    """

    def __init__(self, data: np.ndarray):
        self.data = np.asarray(data, np.float64)
        self.n = len(self.data)
        self._order = np.argsort(self.data[:, 0], kind="stable")
        self._xs = np.ascontiguousarray(self.data[self._order, 0])
        self._ys = np.ascontiguousarray(self.data[self._order, 1])
        self._tree = None

    def query(self, x: np.ndarray, k: int = 1, distance_upper_bound: float = np.inf):
        """Distances ``(m, k)`` and indices ``(m, k)`` of the ``k`` nearest points to each row of ``x`` (m, 2).

        As ``cKDTree.query`` with ``p=2``, ``eps=0`` and a finite ``distance_upper_bound`` (the bound
        limits the sweep), except that ``k == 1`` also gives 2-D arrays; queries must be finite.
        """
        if not np.isfinite(distance_upper_bound):
            raise ValueError("SortedSweep needs a finite distance_upper_bound")
        x = np.ascontiguousarray(x, np.float64).reshape(-1, 2)
        d = np.empty((len(x), k))
        i = np.empty((len(x), k), np.int64)
        tie = np.empty(len(x), np.bool_)
        _knn(self._xs, self._ys, self._order, x, k, float(distance_upper_bound), d, i, tie)
        if tie.any():
            if self._tree is None:
                self._tree = cKDTree(self.data)
            r = np.flatnonzero(tie)
            dt, it = self._tree.query(x[r], k=k, distance_upper_bound=distance_upper_bound)
            d[r], i[r] = dt.reshape(len(r), k), it.reshape(len(r), k)
        return d, i
