"""Process > Initialize 3D: grow facial 3D points from seed points (the guide's algorithm).

1. Brim points, and unused detections in the brim's image region, are excluded.
2. Per caddy (camera pair), starting from the seeds, new detection pairs are
   accepted iteratively: a pair must satisfy the epipolar constraint (symmetric
   epipolar distance <= Max Allowed Symmetric Epipolar Distance), its
   triangulated point must lie within Max Allowed Depth of a current 3D point,
   and it must be unambiguous for both detections (the only candidate, or one
   clearly better than the next).
3. The two caddies' points within Max 3D Distance To Merge are merged
   (mutual nearest neighbours with disjoint sensors).  Blobs far larger than a
   marker (mm, at their depth) are left out, and grown points resting on
   enlarged blobs only are dropped (:mod:`.blob_size`).
4. Bundle adjustment of cameras and points; then markers seen by one camera of
   each caddy are matched across the caddies (:mod:`.cross_caddy`), every
   point takes the unambiguous free detection at its projection in channels
   where it has none, observations that no longer fit are detached (a view
   its point's other views disagree with, the caddy with the larger blobs of
   a point whose caddies disagree: :mod:`.caddy_split`), and the frame is
   bundled again.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..brim import brim_image_offsets
from ..camera import matrix_to_quaternion, symmetric_epipolar_distance, triangulate_many
from ..commands import CompoundCommand
from ..edits import AddPoints, SetCameraPoses, SetPointData
from ..errors import CaraError
from ..points import BRIM, FACE, SRC_DETECTION, SRC_NONE, ST_NONE, ST_RECONSTRUCTED
from .blob_size import blob_sizes_mm, enlarged_pair, gross_views, pulled_views, view_sizes_mm
from .bundle import bundle_cameras
from .caddy_split import caddy_split
from .cross_caddy import grow_across
from .depth_attach import attach_along_depth
from .matching import CLEAR_RATIO, unambiguous
from .nearest import nearest_with_clearance

#: Dilation (px) of the brim's projected convex hull.
BRIM_MARGIN_PX = 12.0
#: Attaching a detection at a point's projection: gate and clearance (px).
ATTACH_GATE_PX = 2.0
ATTACH_CLEARANCE_PX = 5.0
#: Observations farther than this (px) from the bundled point are detached.
REJECT_PX = 2.0
#: A view of a 3+-view point is an outlier when the point made from its other views reprojects this far
#: (px) from it while those views agree within LOO_AGREE_PX (blob centres are good to ~0.1 px: a view
#: 1 px off is a detection pulled by something beside the dot, and a least-squares point shares its
#: error out among the good views).
LOO_PX = 0.6
LOO_AGREE_PX = 0.25
#: Of several views whose removal makes the rest agree, a blob this many times larger (mm) than the
#: next is the pulled one (a brow dot fused with the brow: 1.3 times the other view's blob).
LOO_SIZE = 1.15
#: Once growth within Max Allowed Depth stops, matches the other caddy confirms may lie this many times
#: farther from the points.
RELAXED_DEPTH = 3.0
#: A candidate pair is supported by another camera with a detection this close (px) to its projection...
SUPPORT_GATE_PX = 3.0
#: ...and a candidate without that support counts as this much farther from its epipolar line (px).
UNSUPPORTED_PENALTY_PX = 2.0


def _brim_region(cam, markers, xy, margin):
    """Detections inside the dilated convex hull of the brim's projection."""
    import cv2

    uv = cam.project(markers)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) < 3 or len(xy) == 0:
        return np.zeros(len(xy), bool)
    hull = cv2.convexHull(uv.astype(np.float32))
    return np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), True) >= -margin for x, y in xy], bool)


