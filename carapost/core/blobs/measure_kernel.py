"""Compiled per-blob loops of the centre and ellipse measurement (:mod:`.centre`).

The measurement is many small windows (11-57 px square, ~450 per frame over the
three rounds): as numpy reductions over ``(N, window)`` arrays, the per-call
overhead of ~100 operations per window size dominated (~36 ms of a 47 ms
frame).  Here every blob is a few plain loops over its window, compiled by numba:

- ``cache=True``: the machine code is kept on disk beside this module, so the
  worker processes of Detect Blobs [Active Range] load it instead of compiling;
- ``nogil=True``: a thread running a kernel lets the others run;
- ``fastmath={"reassoc"}`` and branch-free loop bodies: sums may be reordered so
  that they are vectorised; nothing else of IEEE arithmetic is relaxed
  (no approximate division, no assumption that values are finite).

The per-pixel loops are float32 (windows, gradients, weights and their sums: 16
lanes to float64's 8, fit_round 1.7x faster); the solves on those sums and
everything a blob's answer is made of are float64.  On the sample takes' blobs
the centres are the float64 numpy arithmetic's to 2e-4 px, and the benchmark's
detections score the same to four decimals (``tests/test_blob_measure_kernel.py``;
docs/blobs-history.md, "Session 30").  Constants in those loops are float32 (``_0``,
``_1``, ...): one float64 literal would widen the whole loop.
Windows are flat arrays with their pixels' coordinates beside them: one long
loop per step vectorises, where loops over each row's few pixels inside a
weight's reach ran mostly in their scalar remainders (measured: full rows were
faster than the spans inside the reach).  The step names below are those of
docs/blobs.md, "The algorithm", step 3.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import JIT, JIT_EXACT
from .candidate_kernel import _max_nan

F32 = np.float32
#: The per-pixel loops' constants as float32: a float64 literal would make numba widen the whole loop.
_0, _HALF, _1, _NINTH = F32(0.0), F32(0.5), F32(1.0), F32(1.0 / 9.0)


@njit(**JIT)
def taper(d2, reach, inv):
    """Weight at squared distance ``d2``: 1 up to ``reach - 1/inv``, falling linearly to 0 at ``reach``.

    Step 3, the taper of the weights beyond the blob's radius (of the lines, the
    centroid and the moments): ``reach = r + TAPER_OUT``, ``inv = 1 / (TAPER_OUT - TAPER_IN)``.
    """
    return min(max((reach - math.sqrt(d2)) * inv, _0), _1)


@njit(**JIT)
def rows(c, reach, off, size):
    """Rows ``[lo, hi)`` of a grid (row ``i`` at ``i - off``) within ``reach`` of ``c``, one row of slack each side.

    The loops below visit only these rows (the weights decide exactly which
    pixels count): a contiguous part of the flat window, still one long loop.
    """
    return max(int(math.floor(c - reach + off)) - 1, 0), min(int(math.ceil(c + reach + off)) + 2, size)


@njit(inline="always", **JIT)
def window_gradients(P, n, tmp, gx, gy):
    """Gradients on the half-pixel grid of the flat ``n x n`` window ``P``, each the 3x3 mean of its neighbours.

    Step 3, the radial-symmetry centre's lines: 2x2 differences (symmetric about
    each half-pixel point), then a 3x3 mean with the edge rows and columns
    replicated, which steadies each line's direction.  Fills the flat ``(n-1)^2``
    ``gx``, ``gy`` (``tmp`` is ``(4, >= (n-1) n)`` scratch).
    """
    m = n - 1
    rx, ry, vx, vy = tmp[0], tmp[1], tmp[2], tmp[3]
    # The differences and the sums of three rows are laid out with the window's row stride n (column
    # m of each row is not used), so that each is one loop over the flat window: loops over rows of
    # 10-56 pixels ran mostly in their scalar remainders.  Slices indexed by the loop counter: numba
    # then knows no index is negative (no wrap-around test per element) and the loops vectorise.
    L = m * n - 1
    Pa, Pb, Pc, Pd = P[0:L], P[1:L + 1], P[n:L + n], P[n + 1:L + n + 1]
    rxa, rya = rx[0:L], ry[0:L]
    for k in range(L):
        s = Pd[k] - Pa[k]
        t = Pc[k] - Pb[k]
        rxa[k] = _HALF * (s - t)
        rya[k] = _HALF * (s + t)
    # The 3x3 sum: sums of three rows (the edge rows replicated), then of three columns.
    last = (m - 1) * n
    below = min(n, last)
    for j in range(m):
        vx[j] = rx[j] + rx[j] + rx[below + j]
        vy[j] = ry[j] + ry[j] + ry[below + j]
    if m > 1:
        for j in range(m):
            vx[last + j] = rx[last - n + j] + rx[last + j] + rx[last + j]
            vy[last + j] = ry[last - n + j] + ry[last + j] + ry[last + j]
    if m > 2:
        K = last - n
        # One output per loop: with two, the loop read six rows and wrote two that might overlap them,
        # more pairs than LLVM tests at run time, and it was not vectorised.
        ru, rc, rd, vxa = rx[0:K], rx[n:K + n], rx[2 * n:K + 2 * n], vx[n:K + n]
        for k in range(K):
            vxa[k] = ru[k] + rc[k] + rd[k]
        su, sc, sd, vya = ry[0:K], ry[n:K + n], ry[2 * n:K + 2 * n], vy[n:K + n]
        for k in range(K):
            vya[k] = su[k] + sc[k] + sd[k]
    ninth = _NINTH
    # Unsigned offsets, not row views: a view is an atomic reference count taken and dropped,
    # four a row here (~100 a window), and unsigned indices need no wrap-around test either.
    u1, u2 = np.uint64(1), np.uint64(2)
    um = np.uint64(m)
    for i in range(m):
        c = np.uint64(i * m)
        e = np.uint64(i * n)
        gx[c] = (vx[e] + vx[e] + vx[e + u1]) * ninth
        gy[c] = (vy[e] + vy[e] + vy[e + u1]) * ninth
        for j in range(m - 2):
            q = np.uint64(j)
            gx[c + u1 + q] = (vx[e + q] + vx[e + q + u1] + vx[e + q + u2]) * ninth
        for j in range(m - 2):
            q = np.uint64(j)
            gy[c + u1 + q] = (vy[e + q] + vy[e + q + u1] + vy[e + q + u2]) * ninth
        gx[c + um - u1] = (vx[e + um - u2] + vx[e + um - u1] + vx[e + um - u1]) * ninth
        gy[c + um - u1] = (vy[e + um - u2] + vy[e + um - u1] + vy[e + um - u1]) * ninth


@njit(inline="always", **JIT)
def gradient_sums(gx, gy, m, sums):
    """``sums = (sum gx, sum gy, sum gx^2, sum gy^2)`` over the flat ``m x m`` gradients (:func:`window_gradients`).

    The window's gradient energy for any background slope follows from them
    (the ``edge_share`` measurement).
    """
    sx = sy = sxx = syy = _0
    gxa, gya = gx[:m * m], gy[:m * m]
    for k in range(m * m):
        sx += gxa[k]
        sy += gya[k]
        sxx += gxa[k] * gxa[k]
        syy += gya[k] * gya[k]
    sums[0], sums[1], sums[2], sums[3] = sx, sy, sxx, syy


@njit(inline="always", **JIT)
def ring_plane(P, X, Y, h, cx, cy, r, noise, ring_in, ring_out, slope_k, plane):
    """Background plane ``b + gx x + gy y`` fitted to the ring ``r + ring_in .. r + ring_out`` about (cx, cy).

    Step 3, the local background: least squares over the ring's pixels (plus
    1e-3 on the normal equations' diagonal, so an empty ring gives a zero
    plane), then the slope is shrunk by ``slope_k`` times the slope noise alone
    would give.  Writes ``plane[0:3]``; returns the ring's pixel count.
    """
    lo = F32((r + ring_in) * (r + ring_in))
    hi = F32((r + ring_out) * (r + ring_out))
    c32x, c32y = F32(cx), F32(cy)
    s0 = sx = sy = sxx = sxy = syy = _0
    rb = rx = ry = sd2 = _0
    n = 2 * h + 1
    i0, i1 = rows(cy, r + ring_out, h, n)
    # The rows by unsigned offsets (no views: each is an atomic reference count; a loop starting past
    # 0 with signed indices was not vectorised, 3x slower).
    k0 = np.uint64(i0 * n)
    for kk in range(i1 * n - i0 * n):
        k = k0 + np.uint64(kk)
        x = X[k]
        y = Y[k]
        dx = x - c32x
        dy = y - c32y
        d2 = dx * dx + dy * dy
        f = _1 if (d2 >= lo) & (d2 <= hi) else _0
        v = f * P[k]
        s0 += f
        sx += f * x
        sy += f * y
        sxx += f * (x * x)
        sxy += f * (x * y)
        syy += f * (y * y)
        rb += v
        rx += v * x
        ry += v * y
        sd2 += f * d2
    # The solve in float64 (the sums are float32, to ~1e-6 of themselves).
    s0, sx, sy, sxx, sxy, syy = float(s0), float(sx), float(sy), float(sxx), float(sxy), float(syy)
    rb, rx, ry, sd2 = float(rb), float(rx), float(ry), float(sd2)
    a00, a11, a22 = s0 + 1e-3, sxx + 1e-3, syy + 1e-3
    # Cramer's rule on the symmetric 3x3 normal equations.
    c00 = a11 * a22 - sxy * sxy
    c01 = sxy * sy - sx * a22
    c02 = sx * sxy - a11 * sy
    det = a00 * c00 + sx * c01 + sy * c02
    c11 = a00 * a22 - sy * sy
    c12 = sx * sy - a00 * sxy
    c22 = a00 * a11 - sx * sx
    b = (c00 * rb + c01 * rx + c02 * ry) / det
    gx = (c01 * rb + c11 * rx + c12 * ry) / det
    gy = (c02 * rb + c12 * rx + c22 * ry) / det
    sl = math.sqrt(gx * gx + gy * gy)
    sl_noise = noise / math.sqrt(max(sd2 / 2.0, 1e-6))
    k = max(sl - slope_k * sl_noise, 0.0) / max(sl, 1e-9)
    plane[0] = b
    plane[1] = gx * k
    plane[2] = gy * k
    return s0


@njit(inline="always", **JIT)
def lines_centre(gx0, gy0, GX, GY, h, plane, cx, cy, reach, inv, noise, lim, sol):
    """One radial-symmetry solve about (cx, cy): the point nearest the gradient lines.

    Step 3, the radial-symmetry centre: the line through each half-pixel point
    (``GX``, ``GY``) along its gradient (less the plane's slope), weight =
    taper x (squared gradient less the noise's); minimise the weighted squared
    distances.  A degenerate system keeps the old centre; the answer is clipped
    to ``lim``.  Writes ``sol = (x, y)``.
    """
    nz = F32(noise * noise)
    b1 = plane[1]
    b2 = plane[2]
    c32x, c32y, reach32, inv32 = F32(cx), F32(cy), F32(reach), F32(inv)
    sxx = syy = sxy = bx = by = _0
    m = 2 * h
    i0, i1 = rows(cy, reach, h - 0.5, m)
    k0 = np.uint64(i0 * m)
    for kk in range(i1 * m - i0 * m):
        k = k0 + np.uint64(kk)
        px = GX[k]
        py = GY[k]
        dx = px - c32x
        dy = py - c32y
        gx = gx0[k] - b1
        gy = gy0[k] - b2
        w = taper(dx * dx + dy * dy, reach32, inv32) * max(gx * gx + gy * gy - nz, _0)
        wgx = w * gx
        wgy = w * gy
        sxx += wgy * gy
        syy += wgx * gx
        sxy -= wgx * gy
        npx = gx * py - gy * px
        bx -= wgy * npx
        by += wgx * npx
    sxx, syy, sxy, bx, by = float(sxx), float(syy), float(sxy), float(bx), float(by)
    det = sxx * syy - sxy * sxy
    if det > 1e-12 * (sxx + syy) ** 2 + 1e-20:
        cx = (syy * bx - sxy * by) / det
        cy = (sxx * by - sxy * bx) / det
    sol[0] = min(max(cx, -lim), lim)
    sol[1] = min(max(cy, -lim), lim)


@njit(inline="always", **JIT)
def inside_moments(D, X, Y, h, a, cx, cy, reach, inv, mom):
    """Tapered moments of the half-contrast inside map ``clip(2 d / a - 0.5, 0, 1)`` about (cx, cy).

    Step 3, the inside map's centroid and the ellipse's second moments (``D``:
    the background-subtracted window): writes ``mom = (m0, mx, my, mxx, myy,
    mxy)``, sums of the tapered map times 1, dx, dy, dx^2, dy^2, dx dy, with
    dx, dy from (cx, cy).
    """
    s = F32(2.0 / a)
    c32x, c32y, reach32, inv32 = F32(cx), F32(cy), F32(reach), F32(inv)
    m0 = mx = my = mxx = myy = mxy = _0
    n = 2 * h + 1
    i0, i1 = rows(cy, reach, h, n)
    k0 = np.uint64(i0 * n)
    for kk in range(i1 * n - i0 * n):
        k = k0 + np.uint64(kk)
        dx = X[k] - c32x
        dy = Y[k] - c32y
        v = min(max(D[k] * s - _HALF, _0), _1) * taper(dx * dx + dy * dy, reach32, inv32)
        m0 += v
        mx += v * dx
        my += v * dy
        mxx += v * dx * dx
        myy += v * dy * dy
        mxy += v * dx * dy
    mom[0], mom[1], mom[2], mom[3], mom[4], mom[5] = m0, mx, my, mxx, myy, mxy


@njit(**JIT)
def measure_one(h, r, noise, passes, c, S, out):
    """Centre and ellipse of one blob; returns what :func:`measure_extra` continues from.

    Step 3 (see :func:`carapost.core.blobs.centre.measure`, whose outputs these
    are): ``passes`` plane + lines solves, each about the last answer; the
    contrast; the 0.3 lines + 0.7 inside-map centroid blend; the moments about
    the blend -> ellipse.  ``c`` holds the constants ``(TAPER_IN, TAPER_OUT,
    RING_IN, RING_OUT, SLOPE_K, MIX, CORE_Q)``.  ``S`` is ``(13, >= (2h+1)^2)``
    scratch whose rows 0-2 hold the flat window and its pixels' x and y
    (row-major, relative to its centre pixel) and rows 6-7 the half-pixel grid's
    x and y; on return its rows 3-5 hold the background-subtracted window and the
    gradients, and row 12 the plane.  Writes ``out = (x, y,
    major, minor, angle, ok)``.
    """
    t_in, t_out, ring_in, ring_out, slope_k, mix = c[0], c[1], c[2], c[3], c[4], c[5]
    inv = 1.0 / (t_out - t_in)
    reach = r + t_out
    n = 2 * h + 1
    npx = n * n
    P, X, Y, D, gx0, gy0, GX, GY, small = S[0], S[1], S[2], S[3], S[4], S[5], S[6], S[7], S[12]
    plane = small[0:3]
    sol = small[3:5]
    mom = small[5:11]
    window_gradients(P, n, S[8:12], gx0, gy0)
    plane[:] = 0.0
    sol[:] = 0.0
    px = py = 0.0           # the centre the last solve's weights (and ring) were about
    lim = float(h - 1)
    ring_n = 0.0
    for _ in range(max(1, passes)):
        px, py = sol[0], sol[1]
        ring_n = ring_plane(P, X, Y, h, px, py, r, noise, ring_in, ring_out, slope_k, plane)
        lines_centre(gx0, gy0, GX, GY, h, plane, px, py, reach, inv, noise, lim, sol)
    lx, ly = float(sol[0]), float(sol[1])   # the lines' centre
    b0, b1, b2 = plane[0], plane[1], plane[2]
    # The background-subtracted window, and the residual of the background in the last ring.
    lo = F32((r + ring_in) * (r + ring_in))
    hi = F32((r + ring_out) * (r + ring_out))
    rd2 = _0
    p32x, p32y = F32(px), F32(py)
    for k in range(npx):
        d = P[k] - b0 - b1 * X[k] - b2 * Y[k]
        D[k] = d
        dx = X[k] - p32x
        dy = Y[k] - p32y
        d2 = dx * dx + dy * dy
        rd2 += d * d if (d2 >= lo) & (d2 <= hi) else _0
    border_std = math.sqrt(float(rd2) / max(ring_n, 1.0))
    # Contrast: the background-subtracted maximum of the centre 3x3.
    a_n = -np.inf
    for i in range(h - 1, h + 2):
        for j in range(h - 1, h + 2):
            a_n = max(a_n, float(D[i * n + j]))
    a = max(a_n, 0.5 * noise + 1e-3)
    # The inside map's centroid about the lines' centre, then the blend.
    inside_moments(D, X, Y, h, a, lx, ly, reach, inv, mom)
    m0 = max(float(mom[0]), 1e-6)
    cx = lx + (1.0 - mix) * float(mom[1]) / m0
    cy = ly + (1.0 - mix) * float(mom[2]) / m0
    inside_moments(D, X, Y, h, a, cx, cy, reach, inv, mom)
    m0 = max(float(mom[0]), 1e-6)
    mxx, myy, mxy = float(mom[3]) / m0, float(mom[4]) / m0, float(mom[5]) / m0
    tr = mxx + myy
    det = mxx * myy - mxy * mxy
    disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
    # A uniform ellipse of semi-axes (A, B) has second moments A^2/4, B^2/4: full axes 4 sqrt(l).
    major = 4.0 * math.sqrt(max(tr / 2.0 + disc, 1e-6))
    minor = 4.0 * math.sqrt(max(tr / 2.0 - disc, 1e-6))
    angle = 0.5 * math.degrees(math.atan2(2.0 * mxy, mxx - myy))
    angle = (angle + 90.0) % 180.0 - 90.0
    fill = m0 / max(math.pi * major * minor / 4.0, 1e-6)
    out[0], out[1], out[2], out[3], out[4] = cx, cy, major, minor, angle
    ok = (math.isfinite(cx) and math.isfinite(cy) and abs(cx) < h - 1.5 and abs(cy) < h - 1.5
          and a_n > 0.5 * noise)
    out[5] = 1.0 if ok else 0.0
    return px, py, lx, ly, cx, cy, a, mxx, myy, mxy, det, border_std, fill


@njit(**JIT)
def measure_extra(h, r, noise, c, S, state, extra):
    """The stage-2 measurements of the blob :func:`measure_one` just measured in ``S``; writes ``extra``.

    Step 3's edge and core measurements (the order of ``MEASURE_NAMES``); ``state``
    is what :func:`measure_one` returned.
    """
    px, py, lx, ly, cx, cy, a, mxx, myy, mxy, det, border_std, fill = state
    t_in, t_out, core_q = c[0], c[1], c[6]
    inv = 1.0 / (t_out - t_in)
    reach = r + t_out
    n = 2 * h + 1
    m = n - 1
    mpx = m * m
    X, Y, D, gx0, gy0, GX, GY, small = S[1], S[2], S[3], S[4], S[5], S[6], S[7], S[12]
    b0, b1, b2 = small[0], small[1], small[2]
    gsum = small[11:15]
    gradient_sums(gx0, gy0, m, gsum)
    # The core: q < core_q inside the moment ellipse (q = 1 on a uniform ellipse's edge).  Its
    # rows lie within sqrt(4 core_q myy) of the centre (more when the determinant was floored).
    mdet = max(det, 1e-6)
    ry = math.sqrt(4.0 * core_q * max(myy, 0.0) * mdet / det) if det > 0.0 else float(n)
    i0, i1 = rows(cy, ry, h, n)
    Dc, Xc, Yc = D[i0 * n:i1 * n], X[i0 * n:i1 * n], Y[i0 * n:i1 * n]
    c32x, c32y = F32(cx), F32(cy)
    qxx, qyy, qxy, q4, cq = F32(mxx), F32(myy), F32(2.0 * mxy), F32(4.0 * mdet), F32(core_q)
    nc = cs = cs2 = _0
    for k in range(len(Xc)):
        dx = Xc[k] - c32x
        dy = Yc[k] - c32y
        f = _1 if (qyy * dx * dx - qxy * dx * dy + qxx * dy * dy) / q4 < cq else _0
        nc += f
        cs += f * Dc[k]
        cs2 += f * (Dc[k] * Dc[k])
    nc = max(float(nc), 1.0)
    cs, cs2 = float(cs), float(cs2)
    cmean = cs / nc
    core_std = math.sqrt(max(cs2 / nc - cmean * cmean, 0.0)) / a
    # How well the last solve's lines (weights about the centre they were solved about) meet
    # the lines' centre; the edge's sharpness and its share of the window's gradient energy
    # (weights about the answer).
    nz = F32(noise * noise)
    p32x, p32y, l32x, l32y = F32(px), F32(py), F32(lx), F32(ly)
    reach32, inv32 = F32(reach), F32(inv)
    wd2 = wg2_last = wg2 = wg = _0
    i0, i1 = rows(py, reach, h - 0.5, m)
    j0, j1 = rows(cy, reach, h - 0.5, m)
    k0, k1 = min(i0, j0) * m, max(i1, j1) * m
    gxv, gyv, GXv, GYv = gx0[k0:k1], gy0[k0:k1], GX[k0:k1], GY[k0:k1]
    for k in range(len(GXv)):
        gxx = GXv[k]
        gyy = GYv[k]
        gx = gxv[k] - b1
        gy = gyv[k] - b2
        g2 = gx * gx + gy * gy
        ex, ey = gxx - p32x, gyy - p32y
        w = taper(ex * ex + ey * ey, reach32, inv32) * max(g2 - nz, _0)
        dist = gx * (l32y - gyy) - gy * (l32x - gxx)
        wd2 += w * dist * dist
        wg2_last += w * g2
        ex, ey = gxx - c32x, gyy - c32y
        wt = taper(ex * ex + ey * ey, reach32, inv32)
        wg2 += wt * g2
        wg += wt * math.sqrt(g2)
    wd2, wg2_last, wg2, wg = float(wd2), float(wg2_last), float(wg2), float(wg)
    b0, b1, b2 = float(b0), float(b1), float(b2)
    # sum (g - b)^2 over the window, expanded: the plane's slope is one number per blob.
    g2_all = (float(gsum[2]) + float(gsum[3]) - 2.0 * (b1 * float(gsum[0]) + b2 * float(gsum[1]))
              + mpx * (b1 * b1 + b2 * b2))
    line_rms = math.sqrt(wd2 / max(wg2_last, 1e-9))
    sharp = wg2 / max(wg, 1e-6) / a
    edge_share = wg2 / max(g2_all, 1e-6)
    extra[0] = a
    extra[1] = line_rms
    extra[2] = sharp
    extra[3] = border_std
    extra[4] = math.sqrt(b1 * b1 + b2 * b2) * r / a
    extra[5] = fill
    extra[6] = edge_share
    extra[7] = b0 + b1 * cx + b2 * cy
    extra[8] = core_std


@njit(**JIT_EXACT)
def measured_again(x, y, major, cx, cy, rr, again):
    """Whether a blob measured at ``(x, y)`` in a window about ``(cx, cy)`` with weights' radius ``rr`` is measured again.

    :func:`carapost.core.blobs.detector.fit_candidates`' test: its centre moved
    over half a pixel or its next weights' radius ``clip(again[0] * major,
    again[1], again[2])`` differs by over a tenth.  Returns ``(again, radius)``.
    """
    r_new = min(max(again[0] * major, again[1]), again[2])
    moved = math.hypot(x - cx, y - cy)
    return (moved > 0.5) | (abs(r_new - rr) > 0.1 * rr), r_new


@njit(**JIT)
def measure_at(img, ix, iy, hs, r0, noise, passes, c, out, extra, start, again):
    """Measure blobs in windows of ``img`` centred on pixels ``(ix, iy)``, half-sizes ``hs``.

    Step 3 for every blob of a frame (one call per round): copies each window
    (where one reaches past the image's edge, the edge replicated) and runs
    :func:`measure_one` and :func:`measure_extra`.  ``out`` is ``(N, 6)``, ``extra``
    ``(N, 9)``.  With ``again`` (:func:`measured_again`'s constants; empty: none),
    a blob that is ``ok`` and will be measured again from its window's start
    ``start[k] = (x, y, weights' radius)`` (``img``'s pixels) is not given its
    stage-2 measurements (its ``extra`` row is NaN): the next round's replace them,
    or, where the first round's merge makes it not ``ok``, nothing uses them.
    """
    H, W = img.shape
    hmax = 1
    for k in range(len(hs)):
        hmax = max(hmax, hs[k])
    S = np.empty((13, (2 * hmax + 1) ** 2), np.float32)
    P, X, Y, GX, GY = S[0], S[1], S[2], S[6], S[7]
    h_grid = -1
    # By window size, so that the pixels' coordinates are laid out once per size.
    for k in np.argsort(hs, kind="mergesort"):
        h = hs[k]
        n = 2 * h + 1
        if h != h_grid:
            h_grid = h
            for i in range(n):
                for j in range(n):
                    X[i * n + j] = j - h
                    Y[i * n + j] = i - h
            for i in range(n - 1):
                for j in range(n - 1):
                    GX[i * (n - 1) + j] = j - h + 0.5
                    GY[i * (n - 1) + j] = i - h + 0.5
        x0, y0 = ix[k] - h, iy[k] - h
        # Unsigned indices, not row views (a view is an atomic reference count taken and dropped).
        if x0 >= 0 and y0 >= 0 and x0 + n <= W and y0 + n <= H:
            for i in range(n):
                sy, d = np.uint64(y0 + i), np.uint64(i * n)
                for j in range(n):
                    P[d + np.uint64(j)] = img[sy, np.uint64(x0 + j)]
        else:
            # A window reaching past the image's edge: the edge replicated (as cv2.BORDER_REPLICATE pads).
            for i in range(n):
                sy, d = np.uint64(min(max(y0 + i, 0), H - 1)), np.uint64(i * n)
                for j in range(n):
                    P[d + np.uint64(j)] = img[sy, np.uint64(min(max(x0 + j, 0), W - 1))]
        r = max(float(r0[k]), 1.0)
        o = out[k]
        state = measure_one(h, r, noise, passes, c, S, o)
        if (len(again) and o[5] > 0.5
                and measured_again(np.float64(ix[k]) + o[0], np.float64(iy[k]) + o[1], o[2], start[k, 0], start[k, 1],
                                   start[k, 2], again)[0]):
            extra[k, :] = np.nan
        else:
            measure_extra(h, r, noise, c, S, state, extra[k])


@njit(**JIT_EXACT)
def fit_round(img, cx, cy, rr, todo, noise, passes, windows, border, c, out, ok, extra, again):
    """One round of :func:`carapost.core.blobs.detector.fit_candidates` for the blobs ``todo`` (in place).

    Each blob's window is centred on its pixel nearest ``(cx, cy)`` (clipped to the
    image; where a window reaches past the image's edge, the edge is replicated), sized by ``rr``
    (:func:`carapost.core.blobs.centre.window_for`), and measured (:func:`measure_at`
    with the radius as float32, as :func:`carapost.core.blobs.centre.measure_at`
    passes it); writes the full-resolution ``out[0:5, k]`` (x, y, major, minor, angle),
    ``ok[k]`` and ``extra[k]``, as the numpy glue did, operation for operation.  With
    ``again`` (:func:`measured_again`'s constants), the ``extra`` of the blobs another
    round will measure again is NaN (:func:`measure_at`).
    """
    h, w = img.shape
    m = len(todo)
    ix = np.empty(m, np.int64)
    iy = np.empty(m, np.int64)
    half = np.empty(m, np.int64)
    r = np.empty(m)
    start = np.empty((m, 3))
    nw = len(windows)
    for q in range(m):
        k = todo[q]
        need = math.ceil(rr[k] + border + 0.5)
        s = 0
        while s < nw and windows[s] < need:
            s += 1
        half[q] = windows[min(s, nw - 1)]
        ix[q] = min(max(np.int64(np.rint(cx[k])), 0), w - 1)
        iy[q] = min(max(np.int64(np.rint(cy[k])), 0), h - 1)
        r[q] = np.float64(np.float32(rr[k]))
        start[q, 0], start[q, 1], start[q, 2] = cx[k], cy[k], rr[k]
    res = np.zeros((m, 6))
    ext = np.zeros((m, extra.shape[1]))
    measure_at(img, ix, iy, half, r, noise, passes, c, res, ext, start, again)
    for q in range(m):
        k = todo[q]
        out[0, k] = np.float64(ix[q]) + res[q, 0]
        out[1, k] = np.float64(iy[q]) + res[q, 1]
        out[2, k] = res[q, 2]
        out[3, k] = res[q, 3]
        out[4, k] = res[q, 4]
        ok[k] = res[q, 5] > 0.5
        for j in range(extra.shape[1]):
            extra[k, j] = ext[q, j]


@njit(**JIT_EXACT)
def next_round(todo, ok, out, cx, cy, rr, again):
    """The blobs of ``todo`` measured again (:func:`carapost.core.blobs.detector.fit_candidates`).

    Of the ``ok`` ones, those :func:`measured_again` says (``again`` its constants);
    every ``ok`` one's ``(cx, cy, rr)`` becomes its answer (in place).
    """
    redo = np.empty(len(todo), np.int64)
    na = 0
    for q in range(len(todo)):
        k = todo[q]
        if not ok[k]:
            continue
        yes, r_new = measured_again(out[0, k], out[1, k], out[2, k], cx[k], cy[k], rr[k], again)
        if yes:
            redo[na] = k
            na += 1
        cx[k], cy[k], rr[k] = out[0, k], out[1, k], r_new
    return redo[:na]


@njit(inline="always", **JIT_EXACT)
def _clip(v, lo, hi):
    """``np.clip`` of one float64: NaN stays NaN."""
    if v != v:
        return v
    return min(max(v, lo), hi)


@njit(**JIT_EXACT)
def fit_features(logit1, cx, cy, cr, x, y, major, minor, extra, rescued, noise, white, F):
    """Stage 2's inputs of fitted blobs (:data:`~carapost.core.blobs.model.FIT_FEATURE_NAMES`) into ``F`` (float32).

    Row by row in float64, NaN (the measurements of a blob the merge dropped) propagated
    as ``np.clip`` and ``np.maximum`` do: the same float32 features as the numpy
    expressions they replace (``tests/test_blob_measure_kernel.py``), which were ~60 array
    operations on ~250 rows, ~0.05 ms a call holding the interpreter lock.  ``logit1`` is
    stage 1's logit, ``(cx, cy, cr)`` the candidates' centres and radii, ``extra`` the blobs'
    measurements (:data:`~carapost.core.blobs.centre.MEASURE_NAMES`), ``rescued`` whether
    each ellipse came from its candidate's own edge, ``white`` the blobs' colour (the skin's
    light under a black blob is 255 less its background on the inverted image).
    """
    for i in range(len(x)):
        contrast, line_rms, sharp, border_std = extra[i, 0], extra[i, 1], extra[i, 2], extra[i, 3]
        slope, fill, edge_share, background, core_std = extra[i, 4], extra[i, 5], extra[i, 6], extra[i, 7], extra[i, 8]
        light = background if white else 255.0 - background
        r = _max_nan(0.5 * major[i], 0.5)
        moved = math.hypot(x[i] - cx[i], y[i] - cy[i])
        F[i, 0] = _clip(np.float64(logit1[i]), -30.0, 30.0)
        F[i, 1] = math.log(_clip(contrast, 1e-3, 1e4) / noise)
        F[i, 2] = math.log(_clip(major[i], 0.5, 500.0))
        F[i, 3] = _clip(minor[i] / _max_nan(major[i], 1e-6), 0.0, 1.0)
        F[i, 4] = _clip(line_rms / r, 0.0, 5.0)
        F[i, 5] = math.log(_clip(sharp, 1e-3, 10.0))
        F[i, 6] = _clip(border_std / _max_nan(contrast, 1e-3), 0.0, 5.0)
        F[i, 7] = _clip(slope, 0.0, 10.0)
        F[i, 8] = _clip(fill, 0.0, 5.0)
        F[i, 9] = _clip(edge_share, 0.0, 1.0)
        F[i, 10] = _clip(moved / _max_nan(cr[i], 1.0), 0.0, 5.0)
        F[i, 11] = _clip(contrast / _max_nan(light, 1.0), 0.0, 5.0)
        F[i, 12] = _clip(core_std, 0.0, 5.0)
        F[i, 13] = 1.0 if rescued[i] else 0.0
