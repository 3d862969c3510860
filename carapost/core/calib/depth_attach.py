"""A point of one caddy's pair takes the other caddy's view along its uncertain depth.

The two cameras of a caddy are a few centimetres apart: a point seen by them alone
is placed well across their rays and badly along them (about 2 mm of depth per
pixel of detection error, `docs/calibration.md`).  Its projection into a camera of
the other caddy can then miss the marker's blob there by more than the attach gate,
although the blob lies on the projection of the point's line of sight.  Here each
such point looks for its blob along the projection of its depth range, and takes it
when it is the only detection near that segment.
"""
from __future__ import annotations

import numpy as np

#: Depth (mm) either side of a one-caddy point along which its other-caddy view is looked for: about
#: 2.5 px of detection error in a caddy's pair.  3 mm missed a brow dot whose blob in one camera had grown
#: into the hair, 2.7 px off: its pair lay 3.9 mm deep (the sample's 156 black markers, seed 0, frame 299).
DEPTH_MM = 5.0
#: A detection within this distance (px) of the segment is on it: such a grown blob is off across the
#: epipolar line too (that brow dot's other-caddy blob lay 1.6 px from the segment, and 1.74 px once the
#: detector's step 7 placed that clean blob 0.14 px along its axis, session 34).
ALONG_PX = 2.0
#: No other detection may lie within this distance (px) of the segment.
ALONG_CLEAR_PX = 4.0


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points ``p`` (n, 2) to the segment ``a``-``b``."""
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def attach_along_depth(pts: list, cams, xy: list, blocked: list, caddies) -> list:
    """Give each one-caddy two-view point the other caddy's detection on the projection of its depth range.

    Parameters
    ----------
    pts : list of dict
        Points (``det`` (S,) detection index or -1, ``uv`` (S, 2) NaN where no view, ``X`` (3,)); changed in place.
    cams : list of Camera
    xy : list of ndarray
        Each camera's detection centres (raw px).
    blocked : list of ndarray of bool
        Detections that may not be used.
    caddies : list of (int, int)

    Returns
    -------
    list
        ``pts``.
    """
    S = len(cams)
    held = [np.zeros(len(xy[s]), bool) for s in range(S)]
    for d in pts:
        for s in range(S):
            if d["det"][s] >= 0:
                held[s][d["det"][s]] = True
    for d in pts:
        views = np.flatnonzero(np.isfinite(d["uv"][:, 0]))
        caddy = next((c for c in caddies if set(views.tolist()) == set(c)), None)
        if len(views) != 2 or caddy is None:
            continue
        X = np.asarray(d["X"], float)
        centre = np.mean([np.asarray(cams[s].position, float) for s in caddy], axis=0)
        sight = (X - centre) / max(np.linalg.norm(X - centre), 1e-9)
        for s in range(S):
            if s in caddy or len(xy[s]) == 0 or d["det"][s] >= 0:
                continue
            a, b = cams[s].project(np.array([X - DEPTH_MM * sight, X + DEPTH_MM * sight]))
            if not np.all(np.isfinite([a, b])):
                continue
            dist = _segment_distance(xy[s], a, b)
            on = np.flatnonzero(dist <= ALONG_PX)
            near = np.flatnonzero(dist <= ALONG_CLEAR_PX)
            if len(on) != 1 or len(near) != 1:
                continue
            i = int(on[0])
            if blocked[s][i] or held[s][i]:
                continue
            d["det"][s] = i
            d["uv"][s] = xy[s][i]
            held[s][i] = True
    return pts