def other_view_support(cams, xy, X, skip, gate=SUPPORT_GATE_PX):
    """How many cameras outside ``skip`` have a detection within ``gate`` px of each point's projection.

    Parameters
    ----------
    cams : list of Camera
    xy : list of ndarray (N_s, 2)
        Every camera's detections (raw px).
    X : ndarray (n, 3)
    skip : iterable of int
        The cameras that made the points (they support them trivially).
    """
    count = np.zeros(len(X), int)
    for s, cam in enumerate(cams):
        if s in skip or len(xy[s]) == 0 or len(X) == 0:
            continue
        uv = cam.project(X)
        ok = np.all(np.isfinite(uv), axis=1)
        d = np.full(len(X), np.inf)
        d[ok] = cKDTree(xy[s]).query(uv[ok])[0]
        count += d <= gate
    return count


def grow_pair(cam_a, cam_b, xy_a, xy_b, seeds_X, max_depth, max_epi, support=None):
    """Step 2 for one caddy.

    Parameters
    ----------
    xy_a, xy_b : ndarray (Na, 2), (Nb, 2)
        Free detections (raw px).
    seeds_X : ndarray (K, 3)
        Current 3D points.
    support : callable, optional
        ``support(X) -> (n,) int``: cameras of the other caddy that see a
        detection where candidate points project.  Markers one above the other
        lie on the same epipolar line of a caddy's upper and lower cameras, so
        the epipolar distance cannot tell their matches apart; the other caddy,
        looking from the side, can: a candidate it supports beats one it does
        not.

    Returns
    -------
    list of (ia, ib, X)
    """
    if len(xy_a) == 0 or len(xy_b) == 0 or len(seeds_X) == 0:
        return []
    D = symmetric_epipolar_distance(cam_a, xy_a[:, None], cam_b, xy_b[None])
    ia, ib = np.nonzero(D <= max_epi)
    if len(ia) == 0:
        return []
    d = D[ia, ib]
    uv = np.stack([xy_a[ia], xy_b[ib]], axis=1)
    X = triangulate_many([cam_a, cam_b], uv, refine=False)
    good = np.all(np.isfinite(X), axis=1)
    good[good] &= (cam_a.depth(X[good]) > 0) & (cam_b.depth(X[good]) > 0)
    ia, ib, d, X = ia[good], ib[good], d[good], X[good]
    supported = np.zeros(len(X), bool)
    penalty = np.zeros(len(X))
    if support is not None and len(X):
        supported = support(X) > 0
        penalty = UNSUPPORTED_PENALTY_PX * ~supported
    free_a = np.ones(len(xy_a), bool)
    free_b = np.ones(len(xy_b), bool)
    pts = [np.asarray(seeds_X, float)]
    out = []
    alive = np.ones(len(ia), bool)
    reach, relaxed = max_depth, False
    while True:
        tree = cKDTree(np.concatenate(pts))
        idx = np.flatnonzero(alive)
        near = tree.query(X[idx], distance_upper_bound=reach)[0] <= reach
        if relaxed:
            near &= supported[idx]
        if not np.any(near):
            if relaxed or support is None:
                break
            # Growth stalls where markers are sparser than Max Allowed Depth (an eye socket, a nostril
            # between the nose and the lip on a 100-marker set with the dense set's 16 mm): go on, farther,
            # with the matches the other caddy confirms.
            reach, relaxed = RELAXED_DEPTH * max_depth, True
            continue
        # Clear among every free candidate, not only those near the points grown so far: a wrong
        # match that happens to land near them must not win just because the right one lies
        # farther out and is not considered yet.
        acc = idx[near & unambiguous(ia[idx], ib[idx], d[idx], penalty[idx])]
        if len(acc) == 0:
            break
        for j in acc:
            out.append((int(ia[j]), int(ib[j]), X[j]))
        free_a[ia[acc]] = False
        free_b[ib[acc]] = False
        alive &= free_a[ia] & free_b[ib]
        pts.append(X[acc])
    return out


