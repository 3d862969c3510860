"""Initialize 3D across the caddies: markers that one camera of each caddy sees, and no caddy sees whole.

The guide grows matches per caddy, so a marker seen by only one camera of each
caddy (a brow dot lost in the hair of the other two views, a nose tip merged
with the nostrils' shadow in one camera of each caddy) is never made.  Once the
caddies' points are bundled the cameras are known to a fraction of a pixel, and the long baseline
between the caddies makes their epipolar lines cross steeply: the leftover
detections of one camera of each caddy are matched here under the same rules
as within a caddy (clear choice of both detections, near the points grown so
far), with a tighter epipolar gate, no point closer to an existing one than
the caddies' merge distance (that is the same marker), and blobs of a marker's
size.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..camera import symmetric_epipolar_distance, triangulate_many
from .blob_size import enlarged_pair, gross_views
from .matching import CLEAR_RATIO, unambiguous


def cross_pairs(caddies) -> list[tuple[int, int]]:
    """Every pair of cameras on two different caddies."""
    out = []
    for i, ca in enumerate(caddies):
        for cb in caddies[i + 1:]:
            out += [(a, b) for a in ca for b in cb]
    return out


def grow_across(cams, xy, free, caddies, points_X, max_depth: float, min_gap: float, gate: float,
                size_ratio=None, far_depth: float | None = None) -> list[tuple[int, int, int, int, np.ndarray]]:
    """Two-view points from free detections of cameras on different caddies.

    Parameters
    ----------
    cams : list of Camera
        Bundled cameras.
    xy : list of ndarray (N_s, 2)
        Every camera's detections (raw px).
    free : list of ndarray of bool (N_s,)
        Detections no point holds and none of the exclusions (brim, merged
        blobs) applies to; updated in place as pairs are taken.
    caddies : list of (int, int)
    points_X : ndarray (K, 3)
        The points so far.
    max_depth : float
        Max Allowed Depth (mm): a new point lies this close to a point so far.
    min_gap : float
        Max 3D Distance To Merge (mm): a new point closer than this to a point
        so far would be the same marker.
    gate : float
        Largest symmetric epipolar distance (px) of a pair.
    size_ratio : callable, optional
        ``size_ratio(cam, det, X) -> (n,)`` blob size over the typical marker
        size; pairs with a merged blob
        (:func:`~carapost.core.calib.blob_size.gross_views`) or two enlarged
        ones (:func:`~carapost.core.calib.blob_size.enlarged_pair`) are not
        made.
    far_depth : float, optional
        Once growth within ``max_depth`` stops, pairs up to this far (mm) from
        the points are made when each of their detections has no other
        candidate within ``CLEAR_RATIO * gate``: a marker sparser than Max
        Allowed Depth (a nose tip on a 100-marker face with the dense set's
        16 mm, seen by one camera of each caddy).

    Returns
    -------
    list of (cam_a, det_a, cam_b, det_b, X)
    """
    out = []
    pts = [np.asarray(points_X, float).reshape(-1, 3)]
    reach, far = max_depth, False
    while True:
        taken = 0
        for a, b in cross_pairs(caddies):
            fa, fb = np.flatnonzero(free[a]), np.flatnonzero(free[b])
            if not len(fa) or not len(fb) or not sum(len(p) for p in pts):
                continue
            D = symmetric_epipolar_distance(cams[a], xy[a][fa][:, None], cams[b], xy[b][fb][None])
            wide = D <= CLEAR_RATIO * gate
            ia, ib = np.nonzero(D <= gate)
            if not len(ia):
                continue
            X = triangulate_many([cams[a], cams[b]], np.stack([xy[a][fa[ia]], xy[b][fb[ib]]], axis=1), refine=False)
            ok = np.all(np.isfinite(X), axis=1)
            ok[ok] &= (cams[a].depth(X[ok]) > 0) & (cams[b].depth(X[ok]) > 0)
            ia, ib, X, d = ia[ok], ib[ok], X[ok], D[ia[ok], ib[ok]]
            # Clear among every geometrically possible pair, before the distance test (as within a caddy).
            clear = unambiguous(ia, ib, d)
            near = cKDTree(np.concatenate(pts)).query(X)[0] if len(X) else np.zeros(0)
            if far:
                clear &= (wide.sum(axis=1)[ia] == 1) & (wide.sum(axis=0)[ib] == 1)
            acc = np.flatnonzero(clear & (near <= reach) & (near >= min_gap))
            if size_ratio is not None and len(acc):
                ra = size_ratio(a, fa[ia[acc]], X[acc])
                rb = size_ratio(b, fb[ib[acc]], X[acc])
                acc = acc[[not (gross_views([u, v]).any() or enlarged_pair([u, v])) for u, v in zip(ra, rb)]]
            for j in acc:
                out.append((a, int(fa[ia[j]]), b, int(fb[ib[j]]), X[j]))
            free[a][fa[ia[acc]]] = False
            free[b][fb[ib[acc]]] = False
            if len(acc):
                pts.append(X[acc])
            taken += len(acc)
        if not taken:
            if far or far_depth is None or far_depth <= max_depth:
                return out
            reach, far = far_depth, True
