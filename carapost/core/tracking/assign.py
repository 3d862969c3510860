"""Candidate search and one-to-one assignment of detections to points, vectorised per frame."""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ..jit import JIT_EXACT

from .finite import finite_rows
from .nearest import SortedSweep

#: Candidates considered per point and sensor (the nearest ones within the radius).
K_CANDIDATES = 3


def candidates(tree: cKDTree | SortedSweep | None, free: np.ndarray, pred: np.ndarray, radius: np.ndarray, k: int = K_CANDIDATES,
               known: tuple | None = None):
    """Nearest free detections of predicted positions.

    Parameters
    ----------
    tree : cKDTree or SortedSweep or None
        Over the detections (corrected pixels); None when there are none.
    free : ndarray (D,) bool
        Detections still available.
    pred : ndarray (N, 2)
        Predicted corrected positions (NaN: no search).
    radius : ndarray (N,)
        Search radius of each point.
    known : tuple (pred, idx, dist), optional
        An earlier call's ``pred`` and results with the same ``tree``, ``free``, ``radius`` and ``k``:
        rows whose prediction is unchanged take their results from it instead of a new search.

    Returns
    -------
    idx : ndarray (N, k) int
        Detection indices (-1 none), nearest first.
    dist : ndarray (N, k)
        Distances (inf none).
    """
    N = len(pred)
    idx = np.full((N, k), -1)
    dist = np.full((N, k), np.inf)
    ok = finite_rows(pred) & (radius > 0)
    if tree is None or tree.n == 0 or not np.any(ok):
        return idx, dist
    bound = float(np.max(radius[ok]))
    if known is not None:
        same = ok & np.all(pred == known[0], axis=1)
        idx[same], dist[same] = known[1][same], known[2][same]
        ok &= ~same
        if not np.any(ok):
            return idx, dist
    kk = min(tree.n, k + 2)   # a few spares: some neighbours are taken
    d, i = tree.query(pred[ok], k=kk, distance_upper_bound=bound)
    _first_free(d.reshape(len(d), kk), i.reshape(len(i), kk), radius, free, np.flatnonzero(ok), idx, dist)
    return idx, dist


@njit(**JIT_EXACT)
def _first_free(d, i, radius, free, rows, idx, dist):
    """Into ``idx`` / ``dist`` rows ``rows``: the first hits of each query's neighbours (``d``, ``i``, nearest first).

    A hit is within the row's own ``radius`` and ``free`` (the query's bound is the largest radius, and
    taken detections are still in the index); the row keeps the first ``k`` hits in order, -1 / inf after.
    """
    k = idx.shape[1]
    for q in range(len(rows)):
        r = rows[q]
        c = 0
        for j in range(d.shape[1]):
            if c == k:
                break
            if np.isfinite(d[q, j]) and d[q, j] <= radius[r] and free[i[q, j]]:
                idx[r, c] = i[q, j]
                dist[r, c] = d[q, j]
                c += 1


def size_changed(prev: np.ndarray, sizes: np.ndarray, idx: np.ndarray, threshold: float) -> np.ndarray:
    """Candidates whose blob width or height changed too much (Blob Size Difference Threshold).

    The relative change is ``max(|a - b| / max(a, b, 1e-6))`` over (major, minor), ``a`` the
    candidate's size, ``b`` the point's previous one; a NaN (size unknown) counts 0, no evidence
    against the match.

    Parameters
    ----------
    prev : ndarray (n, 2)
        Each query's previous blob size (NaN unknown).
    sizes : ndarray (D, 2)
        Every detection's (major, minor).
    idx : ndarray (n, k) int
        Candidates (-1 none), as from :func:`candidates`.
    threshold : float

    Returns
    -------
    ndarray (n, k) bool
        Candidates (``idx >= 0``) whose change exceeds ``threshold``.
    """
    out = np.empty(idx.shape, np.bool_)
    _size_changed(np.asarray(prev, np.float64), np.asarray(sizes, np.float64), idx, float(threshold), out)
    return out


