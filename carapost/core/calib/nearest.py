"""Nearest detection of each projected point, with the clearance to the next one."""
from __future__ import annotations

import numpy as np


def nearest_with_clearance(d: np.ndarray, pool: np.ndarray | None = None):
    """Per row, the nearest column and the distance to the next nearest.

    Parameters
    ----------
    d : ndarray (n, m)
        Distances from n projected points to m detections (``inf`` where unusable).
    pool : ndarray (n, m), optional
        Distances the nearest is chosen from (e.g. ``d`` with taken detections at
        ``inf``); the clearance is still measured on ``d``, so a crowded spot stays
        ambiguous even when its other detections are taken.

    Returns
    -------
    best : ndarray (n,) int
    best_d : ndarray (n,)
    second_d : ndarray (n,)
        Distance to the nearest other detection in ``d``.
    """
    pool = d if pool is None else pool
    rows = np.arange(len(d))
    best = np.argmin(pool, axis=1)
    best_d = pool[rows, best]
    rest = d.copy()
    rest[rows, best] = np.inf
    return best, best_d, rest.min(axis=1)
