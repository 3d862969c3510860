"""A point's dot looked for again where a camera's detections have none (Tracking Parameters > Search Missing Views).

Blob detection looks at each image once, with no idea where the markers are; the
finest scale it searches is half the image's resolution.  A lower-lip dot against
the lit lip band with the jaw open, or a chin dot seen edge-on, is then often no
candidate at all (docs/blobs.md, "Known limits").  The tracker knows where each
point should be: for a point that fewer than two cameras detect near its
prediction, each camera without a detection there is searched again, in a crop
about the prediction enlarged twice (the detector's finest scale is then the
image's own pixels), at any score.  What it finds is kept only where it makes the
point whole: two or more cameras' dots (found or detected) that meet in 3-D near
the prediction, each within a fraction of a pixel of their point's projection.
The dots kept are added to the frame's detections and tracked as any blob
(docs/tracking-history.md, "Session 41").

Pure functions over images, cameras and arrays; :meth:`.engine.FrameTracker.step`
calls :func:`look_again`.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..detections import COLOR_WHITE, DET_DTYPE
from .geometry import RigState, reprojection, triangulate

#: A camera with a detection this close (raw px) to a point's projected prediction is not searched, and a
#: point is searched only where fewer than two cameras have one.
NEAR_PX = 3.0
#: Half-size (raw px) of each searched crop; dots are taken within :data:`REACH_PX` of its centre, so
#: that the crop's edge (the mosaic's seams) lies well beyond any dot taken.
TILE_R = 12
REACH_PX = 5.0
#: A found dot this close (raw px) to a detection is that detection.
SAME_PX = 1.5
#: The views of a point (found or detected) must meet within this (mm) of its prediction where three or more
#: cameras see it...
MEET_MM = 1.5
#: ...and within this where two do: two views meet wherever one lies near the other's epipolar line, and on
#: the rendered takes a pair's point was about as far from the marker as from the prediction (median 0.22 mm
#: within 0.25 mm of it, 0.46 at 0.5-0.75, 1.0 at 1-1.5; three or more views 0.15, 0.38, 0.49).  At 1.5 mm a
#: chin dot lost for two frames came back on a found dot 6.8 px off and another dot's blob, 2.5 mm off its
#: marker (docs/tracking-history.md, "Session 41").
PAIR_MEET_MM = 0.75
#: Each within this (px) of the projection of the point they make.
VIEW_PX = 0.35
#: The detector's threshold in the crops: any score (the lower-lip dots score 0.02-0.07).
SCORE = 1e-6
#: Full length limits of a found dot's major axis (raw px).
MIN_MAJOR, MAX_MAJOR = 2.0, 25.0


def searched(rig: RigState, uv_c: np.ndarray, near: np.ndarray, seen: np.ndarray) -> tuple:
    """Which views to search: ``(rows, sensors, raw uv)`` of the points projected to ``uv_c`` (N, S, 2).

    ``near`` (N, S) bool: a detection within :data:`NEAR_PX` of the projection.  ``seen`` (N, S) bool: the
    view had a blob on some frame before (a camera that never saw the marker is not searched).  Views whose
    crop would reach past the image's edge are not searched either.
    """
    want = (near.sum(1) < 2)[:, None] & ~near & seen & np.all(np.isfinite(uv_c), axis=2)
    rows, sens = np.nonzero(want)
    raw = np.zeros((len(rows), 2))
    for s in np.unique(sens):
        at = sens == s
        raw[at] = rig.cameras[s].distort(uv_c[rows[at], s])
    W, H = np.array([rig.cameras[s].sensor_size for s in range(rig.S)], float)[sens].T.reshape(2, -1)
    inside = np.all(np.isfinite(raw), axis=1) & (raw[:, 0] >= TILE_R) & (raw[:, 0] < W - TILE_R) \
        & (raw[:, 1] >= TILE_R) & (raw[:, 1] < H - TILE_R)
    return rows[inside], sens[inside], raw[inside]


def find_in_crops(images: list[np.ndarray], uv: np.ndarray, src: np.ndarray, white: bool,
                  learned_centres: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Dots near each of ``uv`` (n, 2) raw px in image ``images[src]``: one detection over a mosaic of crops.

    Each crop (``2 TILE_R + 1`` px square about its ``uv``) is enlarged twice; the mosaic of all of them, of
    every camera, is detected once (the detector's fixed cost, ~4 ms, would otherwise be paid per crop or per
    camera).

    ``learned_centres``: whether the detector's step 9 corrects the centres (Blob Parameters > Learned Centre
    Correction).

    Returns
    -------
    rec : ndarray of DET_DTYPE
        The dots within :data:`REACH_PX` of their crop's centre, in their image's raw px, the centre taken
        again from the dot's edge at the image's own resolution (and corrected by step 9).
    which : ndarray (len(rec),) int
        The index into ``uv`` each was found for.
    """
    from ..blobs import detect
    from ..blobs.centre_net import corrected_centres
    from ..blobs.detector import default_model
    from ..blobs.edges import refine_centres
    from ..blobs.features import noise_sigma

    n = len(uv)
    T = 2 * TILE_R + 1
    cols = int(np.ceil(np.sqrt(n)))
    rows = -(-n // cols)
    mosaic = np.zeros((rows * 2 * T, cols * 2 * T), np.uint8)
    origin = np.rint(uv).astype(int) - TILE_R
    for k in range(n):
        image = images[src[k]]
        H, W = image.shape
        ys = np.clip(np.arange(origin[k, 1], origin[k, 1] + T), 0, H - 1)
        xs = np.clip(np.arange(origin[k, 0], origin[k, 0] + T), 0, W - 1)
        r, c = divmod(k, cols)
        mosaic[r * 2 * T:(r + 1) * 2 * T, c * 2 * T:(c + 1) * 2 * T] = cv2.resize(
            image[np.ix_(ys, xs)], (2 * T, 2 * T), interpolation=cv2.INTER_CUBIC)
    rec = detect(mosaic, white=white, threshold=SCORE, min_major=2 * MIN_MAJOR, max_major=2 * MAX_MAJOR,
                 learned_centres=learned_centres)
    x2, y2 = rec["x"].astype(float), rec["y"].astype(float)
    c, r = (x2 // (2 * T)).astype(int), (y2 // (2 * T)).astype(int)
    k = r * cols + c
    tile = np.minimum(k, n - 1)                 # the mosaic's last row may have empty places (k >= n)
    # cv2.resize's pixel u of the enlarged crop is the crop's (u + 0.5) / 2 - 0.5.
    x = origin[tile, 0] + (x2 - c * 2 * T + 0.5) / 2.0 - 0.5
    y = origin[tile, 1] + (y2 - r * 2 * T + 0.5) / 2.0 - 0.5
    keep = (k < n) & (np.hypot(x - uv[tile, 0], y - uv[tile, 1]) <= REACH_PX)
    rec, k, x, y = rec[keep], k[keep], x[keep], y[keep]
    out = np.zeros(len(rec), DET_DTYPE)
    out["major"], out["minor"] = rec["major"].astype(float) / 2.0, rec["minor"].astype(float) / 2.0
    out["angle"], out["score"], out["color"] = rec["angle"], rec["score"], rec["color"]
    net = default_model(white).centre if learned_centres else None
    for i in np.unique(src[k]):
        at = src[k] == i
        image = images[i]
        bright = image if white else cv2.bitwise_not(image)
        # The enlarged crop's centres are 0.6-0.8 px off on lower-lip dots, their edge at the image's own
        # pixels 0.3 px (docs/tracking-history.md, "Session 38"); and the detector's step 9 there takes a fifth more
        # off (docs/tracking-history.md, "Session 41").
        o = out[at]
        o["x"], o["y"], _ = refine_centres(bright, x[at], y[at], o["major"], o["minor"], o["angle"], flat=not white,
                                           trust=np.zeros(len(o)))
        if net is not None:
            o["x"], o["y"] = corrected_centres(bright, o, noise_sigma(image), net)
        out[at] = o
    return out, k


def look_again(rig: RigState, images, X: np.ndarray, recs: list[np.ndarray], xy_c: list[np.ndarray],
               seen: np.ndarray, learned_centres: bool = True) -> list[np.ndarray] | None:
    """Dots the frame's detections lack that make points of ``X`` whole: records to add, per sensor.

    Parameters
    ----------
    rig : RigState
        The frame's cameras (solved from the brim).
    images : callable
        ``images(sensor) -> (H, W) uint8``: the frame's image of a camera.
    X : ndarray (N, 3)
        The points' predictions.
    recs : list of ndarray
        The frame's detections per sensor (raw px).
    xy_c : list of ndarray (n_s, 2)
        The same, in corrected px.
    seen : ndarray (N, S) bool
        Views that had a blob on some frame before.
    learned_centres : bool
        As :func:`find_in_crops`.

    Returns
    -------
    list of ndarray or None
        Per sensor, the records to append (DET_DTYPE); None when there are none.
    """
    S = rig.S
    N = len(X)
    if N == 0:
        return None
    uv_c = rig.project(X)
    near = np.zeros((N, S), bool)
    best = np.full((N, S, 2), np.nan)          # the nearest detection within REACH_PX (corrected px)
    for s in range(S):
        ok = np.all(np.isfinite(uv_c[:, s]), axis=1)
        if len(xy_c[s]) == 0 or not np.any(ok):
            continue
        dj, j = cKDTree(xy_c[s]).query(uv_c[ok, s], distance_upper_bound=REACH_PX)
        at = np.flatnonzero(ok)
        near[at, s] = dj <= NEAR_PX
        has = np.isfinite(dj)
        best[at[has], s] = xy_c[s][j[has]]
    colour = np.concatenate([r["color"] for r in recs])
    if len(colour) == 0:
        return None
    # The take's markers' colour: that of most of the frame's detections.
    white = bool(np.count_nonzero(colour == COLOR_WHITE) * 2 > len(colour))
    rows, sens, raw = searched(rig, uv_c, near, seen)
    if len(rows) == 0:
        return None
    found = np.full((N, S), -1)                # index into that sensor's found records
    cand = best.copy()
    per: list[np.ndarray] = [np.zeros(0, DET_DTYPE)] * S
    cams = np.unique(sens)
    got, k = find_in_crops([images(int(s)) for s in cams], raw, np.searchsorted(cams, sens), white, learned_centres)
    for s in cams:
        mine = sens[k] == s
        rec, ks = got[mine], k[mine]
        # Not a dot the frame's detections already have.
        if len(rec) and len(recs[s]):
            d = cKDTree(np.column_stack([recs[s]["x"], recs[s]["y"]]).astype(float)).query(
                np.column_stack([rec["x"], rec["y"]]).astype(float))[0]
            rec, ks = rec[d > SAME_PX], ks[d > SAME_PX]
        if len(rec) == 0:
            continue
        c = rig.correct(int(s), np.column_stack([rec["x"], rec["y"]]).astype(float))
        pts = rows[ks]
        # The dot nearest the projection, per point.
        dist = np.hypot(c[:, 0] - uv_c[pts, s, 0], c[:, 1] - uv_c[pts, s, 1])
        order = np.lexsort((dist, pts))
        first_of = order[np.r_[True, pts[order][1:] != pts[order][:-1]]]
        per[s] = rec
        found[pts[first_of], s] = first_of
        cand[pts[first_of], s] = c[first_of]
    use = np.flatnonzero(np.any(found >= 0, axis=1))
    if len(use) == 0:
        return None
    ok, valid = meeting(rig, cand[use], X[use])
    add = []
    any_added = False
    for s in range(S):
        take = use[ok & valid[:, s]]
        j = found[take, s]
        j = np.unique(j[j >= 0])
        add.append(per[s][j] if len(j) else np.zeros(0, DET_DTYPE))
        any_added |= len(j) > 0
    return add if any_added else None


def meeting(rig: RigState, uv_c: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which points' views meet: ``(ok (n,), views (n, S))`` of views ``uv_c`` (n, S, 2; NaN none) near ``pred`` (n, 3).

    The worst view is dropped while more than two remain and one misses the others' point by more than
    :data:`VIEW_PX`; a point is ``ok`` where two or more views are left, each within :data:`VIEW_PX`, and
    their point lies within :data:`MEET_MM` of ``pred`` (:data:`PAIR_MEET_MM` for two views).
    """
    n, S = uv_c.shape[:2]
    valid = np.all(np.isfinite(uv_c), axis=2)
    for _ in range(S - 1):
        X = triangulate(rig, uv_c, valid)
        err = np.where(valid, reprojection(rig, X, uv_c, valid), 0.0)
        worst = np.argmax(err, axis=1)
        drop = (valid.sum(1) > 2) & (err[np.arange(n), worst] > VIEW_PX)
        if not np.any(drop):
            break
        valid[np.flatnonzero(drop), worst[drop]] = False
    X = triangulate(rig, uv_c, valid)
    err = np.where(valid, reprojection(rig, X, uv_c, valid), 0.0)
    nv = valid.sum(1)
    ok = (nv >= 2) & np.all(err <= VIEW_PX, axis=1) \
        & (np.linalg.norm(X - pred, axis=1) <= np.where(nv >= 3, MEET_MM, PAIR_MEET_MM))
    return ok, valid


def appended(recs: list[np.ndarray], found: list[np.ndarray] | None) -> list[np.ndarray]:
    """A frame's detections per sensor with ``found`` (:func:`look_again`'s answer) after each sensor's own."""
    if found is None:
        return recs
    return [np.concatenate([rec, a]) if len(a) else rec for rec, a in zip(recs, found)]
