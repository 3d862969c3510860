"""Points for markers that no point follows.

A marker hidden when Initialize 3D ran (under hair, at a grazing angle on the
chin, behind the lip) has no point, and tracking never gives it one: its row is
missing from the Continuity chart for the whole take.  While tracking, the
detections no point took are matched across the cameras here.  A match is a
candidate when its rays meet, when it lies on the face (near the plane of its
nearest tracked points, within reach of them), when it keeps clear of every
point (tracked, or a lost one's prediction: a lost marker coming back is picked
up by its own point, not given another) and of the brim, when no other match
contests its detections, and when its blobs look like the markers' (classifier
score, size in mm, and with images the contrast against the skin: the skin's
freckles and an eye's highlight match across cameras too).  The tracker makes a
point of a candidate only once the next frame finds it again where its
neighbours carried it (:meth:`.engine.FrameTracker._add_new_markers`).
"""
from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree

from ..camera import fundamental_matrix
from .geometry import RigState, reprojection, triangulate

#: Largest reprojection error (px) of any view of a candidate: blob centres are good to a tenth of a pixel.
LIMIT_PX = 1.0
#: Nearest tracked points whose plane a candidate must lie near, and how near: SURFACE_MM, or this share of
#: their spacing where the face curves more between them.
SURFACE_NEIGHBOURS = 6
SURFACE_MM = 2.0
SURFACE_SHARE = 0.2
#: A candidate nearer a point than this share of the point's spacing (mean distance to its nearest
#: neighbours) is that point's marker.
APART = 0.5
#: ...and one whose nearest tracked points are farther than this many times their spacing is not on the
#: tracked face (a stray match far in front of it or behind it).
REACH = 2.0
#: Nearer a brim marker than this (mm): a brim dot the brim solve did not take.
BRIM_MM = 5.0
#: Every view's classifier score at least this: a new point starts only from blobs that are surely dots (a
#: faint brow dot's blob merged with the hair scores 0.4-0.5 in one view).
MIN_SCORE = 0.9
#: The views' mean size (the major axis in mm at the match's depth, which an oblique view does not shorten)
#: within these times the markers' typical size: a freckle of the skin is a dark dot too, half a marker's size
#: (the markers' views measure 0.68-2.6 times the median, 1 % of them under 0.8).
SIZE_RANGE = (0.75, 1.4)


def _pairs(rig: RigState, xy: list[np.ndarray], limit: float) -> np.ndarray:
    """Every two-camera match of free detections whose epipolar distance is within ``limit``: choice (H, S)."""
    S = rig.S
    rows = []
    cams = rig.to_cameras()
    for a, b in combinations(range(S), 2):
        na, nb = len(xy[a]), len(xy[b])
        if not na or not nb:
            continue
        F = fundamental_matrix(cams[a], cams[b])
        ha = np.column_stack([xy[a], np.ones(na)])
        hb = np.column_stack([xy[b], np.ones(nb)])
        lb = ha @ F.T                                   # lines in b of a's detections (na, 3)
        la = hb @ F                                     # lines in a of b's detections (nb, 3)
        num = np.abs(hb @ lb.T).T                       # (na, nb)
        d = 0.5 * num * (1.0 / np.hypot(lb[:, 0], lb[:, 1])[:, None] + 1.0 / np.hypot(la[:, 0], la[:, 1])[None])
        ia, ib = np.nonzero(d <= limit)
        if len(ia):
            c = np.full((len(ia), S), -1)
            c[:, a], c[:, b] = ia, ib
            rows.append(c)
    return np.concatenate(rows) if rows else np.zeros((0, S), int)


def _uv(xy: list[np.ndarray], choice: np.ndarray) -> np.ndarray:
    uv = np.full(choice.shape + (2,), np.nan)
    for s in range(choice.shape[1]):
        use = choice[:, s] >= 0
        uv[use, s] = xy[s][choice[use, s]]
    return uv


def _fit(rig: RigState, xy: list[np.ndarray], choice: np.ndarray, limit: float):
    """Triangulate each choice; (X, ok) where every view reprojects within ``limit``."""
    uv = _uv(xy, choice)
    valid = choice >= 0
    X = triangulate(rig, uv, valid)
    err = reprojection(rig, X, uv, valid)
    ok = np.all(np.isfinite(X), axis=1) & np.all(np.where(valid, err, 0.0) <= limit, axis=1)
    return X, ok


def surface_distance(X: np.ndarray, tracked: np.ndarray, k: int = SURFACE_NEIGHBOURS):
    """Distance (mm) of each point of ``X`` from the plane of its ``k`` nearest ``tracked`` points, and their
    mean distance from it."""
    k = min(k, len(tracked))
    d, idx = cKDTree(tracked).query(X, k=k)
    d, idx = d.reshape(len(X), k), idx.reshape(len(X), k)
    nb = tracked[idx]                                            # (n, k, 3)
    centre = nb.mean(axis=1)
    _, _, vt = np.linalg.svd(nb - centre[:, None], full_matrices=False)
    normal = vt[:, -1]
    return np.abs(np.einsum("ni,ni->n", X - centre, normal)), d.mean(axis=1)


