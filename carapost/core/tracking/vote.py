"""The neighbours' vote on each point's 2-D displacement, before the first matching pass.

A point's constant-velocity prediction is wrong when its region changes speed
at once: on a rendered take the jaw went from 1-2 to 7-9 mm a frame, every
lower-lip, chin and jaw prediction landed 5-15 px short, and a blob nearer the
prediction than the point's own was often the neighbour's ahead of it.  The
ratio test cannot see that (the neighbour's blob is alone near the
prediction), and neither can the anchor check: when every camera takes the
neighbour's blob the views meet at the neighbour.

What does see it is the region.  Its points moved together, so one
displacement puts all of them on their blobs, while the displacement to a
neighbour's blob puts the others on blobs only where the dots form a lattice.
So, per camera, each point's candidate displacements (staying put, and to its
few nearest detections) are scored by how many of its neighbours agree with
them: first through any detection of theirs at their own prediction plus that
displacement, then (the second round) through the one displacement each
neighbour believes in, so that chance agreements in a dense region do not add
up.  A detection that outvotes staying put clearly enough (a farther one the
nearest as well) becomes the prediction (a *nudge*), and the usual checks
follow.  Neighbours count by how steadily they have moved with the point
(:func:`.elastic.weights`), so a lower lip listens to the chin rather than to
the upper lip.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import JIT_EXACT
from .assign import candidates

#: Views with this many asked neighbours are asked too.
UNREST = 2
#: Candidate displacements per point and camera (its nearest detections).
K_VOTE = 8
#: Views whose nearest detection is within this (px) of the prediction are not put to the vote
#: (constant velocity is right to a pixel or two but for a sudden change of speed).
ASK_PX = 2.0
#: A neighbour's displacement agrees with a candidate to this scale (px): the jaw's displacement
#: changes by 3-5 px across a region of six neighbours (lower lip 11-14 px, chin 7-10).
AGREE_PX = 5.0
#: A candidate wins only with this much more support (in neighbours) than staying put (a farther one
#: than the nearest too)...
MARGIN = 0.5
#: ...and at least this much support (in neighbours).
MIN_SUPPORT = 1.5


def nudges(uv: np.ndarray, slots: np.ndarray, ask: np.ndarray, fd, radius: float, nb: np.ndarray,
           weight: np.ndarray) -> np.ndarray:
    """2-D corrections (N, S, 2) of the predicted projections ``uv`` the region's vote asks for (0: none).

    Parameters
    ----------
    uv : ndarray (N, S, 2)
        Predicted corrected pixels of each point in each camera.
    slots : ndarray (N, S) bool
        The views that may vote (seen on the previous frame).
    ask : ndarray (N, S) bool
        The views put to the vote (their nearest blob is more than :data:`ASK_PX` off, another is in reach);
        with them, every view with :data:`UNREST` of them among its neighbours.
    fd : FrameData
        The frame's detections (free ones are candidates).
    radius : float
        Search radius (px): the Face Point Tracking Distance.
    nb, weight : ndarray (N, K)
        Each point's neighbours (-1 none) and their weights (:func:`.elastic.weights`).
    """
    N, S = slots.shape
    out = np.zeros((N, S, 2))
    slots = slots & np.all(np.isfinite(uv), axis=2)
    ask = ask & slots
    if not np.any(ask) or fd.tree() is None:
        return out
    # A view on a blob in a region that moved is asked too: the neighbour's blob may have landed on it.
    around = np.where((nb >= 0)[:, :, None], ask[np.maximum(nb, 0)], False).sum(axis=1)
    ask |= slots & (around >= UNREST)
    # Candidates of the asked views and of their neighbours' views in the same camera.
    need = ask.copy()
    n, s = np.nonzero(ask)
    nbr = nb[n]
    has = nbr >= 0
    need[nbr[has], np.broadcast_to(s[:, None], nbr.shape)[has]] = True
    need &= slots
    rows, sens = np.nonzero(need)
    idx, _ = candidates(fd.tree(), fd.free, fd.shift(uv[rows, sens], sens), np.full(len(rows), radius), k=K_VOTE)
    xy = np.concatenate(fd.xy)
    off = np.full((N, S, K_VOTE, 2), np.nan)
    off[rows, sens] = np.where((idx >= 0)[..., None], xy[np.maximum(idx, 0)] - uv[rows, sens][:, None], np.nan)
    w = np.where(has, weight[n], 0.0)
    w = w / np.maximum(w.max(axis=1, keepdims=True), 1e-12)             # the steadiest neighbour counts 1
    # The prediction itself is candidate 0: where the neighbours sit on their blobs the region did not
    # move, and a view without a blob of its own (hidden, undetected) must not be sent onto another dot.
    mine = np.concatenate([np.zeros((len(n), 1, 2)), off[n, s]], axis=1)   # (g, 1 + K_VOTE, 2)
    theirs = off[np.maximum(nbr, 0), s[:, None]]                          # (g, K, K_VOTE, 2)
    support = _support(mine, theirs, w)
    # Round 2: each neighbour now votes for one displacement only, the one it believes in (its nearest
    # blob, or its own round-1 choice if it was asked and its neighbours had a say).  Among the many
    # blobs of a dense region some neighbour blob lies near almost any displacement; one vote each
    # leaves chance nothing to add up.
    belief = np.full((N, S, 2), np.nan)
    belief[rows, sens] = off[rows, sens, 0]
    first = np.argmax(support, axis=1)
    said = support[np.arange(len(n)), first] > 0                          # else no neighbour had a word
    belief[n[said], s[said]] = mine[np.flatnonzero(said), first[said]]
    theirs = belief[np.maximum(nbr, 0), s[:, None]]                       # (g, K, 2)
    support = _support(mine, theirs[:, :, None, :], w)
    best = np.argmax(support, axis=1)
    top = support[np.arange(len(n)), best]
    # A blob must outvote staying put, and a farther one the nearest blob too (what pass 1 would take).
    # The nearest blob that wins is moved onto as well: 14 px off, the ratio test alone is a coin toss.
    rival = np.where(best == 1, support[:, 0], support[:, :2].max(axis=1))
    win = (best > 0) & (top >= rival + MARGIN) & (top >= MIN_SUPPORT)
    out[n[win], s[win]] = mine[win, best[win]]
    return out


def _support(mine: np.ndarray, theirs: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(g, C) support of each candidate in ``mine`` (g, C, 2) from the neighbours' displacements ``theirs``
    (g, K, T, 2; NaN: none), weighted by ``w`` (g, K); -inf for a candidate that is not there.

    Each neighbour adds its weight times ``exp(-d² / (2 AGREE_PX²))``, ``d`` the distance from the
    candidate to the nearest of its displacements (nothing without one).
    """
    g, C = mine.shape[:2]
    out = np.empty((g, C))
    _support_loop(np.ascontiguousarray(mine), np.ascontiguousarray(theirs), np.ascontiguousarray(w),
                  2.0 * AGREE_PX ** 2, out)
    return out


@njit(**JIT_EXACT)
def _support_loop(mine, theirs, w, scale, out):
    """:func:`_support` as loops (the least squared distance over T ignoring NaN, as ``np.fmin``)."""
    G, C = mine.shape[0], mine.shape[1]
    K, T = theirs.shape[1], theirs.shape[2]
    for g in range(G):
        for c in range(C):
            if not np.isfinite(mine[g, c, 0]):
                out[g, c] = -np.inf
                continue
            acc = 0.0
            for k in range(K):
                best = np.nan
                for t in range(T):
                    dx = mine[g, c, 0] - theirs[g, k, t, 0]
                    dy = mine[g, c, 1] - theirs[g, k, t, 1]
                    d = dx * dx + dy * dy
                    if np.isnan(best) or d < best:
                        best = d
                if not np.isnan(best):
                    acc += np.exp(-best / scale) * w[g, k]
            out[g, c] = acc
