"""Choosing among candidate matches: a pair is taken only when it is the clear choice of both its detections."""
from __future__ import annotations

import numpy as np

#: A best candidate is "clear" when the next one is this many times worse.
CLEAR_RATIO = 4.0


def unambiguous(ia: np.ndarray, ib: np.ndarray, d: np.ndarray, penalty: np.ndarray | None = None) -> np.ndarray:
    """Mask of candidate pairs that are the clear choice of both their detections.

    Parameters
    ----------
    ia, ib : ndarray of int (n,)
        The two detections of each candidate pair.
    d : ndarray (n,)
        Each pair's cost (an epipolar distance, px).
    penalty : ndarray (n,), optional
        Added to the cost of pairs that lack some evidence (px): pairs are
        ranked by ``d + penalty``, and a best pair is weighed against the next
        by those costs when their penalties differ, by ``d`` alone when they
        are the same (two pairs both lacking the evidence are told apart by
        their own costs, not by costs the penalty has made alike).

    Returns
    -------
    ndarray of bool (n,)
        A pair is clear for a detection when it is that detection's only
        candidate, or when the next best costs at least :data:`CLEAR_RATIO`
        times as much (costs below 0.05 count as 0.05).
    """
    ok = np.ones(len(ia), bool)
    if not len(ia):
        return ok
    pen = np.zeros(len(d)) if penalty is None else np.asarray(penalty, float)
    eff = d + pen
    for key in (ia, ib):
        order = np.lexsort((eff, key))
        k = key[order]
        first = np.r_[True, k[1:] != k[:-1]]
        start = np.flatnonzero(first)
        counts = np.diff(np.r_[start, len(k)])
        nxt = order[np.minimum(start + 1, len(k) - 1)]
        best = order[start]
        same = pen[best] == pen[nxt]
        b = np.where(same, d[best], eff[best])
        second = np.where(counts > 1, np.where(same, d[nxt], eff[nxt]), np.inf)
        good = (counts == 1) | (second >= CLEAR_RATIO * np.maximum(b, 0.05))
        winner = np.zeros(len(k), bool)
        winner[start[good]] = True
        m = np.zeros(len(ia), bool)
        m[order] = winner
        ok &= m
    return ok