def initialize_3d(project, frame: int, params: dict | None = None):
    """Process > Initialize 3D on ``frame``.

    Parameters
    ----------
    project : Project
    frame : int
    params : dict, optional
        ``max_allowed_depth``, ``max_3d_distance_to_merge``,
        ``max_allowed_symmetric_epipolar_distance``; default: the project's
        Initialize 3D Parameters.

    Returns
    -------
    (Command, dict)
        The command adds the new points, extends the seeds and sets the frame's
        cameras; the report has ``new_points``, ``points``, ``rms_px``.

    Raises
    ------
    CaraError
        Without cameras, or without seed points (face points with 2+ views) on the frame.
    """
    if project.rig is None:
        raise CaraError("no camera calibration is loaded: the cameras have no intrinsics (File > Import XCP)")
    frame = project.clamp_frame(frame)
    pr = project.properties
    p = {k: float(pr[f"initialize_3d.{k}"]) for k in
         ("max_allowed_depth", "max_3d_distance_to_merge", "max_allowed_symmetric_epipolar_distance")}
    p.update(params or {})
    S = project.sensor_count
    cams = project.rig.cameras_at(frame)
    recs = [project.detections[s].frame(frame) for s in range(S)]
    xy = [np.column_stack([r["x"], r["y"]]).astype(float) for r in recs]
    blocked = [np.zeros(len(r), bool) for r in recs]
    for q in project.points.values():
        for s in range(S):
            if q.src[frame, s] == SRC_DETECTION and 0 <= q.det[frame, s] < len(recs[s]):
                blocked[s][q.det[frame, s]] = True
    if project.brim is not None and len(project.brim):
        for s in range(S):
            blocked[s] |= _brim_region(cams[s], project.brim.markers, xy[s], BRIM_MARGIN_PX)
    # Points: (id or None, det (S,), X)
    seeds = [q for q in project.face_points()
             if q.status[frame] != ST_NONE and np.count_nonzero(q.src[frame] != SRC_NONE) >= 2]
    if not seeds:
        raise CaraError(f"Initialize 3D needs seed points on frame {frame}: merge the detections of 5-10 face "
                        "markers visible in at least the two cameras of a caddy (Edit > Merge)")
    pts = []
    for q in seeds:
        det = np.where(q.src[frame] == SRC_DETECTION, q.det[frame], -1).astype(int)
        pts.append({"id": q.id, "det": det, "uv": np.where((q.src[frame] != SRC_NONE)[:, None],
                                                           q.uv[frame].astype(float), np.nan),
                    "X": q.pos[frame].astype(float)})
    seed_X = np.array([d["X"] for d in pts])
    grown = []
    for a, b in project.caddies():
        fa, fb = np.flatnonzero(~blocked[a]), np.flatnonzero(~blocked[b])
        def support(X, a=a, b=b):
            return other_view_support(cams, xy, X, (a, b))

        for i, j, X in grow_pair(cams[a], cams[b], xy[a][fa], xy[b][fb], seed_X, p["max_allowed_depth"],
                                 p["max_allowed_symmetric_epipolar_distance"], support):
            det = np.full(S, -1)
            det[a], det[b] = fa[i], fb[j]
            grown.append({"id": None, "det": det, "X": X})
    for g in grown:
        g["uv"] = np.array([xy[s][g["det"][s]] if g["det"][s] >= 0 else (np.nan, np.nan) for s in range(S)])
    pts = _merge(pts + grown, p["max_3d_distance_to_merge"])
    pts = _repair_unsupported(pts, cams, xy, blocked, project.caddies(),
                              p["max_allowed_symmetric_epipolar_distance"], p["max_allowed_depth"])
    pts = _drop_merged_blobs(pts, cams, recs, blocked)
    # Bundle, attach in further channels, reject misfits, bundle again.
    brim = [q for q in project.points.values() if q.kind == BRIM and project.brim is not None
            and 0 <= q.brim_index < len(project.brim) and np.any(q.src[frame] != SRC_NONE)]
    bX = np.array([project.brim.markers[q.brim_index] for q in brim]).reshape(-1, 3)
    buv = np.array([np.where((q.src[frame] != SRC_NONE)[:, None], q.uv[frame].astype(float), np.nan)
                    for q in brim]).reshape(-1, S, 2)
    # Held at their markers: less their dots' perspective offsets (docs/brims.md).
    buv -= brim_image_offsets(cams, project.brim, [q.brim_index for q in brim])
    for rnd in range(2):
        X = np.array([d["X"] for d in pts])
        uv = np.array([d["uv"] for d in pts])
        cams, Xo, err = bundle_cameras(cams, np.concatenate([bX, X]), np.r_[np.ones(len(bX), bool),
                                                                             np.zeros(len(X), bool)],
                                       np.concatenate([buv, uv]))
        err = err[len(bX):]
        for k, d in enumerate(pts):
            d["X"] = Xo[len(bX) + k]
        sizes = view_sizes_mm(cams, recs, pts)
        split = caddy_split(cams, uv, sizes, project.caddies())
        # Leave-one-out would judge the kept caddy's views against the pulled pair's.
        loo = odd_views_out(cams, uv, project.caddies(), sizes) & ~split.any(axis=1, keepdims=True)
        pulled = _pulled(sizes, project.caddies()) & ~(loo | split).any(axis=1, keepdims=True)
        for k, d in enumerate(pts):
            bad = (np.isfinite(err[k]) & (err[k] > REJECT_PX)) | loo[k] | split[k]
            if d["id"] is None:     # seeds keep what the user attached
                bad |= pulled[k]
                for s in np.flatnonzero(pulled[k]):
                    # Not attached again at the point's projection: it lies within the attach gate.
                    blocked[s][d["det"][s]] = True
                d["uv"][bad] = np.nan
                d["det"][bad] = -1
        pts = [d for d in pts if d["id"] is not None or np.count_nonzero(np.isfinite(d["uv"][:, 0])) >= 2]
        if rnd == 1:
            pts = _drop_enlarged_pairs(pts, cams, recs)
        if rnd == 0:
            # The points made so far take the detections at their projections first: a two-view match
            # across the caddies is weaker evidence, and may only have what is left.
            pts = _attach_more(pts, cams, xy, blocked)
            pts = attach_along_depth(pts, cams, xy, blocked, project.caddies())
            pts = _grow_across_caddies(pts, cams, xy, recs, blocked, project.caddies(), p["max_allowed_depth"],
                                       p["max_3d_distance_to_merge"])
            pts = _attach_more(pts, cams, xy, blocked)
    X = np.array([d["X"] for d in pts])
    uv = np.array([d["uv"] for d in pts])
    cams, Xo, err = bundle_cameras(cams, np.concatenate([bX, X]),
                                   np.r_[np.ones(len(bX), bool), np.zeros(len(X), bool)], np.concatenate([buv, uv]))
    err = err[len(bX):]
    Xo = Xo[len(bX):]
    return _command(project, frame, pts, Xo, err, cams, recs)


