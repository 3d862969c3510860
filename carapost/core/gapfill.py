"""Interpolate Gaps: fill missing 3D marker samples from how neighbouring markers move.

The CaraPost guide ("Gap interpolation algorithm") predicts a missing marker
"based on its last known location, and also how its neighboring marker points
move between the frame where the point was last present and the current
frame", forwards from just before the gap and backwards from just after it, and
blends the two.  This module does exactly that, in a form that is exact for
rigid motion and smooth for facial deformation:

1. For a gap of point ``p`` (missing frames ``s..e``, last seen on ``a = s-1``,
   next seen on ``b = e+1``) choose ``K`` *neighbours*: markers present on every
   frame ``a..b`` whose distance to ``p`` varied least over the frames around
   the gap (they move with ``p``; on a face, the markers of the same region),
   ties broken by closeness.
2. For every frame ``t`` of ``a..b`` fit the weighted rigid transform
   ``T_t`` (Kabsch) that maps the neighbours' positions on a reference frame to
   their positions on ``t``.  ``q(t) = T_t^-1 x_p(t)`` is the point in the
   neighbours' moving frame: constant under rigid motion.
3. Forwards prediction is ``T_t q(a)``, backwards prediction ``T_t q(b)``;
   the two are blended with weights moving smoothly from forward to backward
   across the gap.  Rather than a fixed ramp, the local coordinate ``q`` is
   interpolated by a cubic through a few known frames either side of the gap
   (``context``), which continues the point's own motion relative to its
   neighbours; for long gaps the cubic is damped toward the straight blend so it
   cannot overshoot.  With only one side available (gap at the start or end
   of the take, or one prediction switched off) ``q`` is held at that side's
   value: a pure one-sided prediction.
4. Where a single-sensor ray is given for a frame, the result is projected
   orthogonally onto the ray, so it re-projects exactly onto that detection.

Beside this neighbour-motion predictor, two low-rank models (the PCA method of
Gløersen & Federolf 2016, in a frame following the markers' mean translation
and in one following their rigid motion) predict the gap from every other
marker, joined to the known samples at the gap's ends.  The three are blended
by inverse squared error on pseudo-gaps of the same length cut from the
point's own samples near the gap (:func:`_combined`).

All functions here are pure: arrays in, arrays out.
"""
from __future__ import annotations

import numpy as np

from .errors import CaraError

__all__ = ["fill_gaps", "find_gaps", "project_to_ray", "rigid_fit"]


