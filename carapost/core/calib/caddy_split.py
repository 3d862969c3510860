"""A point whose two caddies disagree: the caddy with the larger blobs gives way.

A dot beside a brow or a shadow can be merged with it in both cameras of one
caddy: the two blobs are pulled the same way, along that caddy's short
baseline, so they still agree with each other, and leave-one-out (which needs
the other views to agree) cannot tell which views are wrong.  The other caddy
looks from the side, where the pull crosses its epipolar lines: every pair of
views across the caddies then misses its epipolar line by more than blob noise
(clean points: 99 % within 0.12 px on sample takes).  Two against two, the
geometry cannot say which caddy is right; the blob size can, as a merged blob
is larger than the dot.
"""
from __future__ import annotations

import numpy as np

from ..camera import symmetric_epipolar_distance

#: Every cross-caddy pair of a point's views farther than this (px) from its epipolar line: the caddies disagree.
SPLIT_PX = 0.5
#: The caddy whose blobs are on average this many times larger than the other's gives way.
SPLIT_SIZE = 1.1


def caddy_split(cams, uv: np.ndarray, size: np.ndarray, caddies) -> np.ndarray:
    """Views to detach from points whose two caddies disagree.

    Parameters
    ----------
    cams : list of Camera
    uv : ndarray (N, S, 2)
        Raw pixels, NaN where a point has no view.
    size : ndarray (N, S)
        Each view's blob size (any unit common to all views, e.g. mm at the
        point's depth); NaN where unknown.
    caddies : list of (int, int)

    Returns
    -------
    ndarray of bool (N, S)
        For a point seen by both cameras of two caddies, whose cross-caddy view
        pairs all miss their epipolar lines by more than :data:`SPLIT_PX`, the
        views of the caddy whose mean blob size is :data:`SPLIT_SIZE` times the
        other's; nothing where the sizes do not say.
    """
    n, S = uv.shape[:2]
    bad = np.zeros((n, S), bool)
    seen = np.isfinite(uv[..., 0])
    for i, ca in enumerate(caddies):
        for cb in caddies[i + 1:]:
            rows = np.flatnonzero(seen[:, list(ca)].all(1) & seen[:, list(cb)].all(1))
            if not len(rows):
                continue
            cross = np.stack([symmetric_epipolar_distance(cams[a], uv[rows, a], cams[b], uv[rows, b])
                              for a in ca for b in cb], axis=1)
            split = rows[np.all(cross > SPLIT_PX, axis=1)]
            for r in split:
                sa, sb = np.mean(size[r, list(ca)]), np.mean(size[r, list(cb)])
                if not (sa > 0 and sb > 0):         # NaN or no sizes (detections imported without them)
                    continue
                if sa >= SPLIT_SIZE * sb:
                    bad[r, list(ca)] = True
                elif sb >= SPLIT_SIZE * sa:
                    bad[r, list(cb)] = True
    return bad