def odd_views_out(cams, uv: np.ndarray, caddies=None, sizes=None) -> np.ndarray:
    """Which views of each point the other views disagree with (leave one out).

    Parameters
    ----------
    cams : list of Camera
    uv : numpy.ndarray, shape (N, S, 2)
        Raw pixels, NaN where a point has no view.
    caddies : list of (int, int), optional
        When given, a view is judged only by other views on two caddies or
        more: the two views of one caddy fit each other at any depth along
        their short baseline, so their agreement says nothing (a brow dot's
        blobs pulled the same way in both cameras of a caddy used to outvote
        the third camera's view and leave the point on the pulled pair).
    sizes : numpy.ndarray, shape (N, S), optional
        Each view's blob size (mm, :func:`.blob_size.view_sizes_mm`).  Where
        leaving out either of several views makes the rest agree (three views,
        two of which always fit each other), the data cannot tell which one is
        pulled: the largest blob, by more than ``LOO_SIZE`` times the next, is
        the one merged with something beside its dot.

    Returns
    -------
    numpy.ndarray of bool, shape (N, S)
        At most one view per point: the one whose leave-one-out reprojection
        error exceeds ``LOO_PX`` while the point from the other views fits
        them within ``LOO_AGREE_PX`` (points with 3+ views only); of several,
        the largest error (or the largest blob, above).
    """
    n, S = uv.shape[:2]
    seen = np.isfinite(uv[..., 0])
    out_err = np.zeros((n, S))
    fit_err = np.full((n, S), np.inf)
    many = seen.sum(1) >= 3
    for s in range(S):
        rows = np.flatnonzero(many & seen[:, s])
        if not len(rows):
            continue
        held = uv[rows].copy()
        held[:, s] = np.nan
        X = triangulate_many(cams, held)
        proj = np.stack([cams[c].project(X) for c in range(S)], axis=1)
        e = np.linalg.norm(proj - uv[rows], axis=2)
        out_err[rows, s] = e[:, s]
        others = np.where(seen[rows] & (np.arange(S) != s), e, 0.0)
        fit_err[rows, s] = others.max(axis=1)
        if caddies is not None:
            rest = seen[rows] & (np.arange(S) != s)
            spans = np.zeros(len(rows), int)
            for cad in caddies:
                spans += rest[:, list(cad)].any(axis=1)
            fit_err[rows[spans < 2], s] = np.inf
    cand = (out_err > LOO_PX) & (fit_err <= LOO_AGREE_PX)
    worst = np.argmax(np.where(cand, out_err, -1.0), axis=1)
    if sizes is not None:
        sz = np.where(cand, np.nan_to_num(np.asarray(sizes, float), nan=0.0), 0.0)
        order = np.sort(sz, axis=1)
        clear = (cand.sum(axis=1) >= 2) & (order[:, -1] > LOO_SIZE * order[:, -2]) & (order[:, -2] > 0)
        worst = np.where(clear, np.argmax(sz, axis=1), worst)
    bad = np.zeros((n, S), bool)
    has = cand.any(axis=1)
    bad[np.flatnonzero(has), worst[has]] = True
    return bad