#: With images: the views' mean contrast (:func:`dot_contrast`) at least this share of the frame's markers'
#: median (:func:`stands_out`): a freckle of the skin matches across cameras like a dot, and its blob scores
#: 0.95 and more, but it stands out from the skin 0.25-0.36 where the markers' median is 0.84.
MIN_CONTRAST = 0.5
#: Marker views per camera the median contrast is taken over.
CONTRAST_SAMPLE = 40


def stands_out(images: list, choice: np.ndarray, cand_xy: list[np.ndarray], cand_major: list[np.ndarray],
               ref_xy: list[np.ndarray], ref_major: list[np.ndarray]) -> np.ndarray:
    """Which candidates' blobs stand out from the skin as the markers' do (:data:`MIN_CONTRAST`).

    Parameters
    ----------
    images : list
        Per sensor, ``() -> (H, W) image`` of this frame (called only for the sensors candidates use).
    choice : ndarray (n, S)
        The candidates' detections (-1: none) in ``cand_xy`` and ``cand_major`` (raw px, px) per sensor.
    ref_xy, ref_major : list of ndarray
        Per sensor, the blob views of measured points (raw px, px): up to :data:`CONTRAST_SAMPLE` are read.
    """
    n, S = choice.shape
    share = np.zeros((n, S))
    used = choice >= 0
    for s in np.flatnonzero(used.any(0)):
        img = images[s]()
        step = max(1, len(ref_xy[s]) // CONTRAST_SAMPLE)
        ref = np.nanmedian(dot_contrast(img, ref_xy[s][::step], ref_major[s][::step])) if len(ref_xy[s]) else np.nan
        rows = np.flatnonzero(used[:, s])
        j = choice[rows, s]
        share[rows, s] = dot_contrast(img, cand_xy[s][j], cand_major[s][j]) / ref
    share = np.where(used & np.isfinite(share), share, 0.0)
    counted = (used & (share > 0)).sum(1)
    return share.sum(1) >= MIN_CONTRAST * np.maximum(counted, 1)


def view_depth(rig: RigState, X: np.ndarray) -> np.ndarray:
    """``(n, S)`` depth (mm) of points ``X`` in every camera."""
    return np.einsum("sj,nsj->ns", rig.R[:, 2], X[:, None] - rig.C[None])


def candidates(rig: RigState, xy: list[np.ndarray], tracked: np.ndarray, known: np.ndarray,
               known_spacing: np.ndarray, brim: np.ndarray | None = None, limit: float = LIMIT_PX,
               blobs: list[np.ndarray] | None = None, marker_mm: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Matches of free detections that could be markers no point follows (module docstring).

    Parameters
    ----------
    rig : RigState
        The frame's cameras.
    xy : list of ndarray
        Per sensor, the free detections' corrected pixels ``(k_s, 2)``.
    tracked : ndarray (M, 3)
        The points measured on this frame (the face's surface).
    known : ndarray (K, 3)
        Where every point is on this frame: measured, or a lost point's prediction (NaN: unknown).
    known_spacing : ndarray (K,)
        Each of those points' spacing (mm): the mean distance to its nearest neighbours.
    brim : ndarray (B, 3), optional
        Brim markers (world).
    limit : float
        Largest epipolar distance and reprojection error (px) of a view.
    blobs : list of ndarray, optional
        Per sensor, the free detections' ``(major px, score)`` ``(k_s, 2)``: with ``marker_mm``, the
        markers' typical size, matches of blobs unlike a marker's (:data:`MIN_SCORE`, :data:`SIZE_RANGE`)
        are left out.

    Returns
    -------
    (choice, X)
        ``choice`` (n, S): each candidate's detection in each sensor's ``xy`` (-1: none); ``X`` (n, 3).
    """
    S = rig.S
    none = (np.zeros((0, S), int), np.zeros((0, 3)))
    if len(tracked) < SURFACE_NEIGHBOURS:
        return none
    choice = _pairs(rig, xy, limit)
    if not len(choice):
        return none
    X, ok = _fit(rig, xy, choice, limit)
    choice, X = choice[ok], X[ok]
    # Other cameras' free detections at the match's projection join it.
    if len(choice):
        proj = rig.project(X)
        for s in range(S):
            if not len(xy[s]):
                continue
            free = choice[:, s] < 0
            d, j = cKDTree(xy[s]).query(np.nan_to_num(proj[:, s], nan=1e9))
            add = free & (d <= limit)
            if np.any(add):
                grown = choice.copy()
                grown[add, s] = j[add]
                Xg, okg = _fit(rig, xy, grown, limit)
                take = add & okg
                choice[take], X[take] = grown[take], Xg[take]
    if not len(choice):
        return none
    choice, first = np.unique(choice, axis=0, return_index=True)
    X = X[first]
    # On the face, clear of every point and of the brim.
    spacing = float(np.median(known_spacing)) if len(known_spacing) else 10.0
    off_plane, reach = surface_distance(X, tracked)
    keep = (off_plane <= np.maximum(SURFACE_MM, SURFACE_SHARE * reach)) & (reach <= REACH * spacing)
    have = np.all(np.isfinite(known), axis=1)
    if np.any(have):
        d, i = cKDTree(known[have]).query(X)
        keep &= d >= APART * known_spacing[have][i]
    if brim is not None and len(brim):
        keep &= cKDTree(brim).query(X)[0] >= BRIM_MM
    if blobs is not None and marker_mm and len(choice):
        used = choice >= 0
        major, score = np.zeros(choice.shape), np.ones(choice.shape)
        for s in range(S):
            major[used[:, s], s], score[used[:, s], s] = blobs[s][choice[used[:, s], s]].T
        size = (major * view_depth(rig, X) / rig.K[:, 0, 0]).sum(1) / used.sum(1) / marker_mm
        keep &= np.all(np.where(used, score, 1.0) >= MIN_SCORE, axis=1)
        keep &= (size >= SIZE_RANGE[0]) & (size <= SIZE_RANGE[1])
    choice, X = choice[keep], X[keep]
    # Uncontested: a detection two candidates use goes to the one with more views, or to neither.
    views = (choice >= 0).sum(1)
    win = np.ones(len(choice), bool)
    for s in range(S):
        for j in np.unique(choice[:, s][choice[:, s] >= 0]):
            users = np.flatnonzero(choice[:, s] == j)
            if len(users) > 1:
                top = views[users].max()
                best = users[views[users] == top]
                win[users[views[users] < top]] = False
                if len(best) > 1:
                    win[best] = False
    return choice[win], X[win]


#: A candidate of the last frame, carried by its nearest measured points, confirms one of this frame within
#: this distance (mm).
AGREE_MM = 1.0


def nearest(points: np.ndarray, X: np.ndarray, k: int) -> np.ndarray:
    """``(n, k)`` indices into ``points`` of each of ``X``'s ``k`` nearest."""
    k = min(k, len(points))
    return cKDTree(points).query(X, k=k)[1].reshape(len(X), k)


def carried_to(X_last: np.ndarray, nbr: np.ndarray, nbr_last: np.ndarray, X_now: np.ndarray,
               candidates_now: np.ndarray) -> np.ndarray:
    """Which of this frame's candidates the last frame's found too.

    Parameters
    ----------
    X_last : ndarray (m, 3)
        The last frame's candidates.
    nbr : ndarray (m, k)
        Their nearest measured points (rows of the tracked set) ...
    nbr_last : ndarray (m, k, 3)
        ... and where those were then.
    X_now : ndarray (N, 3)
        Every tracked point on this frame (NaN: not measured).
    candidates_now : ndarray (n, 3)

    Returns
    -------
    ndarray (n,) bool
        Within :data:`AGREE_MM` of a last-frame candidate moved by the mean motion of its neighbours.
    """
    out = np.zeros(len(candidates_now), bool)
    if not len(X_last) or not len(candidates_now):
        return out
    step = X_now[nbr] - nbr_last                                          # (m, k, 3), NaN: not measured now
    have = np.all(np.isfinite(step), axis=2)
    count = have.sum(1)
    move = np.where(have[..., None], step, 0.0).sum(1) / np.maximum(count, 1)[:, None]
    carried = np.where((count > 0)[:, None], X_last + move, np.nan)
    ok = np.all(np.isfinite(carried), axis=1)
    if not np.any(ok):
        return out
    d = cKDTree(carried[ok]).query(candidates_now)[0]
    return d <= AGREE_MM


def dot_contrast(image: np.ndarray, xy: np.ndarray, major: np.ndarray) -> np.ndarray:
    """How far each blob's middle stands out from the skin around it, relative to the brighter of the two.

    Parameters
    ----------
    image : ndarray (H, W)
        The camera's raw image.
    xy : ndarray (k, 2)
        Blob centres (raw px).
    major : ndarray (k,)
        Their major axes (px).

    Returns
    -------
    ndarray (k,)
        ``|ring - middle| / max(ring, middle)``, the ring the median 0.9-1.3 major axes out, the middle the mean
        within a quarter of one: black paint takes the same share of the light on lit and on shaded skin, and
        white paint gives back the same share more; NaN at the border.
    """
    H, W = image.shape[:2]
    out = np.full(len(xy), np.nan)
    for i, ((x, y), a) in enumerate(zip(xy, major)):
        r = int(np.ceil(1.3 * a)) + 1
        cx, cy = int(round(x)), int(round(y))
        if cx - r < 0 or cy - r < 0 or cx + r >= W or cy + r >= H or not np.isfinite(a):
            continue
        win = image[cy - r:cy + r + 1, cx - r:cx + r + 1].astype(float)
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        d = np.hypot(xx + cx - x, yy + cy - y)
        inner = win[d <= max(0.25 * a, 1.0)]
        ring = win[(d >= 0.9 * a) & (d <= 1.3 * a)]
        if len(inner) and len(ring):
            skin = float(np.median(ring))
            out[i] = abs(skin - float(inner.mean())) / max(skin, float(inner.mean()), 1.0)
    return out
