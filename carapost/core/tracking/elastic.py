"""Elastic prediction: where a point should be, given how its neighbours sit.

Every tracked point keeps, for each of its K nearest neighbours (fixed at the
start frame), the offset to that neighbour on the last frame both were
measured.  A face deforms smoothly, so a point's position is predicted as
the median over its measured neighbours of (neighbour + offset): this follows
the head, the jaw and a blink with the neighbours, and brings a point lost
during an occlusion back to where its marker reappears.

Not every neighbour moves with a point: a lower lip's nearest markers are half
on the jaw, half on the upper lip, and a plain median of the two groups leaves
it half way while the jaw is open (and, with offsets refreshed open, half way
again once it closes).  So each offset also keeps how much it has changed from
frame to frame (:func:`update_offsets` with ``motion``), and the prediction is
a weighted median that trusts the neighbours whose offsets stayed steady: once
the jaw has moved, the lower lip follows the chin, not the nose.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ..jit import JIT_EXACT
from ..stabilize import kabsch

#: Neighbours per point.
K_NEIGHBOURS = 6
#: Neighbours per point added because they count the point among their nearest (:func:`neighbours`).
MUTUAL = 2
#: Fewest measured neighbours for a prediction.
MIN_NEIGHBOURS = 2
#: Offset change (mm) per frame below which neighbours count as moving together: noise, and a
#: slow drift, must not let one neighbour outweigh the others before anything has moved.
STEADY_MM = 0.3
#: Weights within this ratio of each other count as equal (the plain median, which costs less).
UNEVEN = 1.5


def neighbours(X: np.ndarray, k: int = K_NEIGHBOURS, mutual: int = 0) -> np.ndarray:
    """``(N, k + mutual)`` indices of each point's nearest other points (-1 padding).

    With ``mutual``, each point also gets, nearest first, up to ``mutual`` of the
    points that count it among their ``k`` nearest but that it does not count
    among its own: the link is made both ways.  On a sparse set a lower lip's
    nearest six are lips, mouth corners and nasolabials while the chin counts
    the lower lip among its own; with the link both ways the lower lip hears the
    chin too, and a jaw marker the cheek beside it.

    A point without a position (a row with NaN) has no neighbours and is no one's.
    """
    n = len(X)
    out = np.full((n, k + mutual), -1)
    have = np.all(np.isfinite(X), axis=1)
    if not have.all():
        # The tracking of new points back from the frame they were made on starts where other points may be lost.
        rows = np.flatnonzero(have)
        sub = neighbours(X[rows], k, mutual)
        out[rows] = np.where(sub >= 0, rows[np.maximum(sub, 0)], -1)
        return out
    if n < 2:
        return out
    kk = min(k, n - 1)
    _, idx = cKDTree(X).query(X, k=kk + 1)
    out[:, :kk] = idx[:, 1:]
    if mutual:
        near = np.zeros((n, n), bool)
        near[np.repeat(np.arange(n), kk), idx[:, 1:].ravel()] = True
        back = near.T & ~near                    # back[i, j]: j counts i among its nearest, not i j
        dist = np.where(back, np.linalg.norm(X[:, None] - X[None], axis=2), np.inf)
        order = np.argsort(dist, axis=1, kind="stable")[:, :mutual]
        ok = np.isfinite(np.take_along_axis(dist, order, 1))
        out[:, kk:kk + order.shape[1]] = np.where(ok, order, -1)
    return out


def spacing(X: np.ndarray, k: int = K_NEIGHBOURS) -> np.ndarray:
    """(N,) each point's mean distance (mm) to its ``k`` nearest others; points without a position get the median."""
    n = len(X)
    have = np.all(np.isfinite(X), axis=1)
    out = np.full(n, np.nan)
    if np.count_nonzero(have) >= 2:
        kk = min(k, int(np.count_nonzero(have)) - 1)
        d, _ = cKDTree(X[have]).query(X[have], k=kk + 1)
        out[have] = d[:, 1:].mean(axis=1)
        out[~have] = np.median(out[have])
    else:
        out[:] = 20.0                                    # a face's typical spacing; nothing to measure it from
    return out


def update_offsets(off: np.ndarray, nb: np.ndarray, X: np.ndarray, measured: np.ndarray,
                   motion: np.ndarray | None = None) -> None:
    """Refresh ``off`` (N, K, 3) in place where a point and its neighbour are both measured.

    Parameters
    ----------
    motion : ndarray (N, K, 2), optional
        Running (sum of squared offset changes in mm², number of changes) per
        neighbour, updated in place where an offset already known is refreshed;
        :func:`weights` turns it into the prediction's weights.
    """
    _refresh(off, nb, X, np.asarray(measured, np.bool_),
             np.zeros((0, 0, 2)) if motion is None else motion, motion is not None)