def _repair_unsupported(pts, cams, xy, blocked, caddies, max_epi, max_depth):
    """Re-pair the grown two-view points that the other caddy does not see, across the caddies.

    A caddy's two cameras are close: a detection pulled off its dot along their
    epipolar line (a nose tip's blob merged with the nostrils' shadow) still
    matches, and the point lands millimetres deep, where the other caddy sees
    nothing.  If one of its two detections matches a free detection of the other
    caddy unambiguously, the point made from those two lies near the face (within
    Max Allowed Depth of another point) and the point's other detection
    disagrees with it, the point is made again from the cross-caddy pair.
    """
    S = len(cams)
    other = {}
    for a, b in caddies:
        for c1, c2 in caddies:
            if (c1, c2) != (a, b):
                other[a] = other[b] = (c1, c2)
    used = [np.zeros(len(xy[s]), bool) for s in range(S)]
    for d in pts:
        for s in range(S):
            if d["det"][s] >= 0:
                used[s][d["det"][s]] = True
    all_X = np.array([d["X"] for d in pts])
    for k, d in enumerate(pts):
        views = np.flatnonzero(d["det"] >= 0)
        if d["id"] is not None or len(views) != 2 or views[0] not in other:
            continue
        if other_view_support(cams, xy, d["X"][None], tuple(views))[0] > 0:
            continue
        rest = np.delete(all_X, k, axis=0)
        for v, w in ((views[0], views[1]), (views[1], views[0])):
            found = None
            for c in other[v]:
                free = np.flatnonzero(~blocked[c] & ~used[c])
                if not len(free):
                    continue
                D = symmetric_epipolar_distance(cams[v], xy[v][d["det"][v]][None, None], cams[c], xy[c][free][None])[0]
                order = np.argsort(D)
                if D[order[0]] > max_epi or (len(order) > 1 and D[order[1]] < CLEAR_RATIO * D[order[0]]):
                    continue
                j = free[order[0]]
                X = triangulate_many([cams[v], cams[c]], np.array([[xy[v][d["det"][v]], xy[c][j]]]))[0]
                if not np.all(np.isfinite(X)) or not len(rest):
                    continue
                if np.min(np.linalg.norm(rest - X, axis=1)) > max_depth:
                    continue
                if np.linalg.norm(cams[w].project(X[None])[0] - xy[w][d["det"][w]]) <= REJECT_PX:
                    continue
                found = (c, j, X)
                break
            if found is None:
                continue
            c, j, X = found
            # Made again only if that brings it nearer the surface of the points around it: the pulled pair's
            # point lies millimetres deep, but a cheek dot that only one caddy sees matched across the caddies
            # with a free nostril blob on its epipolar line (the sample's 156 white markers, seed 1), and that
            # pair lay farther off the cheek than the good caddy pair.
            if not _surface_distance(X, rest) < _surface_distance(d["X"], rest):
                continue
            used[w][d["det"][w]] = False
            used[c][j] = True
            d["det"][w], d["uv"][w] = -1, (np.nan, np.nan)
            d["det"][c], d["uv"][c] = j, xy[c][j]
            d["X"] = X
            break
    return pts


