"""Compiled loops of the candidate stage (:mod:`.features`): DoG maxima and per-candidate features.

Steps 1 and 2 of docs/blobs.md, "The algorithm": the local maxima of one
pyramid level's DoG response, and the 14 features of each candidate's 9x9
neighbourhood that stage 1 of the classifier sees.  As numpy these were a 3x3
dilation, three full-level comparisons and a ``nonzero``, then fancy-indexed
``(N, 81)`` gathers and a dozen reductions per level; here each is one pass.
Features are computed in float64 and returned as float32 (the numpy version
summed float32: the two agree to float32 rounding).  Same numba options as
:mod:`.measure_kernel` (``cache``, ``nogil``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# JIT_EXACT for dog_peaks and the other numpy twins: nothing to vectorise there needs fastmath, and the
# sub-pixel offsets must be numpy's float32 arithmetic, operation for operation.
from ..jit import JIT, JIT_EXACT

#: The ``level`` feature is the candidate's pyramid level over this.
LEVEL_SCALE = 4.0


@njit(**JIT_EXACT)
def _dog_row(g, s, i, out, r):
    """Row ``i`` of the DoG ``g - s`` (float32, as numpy subtracts) into row ``r`` of ``out``.

    Unsigned two-dimensional indices, not row views: numba then tests no wrap-around per
    pixel, and a view costs an atomic reference count taken and dropped.
    """
    ui, ur = np.uint64(i), np.uint64(r)
    for j in range(out.shape[1]):
        uj = np.uint64(j)
        out[ur, uj] = g[ui, uj] - s[ui, uj]


@njit(**JIT_EXACT)
def _grow(a, n):
    """``a`` copied into a new array of length ``n`` (>= ``len(a)``)."""
    out = np.empty(n, a.dtype)
    out[:len(a)] = a
    return out


@njit(**JIT_EXACT)
def _row_mask(R, um, border, n, floor, mask):
    """``mask[q]`` = 1 where row ``um`` of ``R`` at ``q + border`` is above ``floor`` and >= its left and right.

    Without a branch a pixel, so that the loop runs on vectors: most pixels fail one of the
    three tests, and as branches they were mispredicted often enough to cost most of the search.
    """
    one = np.uint64(1)
    for q in range(n):
        j = np.uint64(q + border)
        m = R[um, j]
        mask[q] = (m > floor) & (m >= R[um, j - one]) & (m >= R[um, j + one])


@njit(**JIT_EXACT)
def _scan(g, s, floor, border, R, rot, i0, ys, xs, v, ox, oy, mask):
    """Rows ``i0 ..`` of :func:`dog_peaks`' search, until the output arrays are full; returns ``(next row, count)``.

    ``R`` holds the DoG rows above, at and below the row searched (rows ``rot``, rotated
    by index, not as row views).  The output arrays are not reassigned here: an array
    variable reassigned inside a loop (grown) had its reference count taken and dropped,
    two locked instructions, at every maximum stored (8,000 a frame).  ``mask`` is scratch
    (:func:`_row_mask`; a multiple of 8 long, zero past the row), read 8 pixels at a time.
    """
    H, W = g.shape
    n = W - 2 * border
    cap = len(ys)
    half, two, tiny, lim = np.float32(0.5), np.float32(2.0), np.float32(-1e-6), np.float32(0.5)
    words = mask.view(np.uint64)
    k = 0
    for i in range(i0, H - border):
        if k + n > cap:
            return i, k
        _dog_row(g, s, i + 1, R, rot[2])
        uu, um, ud = np.uint64(rot[0]), np.uint64(rot[1]), np.uint64(rot[2])
        one = np.uint64(1)
        _row_mask(R, um, border, n, floor, mask)
        for w in range(len(words)):
            if words[w] == 0:
                continue
            for q in range(8 * w, 8 * w + 8):
                if mask[q] == 0:
                    continue
                j = np.uint64(q + border)
                m, l, r = R[um, j], R[um, j - one], R[um, j + one]
                u, b = R[uu, j], R[ud, j]
                if (m >= R[uu, j - one] and m >= u and m >= R[uu, j + one]
                        and m >= R[ud, j - one] and m >= b and m >= R[ud, j + one]):
                    ys[k] = i
                    xs[k] = q + border
                    v[k] = m
                    # numpy's float32 arithmetic: 0.5 * (l - r) / minimum(l + r - 2 m, -1e-6), clipped.
                    dx = half * (l - r) / min(l + r - two * m, tiny)
                    dy = half * (u - b) / min(u + b - two * m, tiny)
                    ox[k] = min(max(dx, -lim), lim)
                    oy[k] = min(max(dy, -lim), lim)
                    k += 1
        rot[0], rot[1], rot[2] = rot[1], rot[2], rot[0]
    return H - border, k


@njit(**JIT_EXACT)
def dog_peaks(g, s, floor, border):
    """Local maxima of the DoG ``g - s`` above ``floor``, ``border`` px or more inside, with sub-pixel offsets.

    Step 1, the candidate centres: pixels above ``floor`` and >= their 8
    neighbours, in row-major order (as ``np.nonzero`` gives them).  Returns
    ``(ys, xs, v, ox, oy)``: the DoG there and the offsets of a parabola through
    each axis's neighbours (float32, clipped to half a pixel).  The DoG is made
    three rows at a time, never as a whole image.
    """
    H, W = g.shape
    if H - 2 * border <= 0 or W - 2 * border <= 0:
        e = np.empty(0, np.float32)
        return np.empty(0, np.int64), np.empty(0, np.int64), e, e.copy(), e.copy()
    # Grown by doubling, a chunk of rows at a time (each chunk's room is at least a row's worth):
    # room for every pixel (a flat plateau above the floor is all maxima) would be megabytes
    # mapped and unmapped per level, and page faults cost more than the search.
    cap = max(1024, 2 * W)
    ys = np.empty(cap, np.int64)
    xs = np.empty(cap, np.int64)
    v = np.empty(cap, np.float32)
    ox = np.empty(cap, np.float32)
    oy = np.empty(cap, np.float32)
    R = np.empty((3, W), np.float32)
    rot = np.array([0, 1, 2])
    mask = np.zeros(8 * ((W - 2 * border + 7) // 8), np.uint8)
    _dog_row(g, s, border - 1, R, 0)
    _dog_row(g, s, border, R, 1)
    i, k = border, 0
    while True:
        i, got = _scan(g, s, floor, border, R, rot, i, ys[k:], xs[k:], v[k:], ox[k:], oy[k:], mask)
        k += got
        if i >= H - border:
            break
        cap *= 2
        ys, xs, v = _grow(ys[:k], cap), _grow(xs[:k], cap), _grow(v[:k], cap)
        ox, oy = _grow(ox[:k], cap), _grow(oy[:k], cap)
    return ys[:k].copy(), xs[:k].copy(), v[:k].copy(), ox[:k].copy(), oy[:k].copy()


@njit(**JIT)
def _group_means(P, idx, ptr, out):
    """Means of ``P`` over the index groups ``idx[ptr[g]:ptr[g + 1]]``."""
    for g in range(len(ptr) - 1):
        s = 0.0
        for q in range(ptr[g], ptr[g + 1]):
            s += P[idx[q]]
        out[g] = s / (ptr[g + 1] - ptr[g])


@njit(**JIT)
def candidate_features(lvl, g, ys, xs, dog, level, noise, rings, ring_ptr, sectors, sector_ptr, inner, R, F):
    """The stage-1 features of candidates ``(ys, xs)`` on one pyramid level (``lvl`` padded by >= R + 1).

    Step 2, stage 1's inputs (:data:`.features.FEATURE_NAMES`, in that order):
    the ``(2R+1)^2`` patch's (raveled) ring means (ring ``k``'s pixels are
    ``rings[ring_ptr[k]:ring_ptr[k + 1]]``), its outer ring's 8 sector means
    (``sectors``, ``sector_ptr`` alike), 180 degree asymmetry, the Hessian of
    the centre-blurred ``g``, the DoG ``dog``, and the spread of the ``inner``
    pixels; each normalised by the blob's contrast or the level's noise.
    Writes ``F`` ``(N, 14)``.
    """
    n = 2 * R + 1
    npx = n * n
    # Level noise: pyrDown averages ~4 pixels per level step.
    lnoise = noise / 2.0 ** level
    rm = np.empty(len(ring_ptr) - 1)
    sm = np.empty(len(sector_ptr) - 1)
    ns = len(sm)
    P = np.empty(npx)
    for c in range(len(ys)):
        y, x = ys[c], xs[c]
        # The patch's rows as slices, indexed by the loop counter (no wrap-around test per pixel).
        for i in range(n):
            src = lvl[y + i - R, x - R:x + R + 1]
            dst = P[i * n:i * n + n]
            for j in range(n):
                dst[j] = src[j]
        _group_means(P, rings, ring_ptr, rm)
        _group_means(P, sectors, sector_ptr, sm)
        centre = rm[0]
        outer = rm[3]
        contrast = max(centre - outer, 0.5 * lnoise + 1e-3)
        # The patch read backwards is the patch turned 180 degrees.
        asym = 0.0
        for k in range(npx):
            asym += abs(P[k] - P[npx - 1 - k])
        smean = 0.0
        for s in range(ns):
            smean += sm[s]
        smean /= ns
        svar = 0.0
        for s in range(ns):
            svar += (sm[s] - smean) ** 2
        imean = 0.0
        for k in inner:
            imean += P[k]
        imean /= len(inner)
        ivar = 0.0
        for k in inner:
            ivar += (P[k] - imean) ** 2
        # Hessian of the centre-blurred level by central differences.
        g0 = np.float64(g[y, x])
        dxx = np.float64(g[y, x + 1]) + np.float64(g[y, x - 1]) - 2.0 * g0
        dyy = np.float64(g[y + 1, x]) + np.float64(g[y - 1, x]) - 2.0 * g0
        dxy = 0.25 * (np.float64(g[y + 1, x + 1]) + np.float64(g[y - 1, x - 1]) - np.float64(g[y + 1, x - 1])
                      - np.float64(g[y - 1, x + 1]))
        tr = dxx + dyy
        det = dxx * dyy - dxy * dxy
        disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
        l1 = tr / 2.0 - disc             # the most negative for a bright blob
        l2 = tr / 2.0 + disc
        ratio = l2 / min(l1, -1e-6) if l1 < 0.0 else -1.0
        d = dog[c]
        F[c, 0] = math.log(contrast / lnoise)
        for q in range(1, 4):
            F[c, q] = (centre - rm[q]) / contrast
        F[c, 4] = math.sqrt(svar / ns) / contrast
        F[c, 5] = (sm.max() - sm.min()) / contrast
        F[c, 6] = asym / npx / contrast
        F[c, 7] = min(max(ratio, -1.0), 1.0)
        F[c, 8] = d / contrast
        F[c, 9] = outer / 255.0
        F[c, 10] = centre / 255.0
        F[c, 11] = level / LEVEL_SCALE
        F[c, 12] = math.log(max(d, 1e-3) / lnoise)
        F[c, 13] = math.sqrt(ivar / len(inner)) / contrast


@njit(**JIT)
def median_abs_diff(img, step):
    """Median of ``|img[i, j + 1] - img[i, j]|`` over every ``step``-th row of a uint8 image (-1 if none).

    Step 1, the noise estimate: the lower median (the ``size // 2``-th
    smallest) from a 256-bin histogram.
    """
    H, W = img.shape
    hist = np.zeros(256, np.int64)
    for i in range(0, H, step):
        for j in range(W - 1):
            hist[abs(np.int64(img[i, j + 1]) - np.int64(img[i, j]))] += 1
    total = hist.sum()
    if total == 0:
        return -1
    k = total // 2
    acc = 0
    for v in range(256):
        acc += hist[v]
        if acc > k:
            return v
    return 255


@njit(**JIT)
def greedy_nms(x, y, rad, order, use_max, extra):
    """Greedy suppression: in ``order`` (best first), each kept point drops the points that clash with it.

    Steps 2 and 4, merging one blob's candidates on several octaves and one
    blob's two fits: ``i`` and ``j`` clash when their distance is under
    ``max(rad_i, rad_j) + extra`` (``use_max``) or ``min(rad_i, rad_j) + extra``.
    Points are swept in x order, so only those within the largest reach in x
    are compared.  Returns the kept points' mask.
    """
    n = len(x)
    alive = np.ones(n, np.bool_)
    if n < 2:
        return alive
    reach = rad.max() + extra
    by_x = np.argsort(x)
    xs = x[by_x]
    for i in order:
        if not alive[i]:
            continue
        lo = np.searchsorted(xs, x[i] - reach, side="left")
        hi = np.searchsorted(xs, x[i] + reach, side="right")
        for q in range(lo, hi):
            j = by_x[q]
            if j == i or not alive[j]:
                continue
            lim = (max(rad[i], rad[j]) if use_max else min(rad[i], rad[j])) + extra
            dx, dy = x[i] - x[j], y[i] - y[j]
            if dx * dx + dy * dy < lim * lim:
                alive[j] = False
    return alive


@njit(**JIT_EXACT)
def _max_nan(a, b):
    """``np.maximum(a, b)`` of two scalars: NaN if either is NaN."""
    return a if (a >= b) | (a != a) else b


@njit(**JIT_EXACT)
def profile_radius(F, level, out):
    """Half-contrast radius (full-resolution px) of each candidate from its profile features ``F[:, 1:4]``.

    Step 2, the radius estimate (:func:`.features.profile_radius`, which documents it), times
    ``2 ** level``: numpy's float32 arithmetic operation for operation (the profile and the
    interpolation's fraction are float32, the radius float64), so the result is the same to the bit.
    Writes ``out``.
    """
    r1, r2, r3 = 1.5, 2.5, 3.6
    zero = np.float32(0.0)
    half = np.float32(0.5)
    tiny = np.float32(1e-6)
    for c in range(F.shape[0]):
        # The clipped profile's running maximum (numpy's maximum: NaN stays NaN).
        p1 = _max_nan(zero, _max_nan(F[c, 1], zero))
        p2 = _max_nan(p1, _max_nan(F[c, 2], zero))
        p3 = _max_nan(p2, _max_nan(F[c, 3], zero))
        r = 3.6
        if p1 >= half:
            t = (half - zero) / _max_nan(p1 - zero, tiny)
            r = 0.0 + np.float64(t) * (r1 - 0.0)
        elif p2 >= half:
            t = (half - p1) / _max_nan(p2 - p1, tiny)
            r = r1 + np.float64(t) * (r2 - r1)
        elif p3 >= half:
            t = (half - p2) / _max_nan(p3 - p2, tiny)
            r = r2 + np.float64(t) * (r3 - r2)
        out[c] = min(max(r, 0.7), 3.6) * 2.0 ** level[c]


@njit(**JIT_EXACT)
def engulfing(x, y, major, minor, ratio, inside, out):
    """Mark in ``out`` the points with a point of under ``1 / ratio`` their major axis within ``inside`` of their
    minor semi-axis.

    Step 4's dot measured together with what it touches
    (:func:`carapost.core.blobs.detector._engulfing`): of every two points closer
    than ``inside`` of the largest minor semi-axis, the larger (by ``major``) is marked when its
    major axis is over ``ratio`` times the other's and the other's centre lies
    closer than ``inside`` of its own minor semi-axis.  Points are swept in x order.
    """
    n = len(x)
    if n < 2:
        return
    reach = 0.0
    for i in range(n):
        reach = max(reach, minor[i])
    reach = 0.5 * inside * reach
    by_x = np.argsort(x)
    for p in range(n):
        i = by_x[p]
        for q in range(p + 1, n):
            j = by_x[q]
            if x[j] - x[i] > reach:
                break
            big, small = (i, j) if major[i] >= major[j] else (j, i)
            if (major[big] > ratio * major[small]
                    and math.hypot(x[big] - x[small], y[big] - y[small]) < 0.5 * inside * minor[big]):
                out[big] = True


@njit(**JIT_EXACT)
def pad_level(lvl, border, out):
    """``lvl`` (uint8) as float32 in ``out``, its edge replicated ``border`` px (``cv2.BORDER_REPLICATE``)."""
    H, W = lvl.shape
    for i in range(H + 2 * border):
        src = lvl[min(max(i - border, 0), H - 1)]
        dst = out[i]
        v0, v1 = np.float32(src[0]), np.float32(src[W - 1])
        for j in range(border):
            dst[j] = v0
            dst[W + border + j] = v1
        row = dst[border:border + W]
        for j in range(W):
            row[j] = np.float32(src[j])


@njit(**JIT_EXACT)
def apart(ys, xs, ox, oy, ys2, xs2, ox2, oy2, width, r):
    """Which maxima ``(ys + oy, xs + ox)`` have none of ``(ys2 + oy2, xs2 + ox2)`` within ``r`` (<= 1) level px.

    Step 1, the narrower DoG's candidates (:func:`.features.thin_candidates`)
    beside the ordinary ones, on a level ``width`` px wide.  Offsets are at most
    half a pixel, so a maximum within 1 px of another is on one of its 8
    neighbouring pixels or its own: the second list is sorted row-major here
    (:func:`dog_peaks` gives it so, but not after the strongest were picked out
    of too many), then three binary searches for each maximum of the first.
    """
    n, n2 = len(ys), len(ys2)
    raw = np.empty(n2, np.int64)
    for q in range(n2):
        raw[q] = ys2[q] * width + xs2[q]
    order = np.argsort(raw)
    key2 = np.empty(n2, np.int64)
    for q in range(n2):
        key2[q] = raw[order[q]]
    out = np.ones(n, np.bool_)
    rr = r * r
    for k in range(n):
        y, x = ys[k] + np.float64(oy[k]), xs[k] + np.float64(ox[k])
        for dy in range(-1, 2):
            base = (ys[k] + dy) * width + xs[k]
            q = np.searchsorted(key2, base - 1)
            while q < n2 and key2[q] <= base + 1:
                p = order[q]
                ey, ex = ys2[p] + np.float64(oy2[p]) - y, xs2[p] + np.float64(ox2[p]) - x
                if ex * ex + ey * ey <= rr:
                    out[k] = False
                q += 1
    return out