@njit(**JIT_EXACT)
def _nan_max(a, b):
    """``np.maximum(a, b)``: NaN if either is."""
    if np.isnan(a) or np.isnan(b):
        return np.nan
    return a if a >= b else b


@njit(**JIT_EXACT)
def _size_changed(prev, sizes, idx, threshold, out):
    """:func:`size_changed` as one loop (the array version's arithmetic and NaN and inf handling)."""
    n, k = idx.shape
    for r in range(n):
        for j in range(k):
            d = idx[r, j]
            if d < 0:
                out[r, j] = False
                continue
            rel = 0.0
            for c in range(2):
                a = sizes[d, c]
                b = prev[r, c]
                x = abs(a - b) / _nan_max(_nan_max(a, b), 1e-6)
                if np.isnan(x):
                    x = 0.0
                elif np.isinf(x):
                    x = 1.7976931348623157e308   # np.nan_to_num's stand-in for inf
                rel = x if c == 0 or x > rel else rel
            out[r, j] = rel > threshold


def mutual_best(point: np.ndarray, det: np.ndarray, cost: np.ndarray, n_points: int, n_dets: int,
                rounds: int = 4) -> np.ndarray:
    """One-to-one assignment of candidate pairs by repeated mutual best choice.

    A pair is accepted when it is the cheapest pair of both its point and its
    detection; accepted points and detections leave, and the rest try again.
    On sparse candidate sets this equals the greedy cheapest-first matching and
    costs a few array passes instead of a Python loop over pairs.

    Parameters
    ----------
    point, det : ndarray (P,) int
        Pair members (``point`` is any slot id < n_points, e.g. point * S + sensor).
    cost : ndarray (P,)

    Returns
    -------
    ndarray (P,) bool
        Accepted pairs.
    """
    acc = np.zeros(len(point), np.bool_)
    if len(point):
        _mutual_best(np.asarray(point, np.int64), np.asarray(det, np.int64), np.asarray(cost, np.float64),
                     int(n_points), int(n_dets), int(rounds), acc)
    return acc


@njit(**JIT_EXACT)
def _mutual_best(point, det, cost, n_points, n_dets, rounds, acc):
    """:func:`mutual_best`'s rounds as loops, into ``acc``; the same choices as its array version had.

    Per round: each point's and detection's cheapest alive cost (a NaN cost poisons its point and
    detection, as ``np.minimum.at`` did); a pair cheapest for both wins; of one detection's winners the
    first pair, of one point's the one with the lowest detection index (``np.unique`` sorted them so).
    """
    P = len(point)
    alive = np.empty(P, np.bool_)
    for i in range(P):
        alive[i] = True
    bp = np.empty(n_points)
    bd = np.empty(n_dets)
    first_d = np.empty(n_dets, np.int64)
    pick_p = np.empty(n_points, np.int64)
    taken_p = np.zeros(n_points, np.bool_)
    taken_d = np.zeros(n_dets, np.bool_)
    for _ in range(rounds):
        live = False
        for i in range(P):
            if alive[i]:
                live = True
            bp[point[i]] = np.inf
            bd[det[i]] = np.inf
            first_d[det[i]] = -1
            pick_p[point[i]] = -1
        if not live:
            break
        for i in range(P):
            if alive[i]:
                c = cost[i]
                if np.isnan(c) or c < bp[point[i]]:
                    bp[point[i]] = c
                if np.isnan(c) or c < bd[det[i]]:
                    bd[det[i]] = c
        for i in range(P):
            if alive[i] and cost[i] == bp[point[i]] and cost[i] == bd[det[i]] and first_d[det[i]] < 0:
                first_d[det[i]] = i
        for i in range(P):
            if first_d[det[i]] == i:
                j = pick_p[point[i]]
                if j < 0 or det[i] < det[j]:
                    pick_p[point[i]] = i
        for i in range(P):
            if pick_p[point[i]] == i:
                acc[i] = True
                taken_p[point[i]] = True
                taken_d[det[i]] = True
        for i in range(P):
            if taken_p[point[i]] or taken_d[det[i]]:
                alive[i] = False