#: Points around a point whose best-fitting plane stands for the face's surface there.
SURFACE_NEIGHBOURS = 6


def _surface_distance(X: np.ndarray, others: np.ndarray) -> float:
    """Distance (mm) of ``X`` from the least-squares plane of its ``SURFACE_NEIGHBOURS`` nearest ``others``."""
    nb = others[np.argsort(np.linalg.norm(others - X, axis=1))[:SURFACE_NEIGHBOURS]]
    if len(nb) < 3:
        return 0.0
    centre = nb.mean(axis=0)
    normal = np.linalg.svd(nb - centre)[2][2]
    return abs(float((X - centre) @ normal))


def _drop_merged_blobs(pts, cams, recs, blocked):
    """Leave out the blobs far larger than a marker.

    A blob :data:`~carapost.core.calib.blob_size.GROSS_SIZE` times the frame's
    typical marker size (mm, at the point's depth) is a dot merged with a shadow
    or hair: its centre is pulled off the dot, and two such blobs of one caddy
    can agree with each other along its short baseline and pull the point away
    from the clean views (a nose tip's blob merged with the nostrils' shadow in
    two cameras).  Those views are detached and the detections excluded; a grown
    point left with fewer than two views is dropped, freeing its other
    detection for other matches.  Seeds are kept as the user made them.
    ``blocked`` is updated in place.
    """
    sizes, typical = blob_sizes_mm(cams, recs, pts)
    if not np.isfinite(typical) or typical <= 0:
        return pts
    ratio = [sz / typical for sz in sizes]
    for s, r in enumerate(ratio):
        blocked[s] |= gross_views(r)
    keep = []
    for d in pts:
        views = np.flatnonzero(d["det"] >= 0)
        if d["id"] is not None or not len(views):
            keep.append(d)
            continue
        gross = gross_views([ratio[s][d["det"][s]] for s in views])
        if len(views) - np.count_nonzero(gross) < 2:
            continue
        if gross.any():
            d["det"][views[gross]] = -1
            d["uv"][views[gross]] = np.nan
            d["X"] = triangulate_many(cams, d["uv"][None])[0]
        keep.append(d)
    return keep


def _pulled(sizes, caddies):
    """:func:`.blob_size.pulled_views` of the points whose view sizes (mm) are ``sizes`` (N, S)."""
    typical = np.nanmedian(sizes) if np.any(np.isfinite(sizes)) else np.nan
    if not typical > 0:
        return np.zeros(sizes.shape, bool)
    return pulled_views(sizes / typical, caddies, LOO_SIZE)


def _drop_enlarged_pairs(pts, cams, recs):
    """Drop the grown points left with two views whose blobs are both enlarged.

    Nothing checks two pulled centres against each other (a faint brow dot
    merged with the brow hair in the only two cameras that find it).  Applied
    once the points have taken every view they can: a third view makes such a
    point checkable.
    """
    held = view_sizes_mm(cams, recs, pts)
    if not np.any(np.isfinite(held)):
        return pts
    typical = np.nanmedian(held)
    if not typical > 0:
        return pts
    return [d for k, d in enumerate(pts) if d["id"] is not None
            or not enlarged_pair(held[k][d["det"] >= 0] / typical)]


