"""Blob sizes in millimetres: which detections are too large to be a marker's centre.

A painted marker has one physical size, so its blob's major axis (px) times its
depth over the focal length is about the same millimetres all over the face,
whatever the camera's distance (the major axis is not foreshortened by an
oblique view).  A blob far larger than that is a dot merged with something
beside it (the shadow under the nose, brow hair), and its centre is pulled off
the dot by an unknown amount.
"""
from __future__ import annotations

import numpy as np

#: A blob this many times the frame's typical marker size (mm) is a dot merged with its surroundings:
#: its centre is not the dot's (a nose tip merged with the nostrils' shadow measures 3-3.5 times a
#: marker, and its centre lies 6 px off; clean markers measure up to about 2.2 times on sample takes).
GROSS_SIZE = 2.5
#: A point seen by two cameras only, whose two blobs are both this many times the typical size, is not
#: trusted: nothing checks two pulled centres against each other (a faint brow dot merged with the brow
#: hair in both views put a two-view point 0.6 mm off; two-view points of the right marker measure <= 1.43 times).
ENLARGED_SIZE = 1.5


def view_sizes_mm(cams, recs, pts) -> np.ndarray:
    """The size (mm) of each point's blob in each camera, at the point's depth.

    Parameters
    ----------
    cams : list of Camera
    recs : list of ndarray
        Each camera's detection records (``major`` in px).
    pts : list of dict
        Points (``det`` (S,) detection index or -1, ``X`` (3,)).

    Returns
    -------
    ndarray (N, S)
        NaN where a point holds no detection.
    """
    S = len(cams)
    out = np.full((len(pts), S), np.nan)
    if not pts:
        return out
    X = np.array([d["X"] for d in pts], float)
    det = np.array([d["det"] for d in pts], int)
    for s in range(S):
        rows = np.flatnonzero((det[:, s] >= 0) & (det[:, s] < len(recs[s])))
        if len(rows):
            major = np.asarray(recs[s]["major"], float)[det[rows, s]]
            out[rows, s] = major * cams[s].depth(X[rows]) / cams[s].focal_length
    return out


def blob_sizes_mm(cams, recs, pts) -> tuple[list[np.ndarray], float]:
    """Every detection's size in mm, and the frame's typical marker size.

    Parameters are those of :func:`view_sizes_mm`: a detection held by a point
    is measured at that point's depth, any other at the median depth of the
    camera's points.

    Returns
    -------
    sizes : list of ndarray
        Per camera, one size (mm) per detection; NaN where no depth is known.
    typical : float
        The median size of the detections the points hold (NaN without any).
    """
    held = view_sizes_mm(cams, recs, pts)
    typical = np.nanmedian(held) if np.any(np.isfinite(held)) else np.nan
    sizes = []
    for s, cam in enumerate(cams):
        n = len(recs[s])
        rows = [k for k, d in enumerate(pts) if 0 <= d["det"][s] < n]
        depth = np.full(n, np.nan)
        if rows:
            idx = np.array([pts[k]["det"][s] for k in rows])
            depth[:] = np.median(cam.depth(np.array([pts[k]["X"] for k in rows], float)))
        sz = np.asarray(recs[s]["major"], float) * depth / cam.focal_length
        if rows:
            sz[idx] = held[rows, s]
        sizes.append(sz)
    return sizes, float(typical)


def gross_views(ratio) -> np.ndarray:
    """Which views' blobs are dots merged with their surroundings (:data:`GROSS_SIZE`).

    Parameters
    ----------
    ratio : array_like (V,)
        Each view's blob size over the typical marker size (NaN: unknown, kept).
    """
    return np.asarray(ratio, float) > GROSS_SIZE


def enlarged_pair(ratio) -> bool:
    """Whether a two-view point's blobs are both enlarged (:data:`ENLARGED_SIZE`): nothing checks their centres.

    Parameters
    ----------
    ratio : array_like (V,)
        Each of the point's views' blob size over the typical marker size.
    """
    ratio = np.asarray(ratio, float)
    return len(ratio) == 2 and bool(np.all(ratio > ENLARGED_SIZE))


def pulled_views(ratio, caddies, margin: float) -> np.ndarray:
    """The view of each point whose blob is enlarged and clearly the point's largest, where it can be spared.

    A dot merged with brow hair in three cameras of four has three pulled centres
    that still fit one another within a pixel (the hair lies beside the dot in 3D,
    so the pulls are alike), and leave-one-out finds no odd view while the point
    sits a millimetre off.  The largest blob is the one pulled farthest: it is left
    out when the point keeps three views on both caddies without it.  (A three-view
    point is left alone: a blob 1.9 times a marker whose centre was good left a
    cross-caddy pair 0.28 mm off instead of 0.13 mm.)

    Parameters
    ----------
    ratio : array_like (N, S)
        Each view's blob size over the typical marker size; NaN where a point has no view.
    caddies : list of (int, int)
    margin : float
        The enlarged blob must be this many times the point's next largest.

    Returns
    -------
    ndarray of bool (N, S)
        At most one view of each point with four views or more: one larger than
        :data:`ENLARGED_SIZE` times the typical marker and ``margin`` times the
        point's next blob.
    """
    ratio = np.asarray(ratio, float)
    seen = np.isfinite(ratio)
    r = np.where(seen, ratio, 0.0)
    out = np.zeros(ratio.shape, bool)
    if not ratio.size:
        return out
    top = np.argmax(r, axis=1)
    order = np.sort(r, axis=1)
    rows = np.flatnonzero((order[:, -1] > ENLARGED_SIZE) & (order[:, -2] > 0)
                          & (order[:, -1] > margin * order[:, -2]))
    rest = seen[rows].copy()
    rest[np.arange(len(rows)), top[rows]] = False
    spans = sum(rest[:, list(cad)].any(axis=1).astype(int) for cad in caddies)
    keep = rows[(np.asarray(spans) >= 2) & (rest.sum(axis=1) >= 3)] if len(rows) else rows
    out[keep, top[keep]] = True
    return out