@njit(**JIT_EXACT)
def _refresh(off, nb, X, measured, motion, track_motion):
    """:func:`update_offsets` as one loop: ``off[i, k] = X[i] - X[nb[i, k]]`` where both are measured.

    With ``track_motion``, an offset already known first adds its squared change (summed over x, y, z
    in order, as ``np.sum`` over the last axis) and one count to ``motion[i, k]``.
    """
    n, K = nb.shape
    new = np.empty(3)
    for i in range(n):
        if not measured[i]:
            continue
        for k in range(K):
            j = nb[i, k]
            if j < 0 or not measured[j]:
                continue
            for c in range(3):
                new[c] = X[i, c] - X[j, c]
            if track_motion and np.isfinite(off[i, k, 0]) and np.isfinite(off[i, k, 1]) \
                    and np.isfinite(off[i, k, 2]):
                change = 0.0
                for c in range(3):
                    e = new[c] - off[i, k, c]
                    change += e * e
                motion[i, k, 0] += change
                motion[i, k, 1] += 1.0
            for c in range(3):
                off[i, k, c] = new[c]


def weights(motion: np.ndarray) -> np.ndarray:
    """(N, K) weight of each neighbour: the inverse of its offset's mean squared change (plus the steady floor)."""
    mean_sq = motion[..., 0] / np.maximum(motion[..., 1], 1)
    return 1.0 / (mean_sq + STEADY_MM ** 2)