def _grow_across_caddies(pts, cams, xy, recs, blocked, caddies, max_depth, min_gap):
    """Add the two-view points :func:`~carapost.core.calib.cross_caddy.grow_across` makes from free detections.

    Free: held by no point, not excluded, and farther than ``ATTACH_CLEARANCE_PX``
    from every point's projection (a detection there is a point's own, left
    unattached only because it was not clear, e.g. a second blob of one dot).
    """
    S = len(cams)
    free = [~b for b in blocked]
    X = np.array([d["X"] for d in pts]).reshape(-1, 3)
    for s in range(S):
        held = [d["det"][s] for d in pts if d["det"][s] >= 0]
        free[s][held] = False
        if len(X) and len(xy[s]):
            uv = cams[s].project(X)
            uv = uv[np.all(np.isfinite(uv), axis=1)]
            if len(uv):
                free[s] &= cKDTree(uv).query(xy[s])[0] > ATTACH_CLEARANCE_PX
    _sizes, typical = blob_sizes_mm(cams, recs, pts)

    def size_ratio(s, det, X):
        return np.asarray(recs[s]["major"][det], float) * cams[s].depth(X) / cams[s].focal_length / typical

    for a, i, b, j, Xn in grow_across(cams, xy, free, caddies, X, max_depth, min_gap, REJECT_PX,
                                      size_ratio if np.isfinite(typical) and typical > 0 else None,
                                      RELAXED_DEPTH * max_depth):
        det = np.full(S, -1)
        det[a], det[b] = i, j
        uv = np.full((S, 2), np.nan)
        uv[a], uv[b] = xy[a][i], xy[b][j]
        pts.append({"id": None, "det": det, "uv": uv, "X": Xn})
    return pts


def _merge(pts, dist):
    """Merge points of the two caddies: mutual nearest neighbours within ``dist`` with disjoint sensors."""
    while True:
        X = np.array([d["X"] for d in pts])
        has = np.array([np.isfinite(d["uv"][:, 0]) for d in pts])
        tree = cKDTree(X)
        pairs = tree.query_pairs(dist, output_type="ndarray")
        if len(pairs) == 0:
            return pts
        pairs = pairs[~np.any(has[pairs[:, 0]] & has[pairs[:, 1]], axis=1)]
        if len(pairs) == 0:
            return pts
        dd = np.linalg.norm(X[pairs[:, 0]] - X[pairs[:, 1]], axis=1)
        used, gone = set(), set()
        for k in np.argsort(dd):
            i, j = (int(v) for v in pairs[k])
            if i in used or j in used:
                continue
            # Keep the seed (a point with an id) as the survivor.
            if pts[i]["id"] is None and pts[j]["id"] is not None:
                i, j = j, i
            a, b = pts[i], pts[j]
            m = np.isfinite(b["uv"][:, 0])
            a["uv"][m] = b["uv"][m]
            a["det"][m] = b["det"][m]
            a["X"] = 0.5 * (a["X"] + b["X"])
            used |= {i, j}
            gone.add(j)
        pts = [d for k, d in enumerate(pts) if k not in gone]