def find_gaps(missing: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a 1-D bool array.

    Parameters
    ----------
    missing : ndarray (F,) bool

    Returns
    -------
    list of (start, end)
        Inclusive frame ranges.
    """
    m = np.asarray(missing, bool)
    if not m.any():
        return []
    d = np.diff(np.concatenate(([0], m.view(np.int8), [0])))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def rigid_fit(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares rigid transforms ``dst ~ R src + t`` (Kabsch), batched.

    Parameters
    ----------
    src : ndarray (K, 3)
        Reference positions.
    dst : ndarray (T, K, 3)
        Positions on T frames.
    w : ndarray (K,)
        Non-negative weights.

    Returns
    -------
    R : ndarray (T, 3, 3)
    t : ndarray (T, 3)
    """
    w = w / w.sum()
    cs = w @ src                                        # (3,)
    cd = np.einsum("k,tkc->tc", w, dst)                 # (T, 3)
    a = src - cs
    b = dst - cd[:, None, :]
    h = np.einsum("k,ki,tkj->tij", w, a, b)             # (T, 3, 3) cross-covariance
    u, _s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", u, vt)))
    d[d == 0] = 1.0
    # Reflection guard: flip the least significant axis when det < 0.
    vt = vt.copy()
    vt[:, 2, :] *= d[:, None]
    r = np.einsum("tji,tkj->tik", vt, u)                # V U^T
    t = cd - np.einsum("tij,j->ti", r, cs)
    return r, t


def project_to_ray(x: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Orthogonal projection of points onto rays (the closest point of each ray).

    Parameters
    ----------
    x, origin, direction : ndarray (..., 3)

    Returns
    -------
    ndarray (..., 3)
    """
    d = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    s = np.einsum("...c,...c->...", x - origin, d)
    return origin + s[..., None] * d


def _select_neighbours(pos: np.ndarray, present: np.ndarray, p: int, lo: int, hi: int,
                       k: int, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Neighbours of point ``p`` for filling frames ``lo..hi`` and their weights.

    Candidates are present on every frame ``lo..hi``.  They are ranked by how
    little their distance to ``p`` varied over the frames within ``window`` of
    the gap where both were seen (markers that move with ``p``), plus a small
    share of the mean distance so that, among equally rigid markers, close ones
    win (a closer rigid frame extrapolates rotation errors less).
    """
    cand = np.flatnonzero(present[lo:hi + 1].all(axis=0))
    cand = cand[cand != p]
    if len(cand) == 0:
        return cand, np.zeros(0)
    w0, w1 = max(0, lo - window), min(len(pos), hi + window + 1)
    seen = present[w0:w1, p][:, None] & present[w0:w1][:, cand]
    d = np.linalg.norm(pos[w0:w1, cand, :] - pos[w0:w1, p, None, :], axis=-1)   # (W, C)
    n = seen.sum(axis=0)
    d0 = np.where(seen, d, 0.0)
    mean = d0.sum(0) / np.maximum(n, 1)
    var = np.where(seen, (d - mean) ** 2, 0.0).sum(0) / np.maximum(n, 1)
    score = np.sqrt(var) + 0.02 * mean
    score[n < 2] = np.inf
    ok = np.isfinite(score)
    if not ok.any():
        # The point was never seen near the gap alongside any candidate: fall
        # back to closeness at the gap's boundary.
        f = lo if present[lo, p] else hi
        score = np.linalg.norm(pos[f, cand] - pos[f, p], axis=-1)
    order = np.argsort(score, kind="stable")[:k]
    sel = cand[order]
    s = score[order]
    # Weight by rigidity: a marker whose distance wobbles 1 mm counts less than
    # one that holds to 0.1 mm.
    scale = max(float(np.min(s)), 1e-3) if np.isfinite(s).all() else 1.0
    w = 1.0 / (1.0 + (s / scale) ** 2) if np.isfinite(s).all() else np.ones(len(sel))
    return sel, w


def _local_track(pos, nb, w, p, frames, ref):
    """Transforms of the neighbour frame on ``frames`` and ``p`` in local coordinates."""
    src = pos[ref, nb]
    dst = pos[frames][:, nb]
    if len(nb) >= 3:
        r, t = rigid_fit(src, dst, w)
    else:
        # Too few for a rotation: follow their (weighted) translation only.
        r = np.broadcast_to(np.eye(3), (len(frames), 3, 3)).copy()
        t = np.einsum("k,tkc->tc", w / w.sum(), dst - src[None])
    return r, t


def fill_gaps(positions: np.ndarray, *, forwards: bool = True, backwards: bool = True,
              max_gap: int | None = None, targets=None, rays=None, neighbours: int = 6,
              context: int = 4, slope_gap: float = 20.0, validate: int = 3, gaps=None, weak=None,
              progress=None) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate Gaps over a set of marker trajectories.

    Parameters
    ----------
    positions : ndarray (F, P, 3)
        Marker positions; NaN (any coordinate) marks a missing sample.
    forwards, backwards : bool
        Use the prediction from the last known sample before a gap / the first
        known sample after it (the guide's "Use Forwards / Backwards
        Prediction").  With both, the two are blended across the gap; with one,
        only that side is used (a gap with no usable side stays empty).
    max_gap : int, optional
        Leave gaps longer than this many frames unfilled.
    targets : sequence of int, optional
        Points to fill (default: all).  Every point serves as a neighbour.
    rays : tuple (origins, directions), optional
        Arrays (F, P, 3); where finite, the filled sample on that frame is put on
        that ray (single-sensor constraint).
    neighbours : int
        Neighbour markers per gap (K).
    context : int
        Known frames either side of a gap used to continue the point's relative
        motion (0: plain forward/backward blend).
    slope_gap : float
        Gap length (frames) at which the continued relative motion is weighted
        one half; it fades out for longer gaps.
    validate : int
        Pseudo-gaps of the same length, cut from the point's own known samples
        near each gap, on which the predictors are tried to weight them
        (0: equal weights).
    gaps : dict, optional
        ``{point: bool array (F,)}``: frames to (re)fill even though they hold a
        sample (Overwrite Existing Filled Gaps); those samples are not used.
    weak : dict, optional
        ``{point: bool array (F,)}``: samples kept as they are but not used to
        predict a gap they border (in unbroken runs touching it): the gap is
        predicted from the samples beyond them.  A tracker's sample without
        blobs in two cameras behind it lags or strays as the point is being
        lost, and the predictors carry that error across the whole gap.
    progress : Progress, optional
        Stepped once per target point.

    Returns
    -------
    filled : ndarray (F, P, 3) float64
        ``positions`` with the gaps filled.
    mask : ndarray (F, P) bool
        True on the samples this call filled.
    """
    pos = np.array(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise CaraError(f"positions must be (frames, points, 3), got {pos.shape}")
    n_frames, n_points, _ = pos.shape
    present = np.isfinite(pos).all(axis=2)
    if gaps:
        for p, g in gaps.items():
            present[:, p] &= ~np.asarray(g, bool)
    pos[~present] = np.nan
    src_pos = pos.copy()                    # predictions only ever use measured samples
    mask = np.zeros((n_frames, n_points), bool)
    tgt = range(n_points) if targets is None else [int(t) for t in targets]
    if progress is not None:
        progress.start(len(tgt), "Interpolate Gaps")
    for p in tgt:
        if not 0 <= p < n_points:
            raise CaraError(f"no point {p}")
        kept = present[:, p].copy()
        if kept.any():
            # A gap takes in the weak samples beside it, hidden from the predictors while it is filled
            # (only its own: elsewhere they still serve as context and pseudo-gaps).
            hide = ~kept | _beside_gaps(kept, weak[p]) if weak is not None and p in weak else ~kept
            for s, e in find_gaps(hide):
                todo = ~kept[s:e + 1]
                if not todo.any() or (max_gap is not None and todo.sum() > max_gap):
                    continue
                a = s - 1 if (s > 0 and forwards) else None
                b = e + 1 if (e < n_frames - 1 and backwards) else None
                if a is None and b is None:
                    continue
                present[s:e + 1, p] = False
                est = _combined(src_pos, present, p, s, e, a, b, neighbours, context, slope_gap, validate)
                present[s:e + 1, p] = kept[s:e + 1]
                if est is None:
                    continue
                pos[s:e + 1, p][todo] = est[todo]
                mask[s:e + 1, p] |= todo
        if progress is not None:
            progress.step()
    if rays is not None:
        org, dirn = (np.asarray(r, np.float64) for r in rays)
        has = mask & np.isfinite(org).all(-1) & np.isfinite(dirn).all(-1)
        if has.any():
            pos[has] = project_to_ray(pos[has], org[has], dirn[has])
    return pos, mask


def _beside_gaps(kept: np.ndarray, weak) -> np.ndarray:
    """``(F,)`` bool: the ``weak`` samples of ``kept`` in unbroken runs that touch a missing frame."""
    weak = np.asarray(weak, bool) & kept
    out = np.zeros(len(kept), bool)
    for s, e in find_gaps(weak):
        if (s > 0 and not kept[s - 1]) or (e < len(kept) - 1 and not kept[e + 1]):
            out[s:e + 1] = True
    return out


def _fill_one(pos, present, p, s, e, a, b, k, context, slope_gap):
    """Estimate of point ``p`` on frames ``s..e`` (None when there is nothing to go on)."""
    lo = a if a is not None else s
    hi = b if b is not None else e
    n_frames = len(pos)
    length = e - s + 1
    nb, w = _select_neighbours(pos, present, p, lo, hi, k, window=max(50, 4 * length))
    # Context frames: known samples of p just outside the gap where all the
    # neighbours are present too.
    ctx = []
    if context > 0:
        if a is not None:
            f = a - 1
            while f >= 0 and len(ctx) < context and present[f, p]:
                ctx.append(f)
                f -= 1
        nb_before = len(ctx)
        if b is not None:
            f = b + 1
            while f < n_frames and len(ctx) - nb_before < context and present[f, p]:
                ctx.append(f)
                f += 1
    gap = np.arange(s, e + 1)
    if len(nb) == 0:
        return _self_interp(pos, p, s, e, a, b)
    if ctx:
        ok = present[ctx][:, nb].all(axis=1)
        ctx = [c for c, o in zip(ctx, ok) if o]
    ends = [f for f in (a, b) if f is not None]
    known = np.array(sorted(ends + ctx))
    frames = np.concatenate([known, gap])
    ref = ends[0]
    r, t = _local_track(pos, nb, w, p, frames, ref)
    nk = len(known)
    q_known = np.einsum("tji,tj->ti", r[:nk], pos[known, p] - t[:nk])   # R^T (x - t)
    if a is None or b is None:
        q = np.repeat(q_known[known == ends[0]], length, axis=0)
    else:
        qa = q_known[known == a][0]
        qb = q_known[known == b][0]
        u = (gap - a) / (b - a)
        # The guide's blend: forward prediction fading into backward prediction.
        lin = qa + (qb - qa) * u[:, None]
        q = lin
        # Continue p's motion relative to its neighbours: a cubic Hermite in the
        # local coordinate with the end slopes measured on the context frames.
        # It equals the known samples at both ends (no jump) and reduces to the
        # straight blend when no slope is known.  Slopes are damped for long
        # gaps, where a slope extrapolated from a few frames is not trustworthy.
        ma = _slope(known, q_known, a, -1)
        mb = _slope(known, q_known, b, +1)
        damp = 1.0 / (1.0 + (length / slope_gap) ** 2)
        h = float(b - a)
        chord = (qb - qa) / h
        ma = chord if ma is None else ma
        mb = chord if mb is None else mb
        h10 = u * (1 - u) ** 2
        h11 = u ** 2 * (u - 1)
        q = lin + damp * h * (h10[:, None] * (ma - chord) + h11[:, None] * (mb - chord))
    return np.einsum("tij,tj->ti", r[nk:], q) + t[nk:]


def _pca_markers(present, p, spans, cover, min_others=3):
    """Markers for the low-rank model of ``p`` applied on the frame ranges ``spans``.

    Present on every frame of every ``(lo, hi)`` span and on at least
    ``cover`` of the frames where ``p`` is seen: a marker with many gaps
    elsewhere would shrink the training set (frames where every chosen marker
    is present) more than its correlations help.  With fewer than
    ``min_others`` such markers, the best covered ones.
    """
    there = np.ones(present.shape[1], bool)
    for lo, hi in spans:
        there &= present[lo:hi + 1].all(axis=0)
    there[p] = False
    others = np.flatnonzero(there)
    if len(others) == 0:
        return others
    seen = present[:, p]
    c = present[seen][:, others].mean(axis=0) if seen.any() else np.ones(len(others))
    keep = c >= cover
    if keep.sum() < min_others:
        keep = c >= np.sort(c)[::-1][min(min_others, len(c)) - 1]
    return others[keep]


def _lowrank_model(pos, present, p, spans, rigid=True, cover=0.9, sigma=200.0, own_weight=0.02, sv_kept=0.99,
                   max_train=1000):
    """Low-rank (PCA) model of ``p`` and the other markers: Gløersen & Federolf (2016).

    As the paper: every marker present over the ``spans`` the model will fill
    (see :func:`_pca_markers`) in a coordinate frame moving with them
    (``rigid``: their least-squares rigid motion, which suits a face turning;
    otherwise their mean translation, which suits markers on several body
    segments), each coordinate normalised to unit variance over the training
    frames (every frame where the markers and ``p`` are seen), markers weighted
    by ``exp(-d^2 / 2 sigma^2)`` of their mean distance ``d`` to ``p`` and
    ``p`` itself by ``own_weight`` (so the principal vectors describe the
    others, and ``p``'s loadings are its regression on them), principal
    vectors up to ``sv_kept`` of the summed singular values.  Takes longer
    than ``max_train`` training frames are sampled evenly: at capture rates
    neighbouring frames add little, and the time goes into the covariance.

    Returns a dict for :func:`_lowrank_apply`, or None when too few markers
    or frames are available.
    """
    others = _pca_markers(present, p, spans, cover)
    if len(others) < 3:
        return None
    cols = np.concatenate([others, [p]])
    train = np.flatnonzero(present[:, cols].all(axis=1))
    if len(train) < 10:
        return None
    if len(train) > max_train:
        train = train[np.unique(np.linspace(0, len(train) - 1, max_train).round().astype(int))]
    xs = pos[np.ix_(train, cols)]
    ref = xs[:, :-1].mean(axis=0)
    loc, _r, _t = _to_local(xs, ref, rigid)
    y = loc.reshape(len(train), -1)
    mu = y.mean(0)
    sd = y.std(0)
    sd[sd < 1e-9] = 1.0
    d = np.linalg.norm(xs[:, :-1] - xs[:, -1:], axis=-1).mean(axis=0)
    wv = np.concatenate([np.repeat(np.exp(-0.5 * (d / sigma) ** 2), 3), np.full(3, own_weight)])
    z = (y - mu) / sd * wv
    # Eigen-decomposition of the small covariance rather than an SVD of the
    # long data matrix: same principal vectors, a fraction of the time.
    ev, vec = np.linalg.eigh(z.T @ z)
    ev, vec = np.clip(ev[::-1], 0, None), vec[:, ::-1]
    sv = np.sqrt(ev)
    k = int(min(np.searchsorted(np.cumsum(sv) / max(sv.sum(), 1e-300), sv_kept) + 1,
                3 * len(others) - 1, len(train) - 1))
    vo = vec[:-3, :k]
    lam = 1e-12 * float(ev[0]) + 1e-300                 # guards a singular fit only
    return dict(others=others, cols=cols, rigid=rigid, ref=ref, mu=mu, sd=sd, wv=wv, vo=vo, vp=vec[-3:, :k],
                gram=vo.T @ vo + lam * np.eye(k))


def _to_local(xs, ref, rigid):
    """Markers ``xs`` (T, n+1, 3; the last the predicted point) in the frame moving with the first n."""
    if rigid:
        r, t = rigid_fit(ref, xs[:, :-1], np.ones(len(ref)))
        return (xs - t[:, None, :]) @ r, r, t                    # R^T (x - t), row vectors
    t = xs[:, :-1].mean(axis=1) - ref.mean(axis=0)
    return xs - t[:, None, :], None, t


def _lowrank_apply(m, pos, p, s, e, a, b):
    """Prediction of ``p`` on ``s..e`` by the model ``m`` (:func:`_lowrank_model`) and its misfit.

    The scores on each frame are the least-squares fit of the other markers
    (the fixed point of the paper's iterative refinement).  The model's error
    on ``a`` and ``b`` is removed with a linear ramp, so the fill joins the
    known samples.  The misfit is the RMS residual of the other markers
    (normalised, weighted) on the gap frames: a pose unlike the training
    frames, or a glitching marker, shows there.
    """
    ends = [f for f in (a, b) if f is not None]
    gap = np.arange(s, e + 1)
    frames = np.concatenate([ends, gap])
    xs = pos[np.ix_(frames, m["cols"])]
    xs[:, -1] = 0.0                                     # p is unknown on the gap; its column is not used
    loc, r, t = _to_local(xs, m["ref"], m["rigid"])
    mu, sd, wv, vo = m["mu"], m["sd"], m["wv"], m["vo"]
    zq = ((loc.reshape(len(frames), -1) - mu) / sd * wv)[:, :-3]
    sc = np.linalg.solve(m["gram"], vo.T @ zq.T).T
    pred = (sc @ m["vp"].T) / wv[-3:] * sd[-3:] + mu[-3:]
    pred = pred + t if r is None else np.einsum("tij,tj->ti", r, pred) + t
    ne = len(ends)
    misfit = float(np.sqrt(np.mean((zq[ne:] - sc[ne:] @ vo.T) ** 2)))
    err = pos[ends, p] - pred[:ne]
    g = pred[ne:]
    if ne == 2:
        u = ((gap - a) / (b - a))[:, None]
        return g + err[0] * (1 - u) + err[1] * u, misfit
    return g + err[0], misfit


def _span(s, e, a, b):
    """Frames a gap ``s..e`` reads: from its known sample before (``a``) to the one after (``b``)."""
    return (s if a is None else a, e if b is None else b)


def _predictors(pos, present, p, s, e, a, b, k, context, slope_gap, models=None):
    """Every predictor's ``(estimate, misfit)`` for ``p`` on ``s..e`` (None where one cannot run).

    The first low-rank model (translation frame, the paper's) is the one
    trusted when no pseudo-gap can rank them (see :func:`_combined`); the
    neighbour-motion predictor has no misfit (None).  ``models``: the two
    low-rank models, when already built (shared by a gap and its pseudo-gaps).
    """
    if models is None:
        models = [_lowrank_model(pos, present, p, [_span(s, e, a, b)], rigid=rigid) for rigid in (False, True)]
    fill = _fill_one(pos, present, p, s, e, a, b, k, context, slope_gap)
    return [None if m is None else _lowrank_apply(m, pos, p, s, e, a, b) for m in models] + \
        [None if fill is None else (fill, None)]


def _pseudo_gaps(present, p, s, e, length, need_a, need_b, count):
    """Up to ``count`` stretches of ``length`` frames where ``p`` is known, nearest the gap ``s..e``.

    ``p`` is also known one frame either side (only the sides the real gap
    uses); the stretches do not touch the real gap or each other.
    """
    lo_off, hi_off = int(need_a), int(need_b)
    span = length + lo_off + hi_off
    run = np.convolve(present[:, p].astype(int), np.ones(span, int), "valid")
    starts = np.flatnonzero(run == span) + lo_off
    starts = starts[(starts + length + hi_off < s - 1) | (starts - lo_off > e + 1)]
    order = np.argsort(np.abs(starts + 0.5 * length - 0.5 * (s + e)), kind="stable")
    chosen = []
    for st in starts[order]:
        if all(abs(st - c) >= length for c in chosen):
            chosen.append(int(st))
            if len(chosen) >= count:
                break
    return chosen


def _combined(pos, present, p, s, e, a, b, k, context, slope_gap, validate):
    """Blend of the predictors weighted by their errors on nearby pseudo-gaps.

    Which predictor is best depends on the data (neighbour motion on a face,
    the low-rank models where markers sit on several segments) and on the gap
    length, so each gap tries them on up to ``validate`` stretches of the same
    length where the point is known, as close to the gap as possible, and
    weights them by inverse mean squared error there (model averaging).  In a
    short take where no such stretch leaves every predictor enough to work on
    (shorter stretches rank them wrongly: neighbour motion extrapolates well
    over 7 frames and badly over 30), the paper's low-rank model is used alone.
    """
    length = e - s + 1
    need_a, need_b = a is not None, b is not None
    chosen = _pseudo_gaps(present, p, s, e, length, need_a, need_b, validate) if validate > 0 else []
    models = None
    if chosen and 10 * len(chosen) * length <= present[:, p].sum():
        # A long take: one pair of low-rank models, trained without the
        # pseudo-gaps, serves the gap and every pseudo-gap (a quarter of the
        # work; the few frames held out change the model little).
        held = present.copy()
        for st in chosen:
            held[st:st + length, p] = False
        spans = [_span(s, e, a, b)] + [_span(st, st + length - 1, st - 1 if need_a else None,
                                             st + length if need_b else None) for st in chosen]
        models = [_lowrank_model(pos, held, p, spans, rigid=rigid) for rigid in (False, True)]
    preds = _predictors(pos, present, p, s, e, a, b, k, context, slope_gap, models)
    ests = [None if q is None else q[0] for q in preds]
    ok = [i for i, g in enumerate(ests) if g is not None]
    if not ok:
        return None
    if len(ok) == 1 or validate <= 0:
        return np.mean([ests[i] for i in ok], axis=0)
    sse, n_used = np.zeros(len(ests)), 0
    misfit = np.zeros(len(ests))
    for st in chosen:
        en = st + length - 1
        pr = present.copy()
        pr[st:en + 1, p] = False
        trial = _predictors(pos, pr, p, st, en, st - 1 if need_a else None, en + 1 if need_b else None,
                            k, context, slope_gap, models)
        if any(trial[i] is None for i in ok):
            continue                        # ranks only some of them: not comparable
        for i in ok:
            sse[i] += float(np.sum((trial[i][0] - pos[st:en + 1, p]) ** 2))
            if preds[i][1] is not None:
                misfit[i] += trial[i][1] ** 2
        n_used += 1
    if n_used == 0:
        return ests[ok[0]] if ok[0] == 0 else np.mean([ests[i] for i in ok], axis=0)
    for i in ok:
        # A low-rank model that explains the other markers worse on the gap
        # than on the pseudo-gaps is extrapolating: expect its error to grow
        # in proportion.
        if preds[i][1] is not None and misfit[i] > 0:
            sse[i] *= max(1.0, preds[i][1] ** 2 / (misfit[i] / n_used))
    ok = _drop_outlier(ests, ok, np.sqrt(min(sse[i] for i in ok) / (n_used * length)))
    w = np.array([1.0 / max(sse[i], 1e-12) for i in ok])
    w /= w.sum()
    return np.einsum("i,itc->tc", w, np.stack([ests[i] for i in ok]))


def _drop_outlier(ests, ok, err, factor=4.0):
    """``ok`` without a prediction that disagrees with all the others far beyond their agreement.

    A few pseudo-gaps can rank a predictor well that fails on the real gap
    (a neighbour frame that extrapolates wildly in a short take); when its RMS
    distance to every other prediction exceeds ``factor`` times both the
    others' mutual distance and the best pseudo-gap RMS error ``err``, it is
    left out of the blend.
    """
    if len(ok) < 3:
        return ok
    dist = {(i, j): float(np.sqrt(np.mean(np.sum((ests[i] - ests[j]) ** 2, axis=1)))) for i in ok for j in ok if i < j}
    d = lambda i, j: dist[(min(i, j), max(i, j))]
    for i in ok:
        rest = [j for j in ok if j != i]
        agree = max(d(j, l) for j in rest for l in rest if j < l)
        if min(d(i, j) for j in rest) > factor * max(agree, err):
            return rest
    return ok


def _slope(known, q_known, end, side):
    """Slope (per frame) of the local coordinate at ``end`` from the context on ``side``."""
    sel = (known == end) | ((known - end) * side > 0)
    if sel.sum() < 2:
        return None
    tt = known[sel] - end
    qq = q_known[sel]
    # Least-squares line through the end sample and its context.
    tt0 = tt - tt.mean()
    return (tt0[:, None] * (qq - qq.mean(0))).sum(0) / (tt0 ** 2).sum()


def _self_interp(pos, p, s, e, a, b):
    """No neighbour present over the gap: interpolate the point's own samples."""
    if a is None and b is None:
        return None
    if a is None:
        return np.repeat(pos[b, p][None], e - s + 1, axis=0)
    if b is None:
        return np.repeat(pos[a, p][None], e - s + 1, axis=0)
    u = (np.arange(s, e + 1) - a) / (b - a)
    return pos[a, p] + (pos[b, p] - pos[a, p]) * u[:, None]
