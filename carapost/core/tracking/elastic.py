"""Elastic prediction: where a point should be, given how its neighbours sit.

Every tracked point keeps, for each of its K nearest neighbours (fixed at the
start frame), the offset to that neighbour on the last frame both were
measured.  A face deforms smoothly, so a point's position is predicted as
the median over its measured neighbours of (neighbour + offset): this follows
the head, the jaw and a blink with the neighbours, and brings a point lost
during an occlusion back to where its marker reappears.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

#: Neighbours per point.
K_NEIGHBOURS = 6
#: Fewest measured neighbours for a prediction.
MIN_NEIGHBOURS = 2


def neighbours(X: np.ndarray, k: int = K_NEIGHBOURS) -> np.ndarray:
    """``(N, k)`` indices of each point's nearest other points (-1 padding)."""
    n = len(X)
    out = np.full((n, k), -1)
    if n < 2:
        return out
    kk = min(k, n - 1)
    _, idx = cKDTree(X).query(X, k=kk + 1)
    out[:, :kk] = idx[:, 1:]
    return out


def update_offsets(off: np.ndarray, nb: np.ndarray, X: np.ndarray, measured: np.ndarray) -> None:
    """Refresh ``off`` (N, K, 3) in place where a point and its neighbour are both measured."""
    Xn = X[np.maximum(nb, 0)]
    both = measured[:, None] & (nb >= 0) & measured[np.maximum(nb, 0)]
    off[both] = (X[:, None, :] - Xn)[both]


def predict(X: np.ndarray, available: np.ndarray, nb: np.ndarray, off: np.ndarray,
            min_neighbours: int = MIN_NEIGHBOURS) -> tuple[np.ndarray, np.ndarray]:
    """Median over available neighbours of (neighbour position + offset).

    Parameters
    ----------
    X : ndarray (N, 3)
        Neighbour positions to predict from.
    available : ndarray (N,) bool
        Which rows of ``X`` may be used.

    Returns
    -------
    pred : ndarray (N, 3)
        NaN where fewer than ``min_neighbours`` neighbours are usable.
    count : ndarray (N,) int
        Neighbours used.
    """
    safe = np.maximum(nb, 0)
    use = (nb >= 0) & available[safe] & np.all(np.isfinite(off), axis=2)
    cand = np.where(use[..., None], X[safe] + off, np.nan)
    count = use.sum(axis=1)
    pred = np.full((len(X), 3), np.nan)
    ok = count >= min_neighbours
    if np.any(ok):
        c = cand[ok]
        # Median via sort: NaNs sort last, so the middle of the first `count` entries.
        srt = np.sort(c, axis=1)
        n = count[ok]
        lo = (n - 1) // 2
        hi = n // 2
        r = np.arange(len(c))
        pred[ok] = 0.5 * (srt[r, lo] + srt[r, hi])
    return pred, count