def _attach_more(pts, cams, xy, blocked):
    """Attach, in channels where a point has no 2D data, the unambiguous detection at its projection.

    A detection held by a grown two-view point of one caddy, while a point
    built from other sensors projects onto it, goes to the latter and the
    two-view point is dropped: an epipolar match of one caddy is weaker
    evidence than an independent reconstruction (this is how an epipolar
    mismatch of a dense set shows up).  Returns the list without dropped points.
    """
    S = len(cams)
    X = np.array([d["X"] for d in pts])
    dropped = set()
    for s in range(S):
        if len(xy[s]) == 0:
            continue
        owner = np.full(len(xy[s]), -1)
        for k, d in enumerate(pts):
            if d["det"][s] >= 0 and k not in dropped:
                owner[d["det"][s]] = k
        avail = ~blocked[s] | (owner >= 0)
        proj = cams[s].project(X)
        need = np.array([not np.isfinite(d["uv"][s, 0]) for d in pts]) & np.all(np.isfinite(proj), axis=1)
        need &= np.array([k not in dropped for k in range(len(pts))])
        rows = np.flatnonzero(need)
        if len(rows) == 0:
            continue
        dist = np.linalg.norm(proj[rows][:, None] - xy[s][None], axis=-1)
        dist = np.where(avail[None], dist, np.inf)
        best, bd, clear = nearest_with_clearance(dist)
        # Every point's projection near the detection (ambiguity between points).
        pd = np.linalg.norm(proj[:, None] - xy[s][None][:, best], axis=-1)
        for k, r in enumerate(rows):
            i = int(best[k])
            if not (bd[k] <= ATTACH_GATE_PX and clear[k] > ATTACH_CLEARANCE_PX):
                continue
            near = np.flatnonzero(pd[:, k] <= ATTACH_CLEARANCE_PX)
            near = [j for j in near if j != r and j not in dropped and j != owner[i]]
            if near:
                continue
            q = owner[i]
            if q >= 0:
                dq = pts[q]
                views_q = set(np.flatnonzero(np.isfinite(dq["uv"][:, 0])).tolist())
                views_r = set(np.flatnonzero(np.isfinite(pts[r]["uv"][:, 0])).tolist())
                if not (dq["id"] is None and len(views_q) == 2 and len(views_r - views_q) >= 2):
                    continue
                dropped.add(int(q))
            owner[i] = r
            d = pts[r]
            d["det"][s] = i
            d["uv"][s] = xy[s][i]
    return [d for k, d in enumerate(pts) if k not in dropped]


def _command(project, frame, pts, X, err, cams, recs):
    S = project.sensor_count
    nid = project.next_point_id
    new, updates = [], []
    for k, d in enumerate(pts):
        has = np.isfinite(d["uv"][:, 0])
        row = {"src": np.where(has, np.where(d["det"] >= 0, SRC_DETECTION, SRC_NONE), SRC_NONE)[None].astype(np.uint8),
               "det": d["det"][None].astype(np.int32),
               "uv": d["uv"][None].astype(np.float32),
               "score": np.array([[recs[s][d["det"][s]]["score"] if d["det"][s] >= 0 else np.nan for s in range(S)]],
                                 np.float16),
               "pos": X[k][None].astype(np.float32),
               "status": np.array([ST_RECONSTRUCTED], np.uint8),
               "residual": np.array([np.sqrt(np.nanmean(err[k] ** 2))], np.float16)}
        if d["id"] is None:
            q = project.new_point(FACE, point_id=nid)
            nid += 1
            for key, v in row.items():
                q.arrays[key][frame:frame + 1] = v
            new.append(q)
        else:
            old = project.points[d["id"]]
            # Seeds keep non-detection 2D data (patches, targets) where they have it.
            keep = (old.src[frame] != SRC_NONE) & (old.src[frame] != SRC_DETECTION)
            for key in ("src", "det", "uv", "score"):
                row[key][0, keep] = old.arrays[key][frame, keep]
            updates.append((d["id"], frame, row))
    q = np.stack([matrix_to_quaternion(c.rotation) for c in cams])[:, None]
    pos = np.stack([c.position for c in cams])[:, None]
    cmds = []
    if new:
        cmds.append(AddPoints(new, name="Add Points"))
    if updates:
        cmds.append(SetPointData(updates, name="Update Seed Points"))
    cmds.append(SetCameraPoses(frame, q, pos, np.ones((S, 1), bool)))
    rms = float(np.sqrt(np.nanmean(err ** 2))) if np.any(np.isfinite(err)) else float("nan")
    cmd = CompoundCommand("Initialize 3D", cmds)
    cmd.summary = (f"Initialize 3D: frame {frame}, {len(new)} new points ({len(pts)} in all), "
                   f"RMS reprojection error {rms:.3f} px")
    return cmd, {"new_points": len(new), "points": len(pts), "rms_px": rms}