def predict(X: np.ndarray, available: np.ndarray, nb: np.ndarray, off: np.ndarray,
            min_neighbours: int = MIN_NEIGHBOURS, weight: np.ndarray | None = None,
            rigid: np.ndarray | None = None, rotate: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Median over available neighbours of (neighbour position + offset).

    Parameters
    ----------
    X : ndarray (N, 3)
        Neighbour positions to predict from.
    available : ndarray (N,) bool
        Which rows of ``X`` may be used.
    nb, off : ndarray (n, K), (n, K, 3)
        Neighbours and offsets of the points to predict: all N, or some rows of
        them (then the results are for those rows only).
    weight : ndarray (n, K), optional
        Per-neighbour weights (:func:`weights`): a weighted median per
        coordinate; None gives every neighbour the same say.
    rigid : ndarray (n,) bool, optional
        Rows predicted by their neighbours' rigid motion instead (:func:`_rigid_fit`; rows with fewer
        than four usable neighbours keep the median): points whose offsets are from frames ago.
    rotate : ndarray (n,) bool, optional
        Rows whose votes are turned first by their neighbourhood's rotation since the offsets were refreshed
        (:func:`turned_offsets`); the median then still leaves out a neighbour that moved on its own.

    Returns
    -------
    pred : ndarray (N, 3)
        NaN where fewer than ``min_neighbours`` neighbours are usable.
    count : ndarray (N,) int
        Neighbours used.
    """
    X = np.ascontiguousarray(X, dtype=float)
    if rigid is not None and np.any(rigid):
        pred, count = predict(X, available, nb, off, min_neighbours, weight)
        _rigid_fit(X, available, nb, off, weight, np.flatnonzero(rigid), pred)
        return pred, count
    if rotate is not None and np.any(rotate):
        off = turned_offsets(X, available, nb, off, np.flatnonzero(rotate))
    if weight is None:
        pred, _use, _cand, count = _votes_median(X, available, nb, off, min_neighbours)
        return pred, count
    # Weighted median per coordinate where the weights differ (near the jaw, once it has moved): the vote
    # that minimises the weighted sum of distances to all votes (the mean of the minimisers when two tie,
    # as the plain median of an even count does).
    return _votes_weighted_median(X, available, nb, off, min_neighbours, np.ascontiguousarray(weight, dtype=float),
                                  UNEVEN)


@njit(**JIT_EXACT)
def _votes_median(X, available, nb, off, min_neighbours):
    """Each row's votes ``X[nb] + off`` and their plain median, as numpy's sort-based median computes it.

    Returns the medians (n, 3; NaN where fewer than ``min_neighbours`` votes), the votes used (n, K),
    the votes (n, K, 3; NaN unused) and their count (n,).  Per coordinate the votes are sorted with NaN
    last (an available neighbour may lack a position) and the median is ``0.5 * (lo + hi)`` of the middle
    two, as ``np.sort`` and the indexing did; one pass per row instead of a dozen array operations.
    """
    n, K = nb.shape
    pred = np.empty((n, 3))
    use = np.empty((n, K), np.bool_)
    cand = np.empty((n, K, 3))
    count = np.empty(n, np.int64)
    col = np.empty(K)
    for i in range(n):
        c = 0
        for d in range(3):
            pred[i, d] = np.nan
        for k in range(K):
            use[i, k] = False
            for d in range(3):
                cand[i, k, d] = np.nan
            j = nb[i, k]
            if j >= 0 and available[j] and np.isfinite(off[i, k, 0]) and np.isfinite(off[i, k, 1]) \
                    and np.isfinite(off[i, k, 2]):
                use[i, k] = True
                for d in range(3):
                    cand[i, k, d] = X[j, d] + off[i, k, d]
                c += 1
        count[i] = c
        if c < min_neighbours:
            continue
        for d in range(3):
            # Insertion sort of the used votes, NaN last.
            m = 0
            for k in range(K):
                if use[i, k]:
                    v = cand[i, k, d]
                    p = m
                    while p > 0 and (col[p - 1] > v or (np.isnan(col[p - 1]) and not np.isnan(v))):
                        col[p] = col[p - 1]
                        p -= 1
                    col[p] = v
                    m += 1
            pred[i, d] = 0.5 * (col[(c - 1) // 2] + col[c // 2])
    return pred, use, cand, count


@njit(error_model="numpy", **JIT_EXACT)
def _votes_weighted_median(X, available, nb, off, min_neighbours, weight, ratio):
    """:func:`_votes_median`, then a weighted median per coordinate for the rows whose weights are uneven.

    Uneven: the largest used weight exceeds ``ratio`` times the smallest (a NaN weight: not).  There,
    per coordinate, each used vote costs the weighted sum of its distances to all used votes, and the
    prediction is the mean of the votes whose cost is within ``1e-9 (1 + least)`` of the least (NaN costs
    leave no least: NaN, as numpy divided by zero).
    """
    pred, use, cand, count = _votes_median(X, available, nb, off, min_neighbours)
    n, K = nb.shape
    cost = np.empty(K)
    for i in range(n):
        if count[i] < min_neighbours:
            continue
        hi = -np.inf
        lo = np.inf
        nan = False
        for k in range(K):
            if use[i, k]:
                wk = weight[i, k]
                if np.isnan(wk):
                    nan = True
                hi = max(hi, wk)
                lo = min(lo, wk)
        if nan or not hi > ratio * lo:
            continue
        for c in range(3):
            best = np.inf
            for a in range(K):
                if not use[i, a]:
                    continue
                acc = 0.0
                for b in range(K):
                    if use[i, b]:
                        acc += abs(cand[i, a, c] - cand[i, b, c]) * weight[i, b]
                cost[a] = acc
                if np.isnan(best) or np.isnan(acc) or acc < best:
                    best = acc if not np.isnan(best) else best
            lim = best + 1e-9 * (1.0 + best)
            acc = 0.0
            m = 0
            for a in range(K):
                if use[i, a] and cost[a] <= lim:
                    acc += cand[i, a, c]
                    m += 1
            pred[i, c] = acc / m
    return pred, count


def _neighbourhood_motion(X, available, nb, off, weight, rows):
    """The rigid motion (n, 3, 4) carrying each of ``rows``' neighbours from where its offsets placed them
    (``-off``, the point at the origin) to where they are now (weighted least squares,
    :func:`..stabilize.kabsch`), and which rows have the four usable neighbours that it needs (n,) bool."""
    j = nb[rows]
    there = np.where((j >= 0)[..., None], X[np.maximum(j, 0)], np.nan)
    then = -off[rows]
    usable = (j >= 0) & available[np.maximum(j, 0)] & np.isfinite(there).all(-1) & np.isfinite(then).all(-1)
    w = np.ones(j.shape) if weight is None else weight[rows]
    fit = kabsch(then, there, np.where(usable, w, 0.0))
    return fit, usable.sum(axis=1) >= 4


def _rigid_fit(X, available, nb, off, weight, rows, pred) -> None:
    """Into ``pred[rows]``, for rows with 4+ usable neighbours: where the neighbours' rigid motion takes the point.

    The rotation and shift that best carry the neighbours from where the offsets placed them (when they were
    last refreshed) onto their positions now (:func:`_neighbourhood_motion`) carry the point too, to the
    shift.  A point lost for a while keeps the offsets of its loss: a median of translated votes leaves it
    behind a turning jaw.
    """
    fit, enough = _neighbourhood_motion(X, available, nb, off, weight, rows)
    pred[rows[enough]] = fit[enough, :, 3]


def turned_offsets(X, available, nb, off, rows) -> np.ndarray:
    """``off`` (n, K, 3) with each of ``rows`` turned by its neighbourhood's rotation since it was refreshed.

    A vote ``X[j] + off`` translates the point with its neighbour; where the face turns (the jaw opening)
    the point also swings about it, by the offset's length times the angle: 0.1-0.2 mm a frame at 10 mm.
    The rotation is :func:`_neighbourhood_motion`'s, unweighted; rows with fewer than four usable neighbours
    are left as they are.
    """
    # Every usable neighbour has the same say in the rotation: where one outweighs the rest (it moved with
    # the point), the weighted fit rests on one point and its rotation is a guess (docs/tracking-history.md,
    # "Session 28": a cheek dot's neighbourhood turned 11-14 degrees in four frames).
    fit, enough = _neighbourhood_motion(X, available, nb, off, None, rows)
    enough &= np.isfinite(fit[:, 0, 0])
    out = np.array(off, dtype=float, copy=True)
    r = rows[enough]
    out[r] = np.einsum("nij,nkj->nki", fit[enough, :, :3], off[r])
    return out


@njit(**JIT_EXACT)
def along_spread(X, nb, off, weight, pred, u, rows, use_firm, firm, voting, out):
    """Into ``out[q]``: the weighted robust spread along ``u[q]`` of row ``rows[q]``'s votes about ``pred[q]``.

    A vote is ``X[j] + off[i, k]`` of neighbour ``j = nb[i, k]`` if ``j`` is in ``firm`` (where
    ``use_firm[q]``) or ``voting`` (elsewhere) and its offset is known; its deviation is the absolute
    component along ``u[q]`` of its distance from ``pred[q]``.  The spread is 1.4826 times the weighted
    median deviation (the first, in increasing order, whose cumulative weight reaches half the total;
    NaN deviations last); 0 where that is not finite or no vote has weight.
    """
    K = nb.shape[1]
    dev = np.empty(K)
    w = np.empty(K)
    for q in range(len(rows)):
        i = rows[q]
        m = 0
        total = 0.0
        for k in range(K):
            j = nb[i, k]
            if j < 0 or not (firm[j] if use_firm[q] else voting[j]):
                continue
            if not (np.isfinite(off[i, k, 0]) and np.isfinite(off[i, k, 1]) and np.isfinite(off[i, k, 2])):
                continue
            d = abs((X[j, 0] + off[i, k, 0] - pred[q, 0]) * u[q, 0] + (X[j, 1] + off[i, k, 1] - pred[q, 1]) * u[q, 1]
                    + (X[j, 2] + off[i, k, 2] - pred[q, 2]) * u[q, 2])
            wk = weight[i, k]
            # Insertion sort by deviation, NaN last, equal ones in neighbour order.
            p = m
            while p > 0 and (dev[p - 1] > d or (np.isnan(dev[p - 1]) and not np.isnan(d))):
                dev[p] = dev[p - 1]
                w[p] = w[p - 1]
                p -= 1
            dev[p] = d
            w[p] = wk
            m += 1
        total = 0.0
        heavy = 0.0
        for p in range(m):      # in sorted order, as the cumulative sum below adds them
            total += w[p]
            heavy = max(heavy, w[p])
        out[q] = 0.0
        if m == 0 or not total > 0.0:
            continue
        # A vote of half the weight or more is the weighted median alone, and its own deviation (0) would be the
        # spread whatever the others say: it counts as much as the others together, and the spread is the
        # first deviation past half.
        capped = m > 1 and 2.0 * heavy >= total
        cap = total - heavy if capped else heavy
        if capped:
            total = 2.0 * cap
        acc = 0.0
        half = 0
        for p in range(m):
            acc += min(w[p], cap)
            # Capped, the heavy vote reaches half exactly: the median is the next deviation, not its own.
            if acc > 0.5 * total or (not capped and acc == 0.5 * total):
                half = p
                break
        s = 1.4826 * dev[half]
        if np.isfinite(s):
            out[q] = s
