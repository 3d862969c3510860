"""Picking a lost point up again from detections that agree in 3D.

While a marker is lost its point keeps only a prediction from its neighbours,
and a jaw that opens meanwhile leaves that prediction millimetres off (the
lower lip's neighbours are half on the jaw, half on the upper lip): the 2D
nearest-detection search then finds nothing unambiguous and the point stays
lost until the jaw closes again.  Here every free detection near the
prediction in every camera is a candidate, and a hypothesis is a set of views
whose rays meet: a stray blob or another marker's blob rarely lies on the
epipolar lines of the right ones.  The hypothesis seen by the most cameras
wins; one seen by only two is taken only when nothing else fits.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from .geometry import RigState, reprojection, triangulate


def best_views(rig: RigState, cand_xy: list[np.ndarray], limit: float,
               min_views: int = 3) -> tuple[np.ndarray, np.ndarray] | None:
    """The views of one lost point whose rays agree best.

    Parameters
    ----------
    rig : RigState
        Cameras of the frame.
    cand_xy : list of ndarray
        Per sensor, the candidate detections' corrected pixels ``(k_s, 2)``
        (empty arrays for sensors without candidates).
    limit : float
        Largest reprojection error (px) of any view of an accepted hypothesis.
    min_views : int
        Fewest agreeing cameras to accept (2: a unique pair is enough).

    Returns
    -------
    (choice, X) or None
        ``choice`` (S,) index into each sensor's candidates (-1: that sensor is
        not used) and the triangulated point; None when no hypothesis has
        ``min_views`` agreeing cameras, or the best is ambiguous.
    """
    S = rig.S
    pairs = []
    for a, b in combinations(range(S), 2):
        na, nb = len(cand_xy[a]), len(cand_xy[b])
        if na and nb:
            ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
            pairs.append((a, b, ia.ravel(), ib.ravel()))
    if not pairs:
        return None
    H = sum(len(p[2]) for p in pairs)
    choice = np.full((H, S), -1)
    uv = np.full((H, S, 2), np.nan)
    row = 0
    for a, b, ia, ib in pairs:
        n = len(ia)
        choice[row:row + n, a], choice[row:row + n, b] = ia, ib
        uv[row:row + n, a] = cand_xy[a][ia]
        uv[row:row + n, b] = cand_xy[b][ib]
        row += n
    valid = choice >= 0
    X = triangulate(rig, uv, valid)
    err = reprojection(rig, X, uv, valid)
    ok = np.all(np.where(valid, err, 0.0) <= limit, axis=1) & np.all(np.isfinite(X), axis=1)
    if not np.any(ok):
        return None
    choice, uv, X = choice[ok], uv[ok], X[ok]
    # Add every other camera's nearest candidate that fits the hypothesis.
    proj = rig.project(X)
    for s in range(S):
        if not len(cand_xy[s]):
            continue
        free = choice[:, s] < 0
        d = np.linalg.norm(proj[:, s, None, :] - cand_xy[s][None], axis=2)
        j = np.argmin(d, axis=1)
        add = free & (d[np.arange(len(j)), j] <= limit)
        choice[add, s] = j[add]
        uv[add, s] = cand_xy[s][j[add]]
    valid = choice >= 0
    X = triangulate(rig, uv, valid)
    err = reprojection(rig, X, uv, valid)
    fits = np.all(np.where(valid, err, 0.0) <= limit, axis=1)
    views = np.where(fits, valid.sum(1), 0)
    if views.max() < max(2, min_views):
        return None
    top = np.flatnonzero(views == views.max())
    # Hypotheses with the most views that use other detections: the choice is ambiguous.
    if not np.all(choice[top] == choice[top[0]], axis=1).all():
        return None
    return choice[top[0]], X[top[0]]
