"""Step 5 of blob detection: the centre from the dot's painted edge.

The measurement of :mod:`.centre` weighs intensities, so whatever changes the
light around a dot moves its centre: a lip band or a brow on one side, the
shading of a curved cheek, the dark half of a nostril, the brim's oblique dots
whose far side is dimmer.  The paint's *edge*, though, is where the image
changes fastest, whatever the levels on either side of it: a blurred step's
steepest point is the step, for any step height.  So each detection's centre
is measured again here from its outline (docs/blobs.md, step 5):

1. along ``RAYS`` normals of the measured ellipse, the outward fall of the
   Sobel gradient (bicubic between pixels) is sampled every ``STEP`` px for
   ``REACH`` px either side; its maximum, refined by a parabola, is an edge point;
2. rays whose peak is weak (under ``WEAK`` of the blob's median peak: a gap in
   the edge, a brow hair or a neighbouring feature) are left out; so are, for
   black dots (whose paint is flat), rays with no paint just inside their edge
   point: ``INSIDE`` px in, the level falls short of the dot's by ``FLAT`` of the
   edge's height more than on the dot's median ray (brow hair lighter than the
   paint but darker than the skin, whose outer edge is the ray's steepest);
3. a conic is fitted to the edge points (least squares), three times, dropping
   points more than three robust deviations off the last fit; its centre is
   the edge's centre.

A blob keeps its first centre when the edge does not make a clean ellipse (too
few rays left, points scattered more than ``MAX_SCATTER`` px about the fit, or a
centre more than ``MAX_MOVE`` minor semi-axes away: a different shape was found)
and when the move is within the fit's own noise (``TRUST``).  A centre moved
more than ``AGAIN`` px was measured from an ellipse off the dot, whose normals
cut its edge obliquely: the step runs once more from there, and its answer is
kept when it converges (``AGAIN_SHRINK``).

Each blob is one compiled loop (numba, the options of :mod:`.measure_kernel`):
the gradients of the few hundred pixels its rays cross, the rays, the fits.
The numpy version it replaced (full-frame Sobel, ``cv2.remap``, batched
eigen-decompositions; 6.4 ms a frame) is kept as a test reference,
``tests/blob_edges_reference.py``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import JIT, JIT_EXACT

#: Normals sampled around each ellipse.
RAYS = 48
#: How far either side of the measured ellipse the edge is looked for, px.
REACH = 3.0
#: Sampling step along a normal, px.
STEP = 0.25
#: A ray is used when its peak is at least this share of the blob's median peak.
WEAK = 0.3
#: Share of the rays that must remain for the edge to be trusted.
MIN_RAYS = 0.6
#: Largest robust scatter of the edge points about the fitted conic, px.
MAX_SCATTER = 0.3
#: Largest move from the first centre, in minor semi-axes.
MAX_MOVE = 1.0
#: A move smaller than this many of the edge fit's own standard errors is noise: the first centre
#: (from every pixel's intensity, close to the Cramer-Rao bound on a clean dot) is kept; from there
#: to twice that the centre moves over to the edge's gradually.
TRUST = 8.0
#: ... for a blob on textured or shaded skin (:data:`.detector.TEXTURED`): there the intensity centre is pulled by
#: the skin around the dot, and the edge is the better answer once it moves further than its own noise
#: (black centre RMS on the benchmark's frames 0.103 -> 0.098 px, white 0.151 -> 0.144; isolated discs
#: unchanged, since their surround is flat).
TRUST_TEXTURED = 2.0
#: A centre the edge moved further than this (px) is measured from its edge once more, from there; the
#: second answer is kept when it moves the centre less than AGAIN_SHRINK times the first move (it converges).
AGAIN = 0.8
AGAIN_SHRINK = 1.0
#: A blob measured this many times its candidate's radius (semi-major axis) may be a dot measured
#: together with a darker region it touches.
MERGED = 1.8
#: Along the major axis of an elongated blob the edge's centre is averaged with the first (intensity)
#: centre (``refine_centres(along=True)``): the first centre's weight is ALONG_MAX at a minor/major ratio
#: of ALONG_THIN or less and falls linearly to 0 at ALONG_ROUND.  The ends of an oblique dot's ellipse are
#: sharp beside the blur, and shading and texture move them: along that axis the edge is no better than
#: the intensity, and their errors are independent enough that the mean beats either (docs/blobs.md,
#: "Session 19: an oblique dot's centre along its major axis").
ALONG_MAX, ALONG_THIN, ALONG_ROUND = 0.6, 0.3, 0.7
#: Robust fitting rounds.
ROUNDS = 3
#: Arcs tried when the whole edge is not a clean ellipse (0: none), and the distance within which an
#: edge point agrees with an arc's ellipse, px.
ARCS = 8
INLIER = 0.35
#: The arcs are tried only when the whole edge's conic is centred more than this far (px) from the blob: white dots
#: ``ARC_MOVE``, black (flat paint) ``ARC_MOVE_FLAT``.  (0.3 for both until session 34: from 0.05 px black centre RMS
#: 0.0868 -> 0.0839 px, its brow dots 0.257 -> 0.228, held out 0.0972 -> 0.0952; white 0.1195 -> 0.1193, held out
#: 0.1337 -> 0.1327, but on the white clutter frames 0.1088 -> 0.1198.)
ARC_MOVE, ARC_MOVE_FLAT = 0.3, 0.05
#: With flat paint (black dots), a ray is dropped when the level INSIDE px inside its edge point falls
#: short of the dot's by FLAT of the edge's height more than the dot's median ray does (0: no test).
FLAT = 0.05
INSIDE = 1.5
#: ... on dots whose fitted minor semi-axis is at least this (px): a thinner one is blurred right through.
FLAT_MINOR = 2.0

_SAMPLES = int(round(2 * REACH / STEP)) + 1
#: The coarse search's step, in samples.
COARSE = 4
_NCOARSE = (_SAMPLES - 1) // COARSE + 1
#: A ray's edge is its innermost local peak at least this share of the ray's highest.
INNER = 0.6
#: The least minor semi-axis of a start ellipse (:func:`edge_ellipses`' ``start``), px.  A thin dot's threshold
#: component measures 1.1-1.7 px across (semi-axis); a start thinner than this, from a region of one or two pixel
#: rows, would put the rays across the dot's width all at its centre line.
MIN_START_MINOR = 0.7
_COS = np.cos(2.0 * np.pi * np.arange(RAYS) / RAYS)
_SIN = np.sin(2.0 * np.pi * np.arange(RAYS) / RAYS)


@njit(**JIT)
def _cubic(t):
    """Bicubic weights of the four taps around fraction ``t`` (OpenCV's INTER_CUBIC, A = -0.75).

    Returned as four numbers, not written to an array: kept in registers, the fine
    search's samples cost a fifth less (the same arithmetic, the same results).
    """
    A = -0.75
    x = t + 1.0
    w0 = ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A
    w1 = ((A + 2.0) * t - (A + 3.0)) * t * t + 1.0
    u = 1.0 - t
    w2 = ((A + 2.0) * u - (A + 3.0)) * u * u + 1.0
    w3 = 1.0 - w0 - w1 - w2
    return w0, w1, w2, w3


@njit(**JIT)
def _sobel_box(img, x0, y0, nx, ny, buf, gx, gy):
    """Sobel gradients (/8) of the box ``[x0, x0+nx) x [y0, y0+ny)``, image edges replicated.

    ``gx``, ``gy`` are ``(ny, nx + 2)`` (columns ``nx``, ``nx + 1`` are not used) and ``buf`` is
    ``(ny + 2) (nx + 2)`` scratch: the box with a pixel more on each side, as float, with that row
    stride, so that each gradient is one loop over the flat box (loops over rows of 18-40 pixels
    ran mostly in their scalar remainders).
    """
    H, W = img.shape
    S = nx + 2
    if x0 >= 1 and y0 >= 1 and x0 + nx + 1 <= W and y0 + ny + 1 <= H:
        for j in range(ny + 2):
            src = img[y0 - 1 + j, x0 - 1:x0 - 1 + S]
            dst = buf[j * S:j * S + S]
            for i in range(S):
                dst[i] = float(src[i])
    else:
        for j in range(ny + 2):
            row = img[min(max(y0 - 1 + j, 0), H - 1)]
            dst = buf[j * S:j * S + S]
            for i in range(S):
                dst[i] = float(row[min(max(x0 - 1 + i, 0), W - 1)])
    L = ny * S - 2
    fx, fy = gx.reshape(ny * S)[0:L], gy.reshape(ny * S)[0:L]
    a, b, c = buf[0:L], buf[1:L + 1], buf[2:L + 2]
    d, f = buf[S:L + S], buf[S + 2:L + S + 2]
    g, h, k = buf[2 * S:L + 2 * S], buf[2 * S + 1:L + 2 * S + 1], buf[2 * S + 2:L + 2 * S + 2]
    for q in range(L):
        fx[q] = ((c[q] + 2.0 * f[q] + k[q]) - (a[q] + 2.0 * d[q] + g[q])) * 0.125
    for q in range(L):
        fy[q] = ((g[q] + 2.0 * h[q] + k[q]) - (a[q] + 2.0 * b[q] + c[q])) * 0.125


@njit(inline="always", **JIT)
def _sample(gx, gy, x0, y0, px, py):
    """Bicubic gradient at image point ``(px, py)`` from the box gradients (the image's edge replicated)."""
    ix, iy = math.floor(px), math.floor(py)
    w0, w1, w2, w3 = _cubic(px - ix)
    v0, v1, v2, v3 = _cubic(py - iy)
    # The box reaches 2 px beyond every sample (see _edge_points): no tap needs clamping, so the
    # indices are never negative (unsigned: numba then tests no wrap-around per tap).
    # Two-dimensional indices, not row views: a view is an atomic reference count taken and
    # dropped (two locked instructions), and these taps were ~30,000 of them a frame.
    c0, r0 = np.uint64(int(ix) - 1 - x0), np.uint64(int(iy) - 1 - y0)
    c1, c2, c3 = c0 + np.uint64(1), c0 + np.uint64(2), c0 + np.uint64(3)
    sx = sy = 0.0
    for j in range(4):
        r = r0 + np.uint64(j)
        ax = w0 * gx[r, c0] + w1 * gx[r, c1] + w2 * gx[r, c2] + w3 * gx[r, c3]
        ay = w0 * gy[r, c0] + w1 * gy[r, c1] + w2 * gy[r, c2] + w3 * gy[r, c3]
        wy = v0 if j == 0 else (v1 if j == 1 else (v2 if j == 2 else v3))
        sx += wy * ax
        sy += wy * ay
    return sx, sy


@njit(inline="always", **JIT)
def _bilinear(gx, gy, x0, y0, px, py):
    """Bilinear gradient at image point ``(px, py)`` from the box gradients (for the coarse search)."""
    ix, iy = math.floor(px), math.floor(py)
    fx, fy = px - ix, py - iy
    # The box reaches 2 px beyond every sample (see _edge_points): the taps need no clamping, and
    # unsigned indices need no wrap-around test.
    c0, r0 = np.uint64(int(ix) - x0), np.uint64(int(iy) - y0)
    c1, r1 = c0 + np.uint64(1), r0 + np.uint64(1)
    w00, w01, w10, w11 = (1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy
    return (w00 * gx[r0, c0] + w01 * gx[r0, c1] + w10 * gx[r1, c0] + w11 * gx[r1, c1],
            w00 * gy[r0, c0] + w01 * gy[r0, c1] + w10 * gy[r1, c0] + w11 * gy[r1, c1])


@njit(inline="always", **JIT)
def _fall(gx, gy, x0, y0, px, py, nx, ny, t):
    """The outward fall of intensity at ``t`` along the normal ``(nx, ny)`` from ``(px, py)`` (bicubic)."""
    sx, sy = _sample(gx, gy, x0, y0, px + nx * t, py + ny * t)
    return -(sx * nx + sy * ny)


@njit(**JIT)
def _box_side(r):
    """Side (px) of the box of gradients that the rays of an ellipse of largest semi-axis ``r`` cross.

    (:func:`_edge_points`: the samples and their bicubic taps.)
    """
    return int(math.ceil(2.0 * (r + REACH + 3.0))) + 2


@njit(**JIT)
def _scratch(r):
    """Scratch of :func:`_fit_edge` for ellipses of largest semi-axis up to ``r``: ``(buf, box)``.

    ``buf`` is ``(10, RAYS)`` (rows 0-6 the rays' points and fits, 7-9 working rows), ``box`` the
    gradients' box (:func:`_edge_points`).
    """
    n = _box_side(r)
    return np.empty((10, RAYS)), np.empty((3, (n + 2) * (n + 2)))


@njit(**JIT)
def _edge_points(img, cx, cy, a, b, th, ex, ey, peak, box, fall, coarse):
    """One blob's edge point and peak fall on each ray (step 5.1).

    ``box`` is ``(3, >= (n + 2)^2)`` scratch for the gradients of the box the rays
    cross (:func:`_box_side`), ``fall`` and ``coarse`` scratch rows (the caller's:
    allocating them at every call cost more than filling them).
    """
    # Samples lie within max(a, b) + REACH of the centre (the normals leave the ellipse at most that far);
    # the bicubic taps reach 2 px beyond.
    reach = max(a, b) + REACH + 3.0
    x0, y0 = int(math.floor(cx - reach)), int(math.floor(cy - reach))
    n = _box_side(max(a, b))
    if (n + 2) * (n + 2) > box.shape[1]:
        box = np.empty((3, (n + 2) * (n + 2)))      # the caller sized it for smaller ellipses
    gx = box[0, :n * (n + 2)].reshape((n, n + 2))
    gy = box[1, :n * (n + 2)].reshape((n, n + 2))
    _sobel_box(img, x0, y0, n, n, box[2], gx, gy)
    ca, sa = math.cos(th), math.sin(th)
    for k in range(RAYS):
        c, s = _COS[k], _SIN[k]
        ux, uy = a * c, b * s
        px, py = cx + ca * ux - sa * uy, cy + sa * ux + ca * uy
        # The ellipse's outward normal at parameter phi is (b cos phi, a sin phi) in its own axes.
        m0, m1 = b * c, a * s
        norm = math.sqrt(m0 * m0 + m1 * m1)
        m0, m1 = m0 / norm, m1 / norm
        nx, ny = ca * m0 - sa * m1, sa * m0 + ca * m1
        # Coarse search, bilinear every COARSE steps; then bicubic at the peak and its neighbours (the
        # parabola's three points), moving along while the peak is not in the middle.
        top = -np.inf
        for j in range(_NCOARSE):
            t = -REACH + j * COARSE * STEP
            sx, sy = _bilinear(gx, gy, x0, y0, px + nx * t, py + ny * t)
            coarse[j] = -(sx * nx + sy * ny)
            top = max(top, coarse[j])
        # The innermost clear peak, not the highest: a dot touching a darker region (a lower lip's dot
        # against the open mouth, a nose tip above the nostrils' shadow) has its own edge inside, and
        # the region's edge, often steeper, farther out.
        best = 0
        for j in range(_NCOARSE):
            if (coarse[j] >= INNER * top and (j == 0 or coarse[j] >= coarse[j - 1])
                    and (j == _NCOARSE - 1 or coarse[j] >= coarse[j + 1])):
                best = j * COARSE
                break
        best = min(max(best, 1), _SAMPLES - 2)
        for q in range(best - 1, best + 2):
            fall[q] = _fall(gx, gy, x0, y0, px, py, nx, ny, -REACH + q * STEP)
        for _ in range(COARSE):
            if fall[best - 1] > fall[best] and best > 1:
                best -= 1
                fall[best - 1] = _fall(gx, gy, x0, y0, px, py, nx, ny, -REACH + (best - 1) * STEP)
            elif fall[best + 1] > fall[best] and best < _SAMPLES - 2:
                best += 1
                fall[best + 1] = _fall(gx, gy, x0, y0, px, py, nx, ny, -REACH + (best + 1) * STEP)
            else:
                break
        g0, g1, g2 = fall[best - 1], fall[best], fall[best + 1]
        curv = g0 - 2.0 * g1 + g2
        off = 0.5 * (g0 - g2) / curv if curv < 0 else 0.0
        t = -REACH + best * STEP + min(max(off, -1.0), 1.0) * STEP
        ex[k], ey[k], peak[k] = px + nx * t, py + ny * t, g1


@njit(inline="always", **JIT)
def _forward(a, m, r):
    """``x`` with ``M x = a`` (6 unknowns, forward substitution), ``M`` lower triangular.

    ``r`` holds the reciprocals of ``M``'s diagonal and ``m`` its strict lower triangle
    row by row (``m10, m20, m21, m30, ...``); all three are tuples (kept in registers).
    """
    x0 = a[0] * r[0]
    x1 = (a[1] - m[0] * x0) * r[1]
    x2 = (a[2] - m[1] * x0 - m[2] * x1) * r[2]
    x3 = (a[3] - m[3] * x0 - m[4] * x1 - m[5] * x2) * r[3]
    x4 = (a[4] - m[6] * x0 - m[7] * x1 - m[8] * x2 - m[9] * x3) * r[4]
    x5 = (a[5] - m[10] * x0 - m[11] * x1 - m[12] * x2 - m[13] * x3 - m[14] * x4) * r[5]
    return x0, x1, x2, x3, x4, x5


@njit(error_model="numpy", **JIT)       # a zero vector's norm divides as numpy does (nan), not raises
def _smallest_eigenvector(s):
    """Unit eigenvector of the smallest eigenvalue of the 6x6 scatter matrix (inverse iteration).

    A conic through points on an ellipse makes that eigenvalue (the residual sum
    of squares) far below the next, so a few steps from a circle converge; a
    shift of 1e-12 of the trace keeps the Cholesky factor defined when the points
    fit exactly.  (LAPACK's eigh, three per blob, cost more than everything else.)
    ``s`` is the matrix's upper triangle row by row (:func:`_scatter`); the
    vector is returned as a tuple ``(A, B, C, D, E, F)``.  Written out in scalars:
    the Cholesky factor and the iterate stay in registers (as loops over small
    arrays they were five allocations a solve and a fifth of the from-edge
    search's time); both triangular solves are :func:`_forward`, the second on
    the unknowns in reverse order.
    """
    (s00, s01, s02, s03, s04, s05, s11, s12, s13, s14, s15, s22, s23, s24, s25, s33, s34, s35, s44, s45,
     s55) = s
    eps = 1e-12 * (s00 + s11 + s22 + s33 + s44 + s55) + 1e-300
    # Cholesky factor L (lower), column by column: L[j, j] = sqrt(S[j, j] + eps - sum_k L[j, k]^2),
    # L[i, j] = (S[i, j] - sum_k L[i, k] L[j, k]) / L[j, j], the sums over k < j in order.
    l00 = math.sqrt(max(s00 + eps, 1e-300))
    l10, l20, l30, l40, l50 = s01 / l00, s02 / l00, s03 / l00, s04 / l00, s05 / l00
    l11 = math.sqrt(max(s11 + eps - l10 * l10, 1e-300))
    l21 = (s12 - l20 * l10) / l11
    l31 = (s13 - l30 * l10) / l11
    l41 = (s14 - l40 * l10) / l11
    l51 = (s15 - l50 * l10) / l11
    l22 = math.sqrt(max(s22 + eps - l20 * l20 - l21 * l21, 1e-300))
    l32 = (s23 - l30 * l20 - l31 * l21) / l22
    l42 = (s24 - l40 * l20 - l41 * l21) / l22
    l52 = (s25 - l50 * l20 - l51 * l21) / l22
    l33 = math.sqrt(max(s33 + eps - l30 * l30 - l31 * l31 - l32 * l32, 1e-300))
    l43 = (s34 - l40 * l30 - l41 * l31 - l42 * l32) / l33
    l53 = (s35 - l50 * l30 - l51 * l31 - l52 * l32) / l33
    l44 = math.sqrt(max(s44 + eps - l40 * l40 - l41 * l41 - l42 * l42 - l43 * l43, 1e-300))
    l54 = (s45 - l50 * l40 - l51 * l41 - l52 * l42 - l53 * l43) / l44
    l55 = math.sqrt(max(s55 + eps - l50 * l50 - l51 * l51 - l52 * l52 - l53 * l53 - l54 * l54, 1e-300))
    # The diagonal's reciprocals once: the solves below are then chains of products, not of divisions.
    r0, r1, r2, r3, r4, r5 = 1.0 / l00, 1.0 / l11, 1.0 / l22, 1.0 / l33, 1.0 / l44, 1.0 / l55
    z0, z1, z2, z3, z4, z5 = 1.0, 0.0, 1.0, 0.0, 0.0, -1.0
    lower = (l10, l20, l21, l30, l31, l32, l40, l41, l42, l43, l50, l51, l52, l53, l54)
    # L^T is upper triangular: its solve is a lower one with the unknowns in reverse order.
    upper = (l54, l53, l43, l52, l42, l32, l51, l41, l31, l21, l50, l40, l30, l20, l10)
    r, rr = (r0, r1, r2, r3, r4, r5), (r5, r4, r3, r2, r1, r0)
    for _ in range(6):
        y = _forward((z0, z1, z2, z3, z4, z5), lower, r)                         # L y = z
        z5, z4, z3, z2, z1, z0 = _forward((y[5], y[4], y[3], y[2], y[1], y[0]), upper, rr)   # L^T z = y
        norm = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2 + z3 * z3 + z4 * z4 + z5 * z5)
        z0, z1, z2, z3, z4, z5 = z0 / norm, z1 / norm, z2 / norm, z3 / norm, z4 / norm, z5 / norm
    return z0, z1, z2, z3, z4, z5


@njit(inline="always", **JIT)
def _conic_fit(u, v, w, scale, res):
    """Weighted algebraic conic fit of points ``(u, v)`` (scaled); centre and geometric residuals (px).

    Returns ``(x0, y0, ok)`` in the scaled units; fills ``res``.
    """
    x0, y0, ok, _z = _conic_solve(u, v, w, scale, res)
    return x0, y0, ok


@njit(**JIT_EXACT)                     # no fastmath: its sums stay in the points' order
def _scatter(u, v, w):
    """The conic fit's 6x6 scatter matrix of the points ``(u, v)`` whose weight ``w`` (0 or 1) is 1.

    The sum over the points of ``m m^T``, ``m = (u^2, u v, v^2, u, v, 1)``: its upper
    triangle (the matrix is symmetric: ``m_i m_j == m_j m_i`` exactly) in 21 running
    sums kept in registers and returned row by row as a tuple (no array to allocate),
    each in the points' order: the same sums, operation for operation, as
    accumulating into the matrix did, at a third of the time.  Inlined
    into :func:`_conic_solve` (``reassoc``), a plain loop was vectorised and its sums
    reordered (other last bits); the loop's exit on a negative weight (there is none)
    keeps it a scalar loop.
    """
    s00 = s01 = s02 = s03 = s04 = s05 = s11 = s12 = s13 = s14 = s15 = 0.0
    s22 = s23 = s24 = s25 = s33 = s34 = s35 = s44 = s45 = s55 = 0.0
    for k in range(len(u)):
        if w[k] < 0.0:
            break       # never (weights are 0 or 1): a loop with an exit is not vectorised
        if w[k] == 0.0:
            continue
        m0, m1, m2, m3, m4 = u[k] * u[k], u[k] * v[k], v[k] * v[k], u[k], v[k]
        s00 += m0 * m0
        s01 += m0 * m1
        s02 += m0 * m2
        s03 += m0 * m3
        s04 += m0 * m4
        s05 += m0 * 1.0
        s11 += m1 * m1
        s12 += m1 * m2
        s13 += m1 * m3
        s14 += m1 * m4
        s15 += m1 * 1.0
        s22 += m2 * m2
        s23 += m2 * m3
        s24 += m2 * m4
        s25 += m2 * 1.0
        s33 += m3 * m3
        s34 += m3 * m4
        s35 += m3 * 1.0
        s44 += m4 * m4
        s45 += m4 * 1.0
        s55 += 1.0 * 1.0
    return (s00, s01, s02, s03, s04, s05, s11, s12, s13, s14, s15, s22, s23, s24, s25, s33, s34, s35, s44, s45,
            s55)


@njit(inline="always", **JIT)
def _conic_solve(u, v, w, scale, res):
    """:func:`_conic_fit` that also returns the conic's coefficients ``(A, B, C, D, E, F)``."""
    z = _smallest_eigenvector(_scatter(u, v, w))
    A, B, C, D, E, F = z[0], z[1], z[2], z[3], z[4], z[5]
    det = 4.0 * A * C - B * B
    safe = det if abs(det) > 1e-12 else 1.0
    x0, y0 = (B * E - 2.0 * C * D) / safe, (B * D - 2.0 * A * E) / safe
    for k in range(len(u)):
        alg = A * u[k] * u[k] + B * u[k] * v[k] + C * v[k] * v[k] + D * u[k] + E * v[k] + F
        gu = 2.0 * A * u[k] + B * v[k] + D
        gv = B * u[k] + 2.0 * C * v[k] + E
        res[k] = abs(alg) / max(math.sqrt(gu * gu + gv * gv), 1e-12) * scale
    return x0, y0, det > 0, z


@njit(**JIT)
def _conic_axes(z, x0, y0):
    """Semi-axes ``(a, b)`` and angle (radians, of ``a``) of the ellipse conic ``z`` centred at ``(x0, y0)``.

    ``(0, 0, 0)`` when ``z`` is not a real ellipse.
    """
    A, B, C, D, E, F = z[0], z[1], z[2], z[3], z[4], z[5]
    if A + C < 0.0:                 # the eigenvector's sign is arbitrary
        A, B, C, D, E, F = -A, -B, -C, -D, -E, -F
    # The conic's value at its centre; the quadratic form's eigenvalues give the axes.
    f0 = A * x0 * x0 + B * x0 * y0 + C * y0 * y0 + D * x0 + E * y0 + F
    mean, half = 0.5 * (A + C), math.hypot(0.5 * (A - C), 0.5 * B)
    l1, l2 = mean - half, mean + half
    if l1 * l2 <= 0.0 or f0 * l1 >= 0.0:
        return 0.0, 0.0, 0.0
    return math.sqrt(-f0 / l1), math.sqrt(-f0 / l2), 0.5 * math.atan2(B, A - C) + 0.5 * math.pi


@njit(**JIT)
def _kth(a, n, q):
    """The ``q``-th smallest of ``a[:n]`` (no NaN), by partitioning ``a`` in place (quickselect)."""
    lo, hi = 0, n - 1
    while lo < hi:
        pivot = a[(lo + hi) >> 1]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        # a[lo:j+1] <= pivot <= a[i:hi+1]; between them, the pivot's value.
        if q <= j:
            hi = j
        elif q >= i:
            lo = i
        else:
            return a[q]
    return a[q]


@njit(inline="always", **JIT)
def _median(a, tmp):
    """``np.median(a)`` (no NaN in ``a``): the middle value, or the mean of the two middle ones, by selection.

    ``tmp`` (as long as ``a``; it may be ``a`` itself) is overwritten.  numba's ``np.median`` copied ``a`` into a
    new array at every call (an allocation, and its reference counts); the order statistics, and so the
    answer, are the same.
    """
    n = len(a)
    for i in range(n):
        tmp[i] = a[i]
    h = n >> 1
    if n & 1:
        return _kth(tmp, n, h)
    lo = _kth(tmp, n, h - 1)
    return (lo + _kth(tmp, n, h)) / 2


@njit(inline="always", **JIT)
def _median_of_used(r, w, vals):
    """The (lower) median of ``r`` where the weight ``w`` is positive; infinity when none is.

    As ``np.sort`` of those values then the middle one (NaN sorted last), by selection
    (``vals``, as long as ``r``, is overwritten).
    """
    k = 0
    nan = 0
    for i in range(len(r)):
        if w[i] > 0.0:
            x = r[i]
            if x != x:
                nan += 1
            else:
                vals[k] = x
                k += 1
    if k + nan == 0:
        return np.inf
    q = (k + nan - 1) // 2
    if q >= k:
        return np.nan
    return _kth(vals, k, q)


@njit(**JIT)
def _level(img, px, py):
    """Bilinear intensity of ``img`` at ``(px, py)`` (edges replicated)."""
    H, W = img.shape
    px = min(max(px, 0.0), W - 1.0)
    py = min(max(py, 0.0), H - 1.0)
    ix, iy = min(int(px), W - 2), min(int(py), H - 2)
    fx, fy = px - ix, py - iy
    return ((1 - fx) * (1 - fy) * img[iy, ix] + fx * (1 - fy) * img[iy, ix + 1]
            + (1 - fx) * fy * img[iy + 1, ix] + fx * fy * img[iy + 1, ix + 1])


@njit(**JIT)
def _drop_unpainted(img, cx, cy, a, b, th, ex, ey, peak, ratio, tmp):
    """Zero the peak of rays with no paint just inside their edge point (step 5.2, flat paint only).

    Black paint is flat: just inside a dot's edge the image is at the dot's own
    level, whatever the light.  A black dot touching a region darker than the
    skin but lighter than the paint (brow hair) has its edge there, and the ray's
    steepest fall is the region's outer edge, farther out: inside that point the
    level is the region's.  A ray whose level ``INSIDE`` px in falls short of the
    dot's by ``FLAT`` of its edge's height more than the dot's usual ray is dropped.
    ``ratio`` and ``tmp`` are scratch rows (``RAYS`` long).
    """
    ca, sa = math.cos(th), math.sin(th)
    vals = tmp[:9]
    vals[0] = _level(img, cx, cy)
    for j in range(8):
        c, s = math.cos(j * math.pi / 4.0), math.sin(j * math.pi / 4.0)
        ux, uy = 0.35 * a * c, 0.35 * b * s
        vals[j + 1] = _level(img, cx + ca * ux - sa * uy, cy + sa * ux + ca * uy)
    core = _median(vals, vals)
    m = 0
    for k in range(RAYS):
        ratio[k] = np.nan
        if peak[k] <= 0.0:
            continue
        dx, dy = ex[k] - cx, ey[k] - cy
        r = math.sqrt(dx * dx + dy * dy)
        if r < 1e-6:
            continue
        dx, dy = dx / r, dy / r
        inside = _level(img, ex[k] - dx * min(INSIDE, 0.5 * r), ey[k] - dy * min(INSIDE, 0.5 * r))
        outside = _level(img, ex[k] + dx * INSIDE, ey[k] + dy * INSIDE)
        if core - outside > 0.0:
            ratio[k] = (core - inside) / (core - outside)
            m += 1
    if m < MIN_RAYS * RAYS:
        return 0
    # np.nanmedian: the median of the rays that have a ratio.
    m = 0
    for k in range(RAYS):
        if ratio[k] == ratio[k]:
            tmp[m] = ratio[k]
            m += 1
    used = tmp[:m]
    usual = _median(used, used)
    dropped = 0
    for k in range(RAYS):
        if ratio[k] > usual + FLAT:
            peak[k] = 0.0
            dropped += 1
    return dropped


@njit(inline="always", **JIT)
def _robust_conic(u, v, w, peak, lim, a, res, tmp):
    """Step 5.3: the conic fitted up to ``ROUNDS`` times, dropping points three robust deviations off.

    Updates the weights ``w`` and residuals ``res`` (``tmp`` is a scratch row); returns ``(x0, y0, ok, spread)``.
    """
    x0 = y0 = 0.0
    ok = False
    spread = np.inf
    for _ in range(ROUNDS):
        x0, y0, ok = _conic_fit(u, v, w, a, res)
        spread = 1.4826 * _median_of_used(res, w, tmp) + 0.02
        same = True
        for k in range(RAYS):
            wk = 1.0 if peak[k] > lim and peak[k] > 0.0 and res[k] < 3.0 * spread else 0.0
            same = same and wk == w[k]
            w[k] = wk
        if same:
            break       # the same points: another round would fit the same conic
    return x0, y0, ok, spread


@njit(**JIT)
def _fit_edge(img, cx, cy, a, b, th, buf, box, arcs=False, flat=0):
    """Steps 5.1-5.3 for one blob from the ellipse ``(cx, cy, a, b, th)``.

    Returns ``(dx, dy, clean, spread, n)``: the edge conic's centre less
    ``(cx, cy)`` in px, whether the edge is a clean ellipse, the points' robust
    scatter (px) and how many points the last fit kept.
    """
    ex, ey, peak, u, v, res, w = buf[0], buf[1], buf[2], buf[3], buf[4], buf[5], buf[6]
    _edge_points(img, cx, cy, a, b, th, ex, ey, peak, box, buf[8], buf[9])
    lim = WEAK * _median(peak, buf[7])
    if flat == 1 and FLAT > 0.0 and b >= FLAT_MINOR:
        _drop_unpainted(img, cx, cy, a, b, th, ex, ey, peak, buf[7], buf[8])
    usable = 0.0
    for k in range(RAYS):
        w[k] = 1.0 if peak[k] > lim and peak[k] > 0.0 else 0.0
        usable += w[k]
        u[k], v[k] = (ex[k] - cx) / a, (ey[k] - cy) / a
    if usable < MIN_RAYS * RAYS:
        # Neither the whole edge nor any arc can keep enough rays to be clean (callers use nothing else
        # of an edge that is not): no fit.
        return 0.0, 0.0, False, np.inf, usable
    x0, y0, ok, spread = _robust_conic(u, v, w, peak, lim, a, res, buf[8])
    if flat == 2 and FLAT > 0.0 and ok:
        # The flat-paint test, about the ellipse just fitted; again without the rays it drops.
        _x, _y, ok2, z = _conic_solve(u, v, w, a, res)
        fa, fb, fth = _conic_axes(z, _x, _y)
        if ok2 and fb * a >= FLAT_MINOR and _drop_unpainted(img, cx + _x * a, cy + _y * a, fa * a, fb * a, fth,
                                                             ex, ey, peak, buf[7], buf[8]) > 0:
            for k in range(RAYS):
                w[k] = 1.0 if peak[k] > lim and peak[k] > 0.0 else 0.0
            x0, y0, ok, spread = _robust_conic(u, v, w, peak, lim, a, res, buf[8])
    n = w.sum()
    dx, dy = x0 * a, y0 * a
    clean = ok and n >= MIN_RAYS * RAYS and spread < MAX_SCATTER and math.hypot(dx, dy) < MAX_MOVE * b
    # A scattered whole edge whose conic is centred where the blob already is confirms that centre;
    # one centred elsewhere may be a dot's outline spoiled on one side.
    if not clean and arcs and ARCS > 0 and math.hypot(dx, dy) > (ARC_MOVE_FLAT if flat else ARC_MOVE):
        return _fit_arcs(u, v, peak, lim, a, b, buf)
    return dx, dy, clean, spread, n


@njit(**JIT)
def _fit_arcs(u, v, peak, lim, a, b, buf):
    """Step 5.3 again for an edge that is not a clean ellipse as a whole: the best arc's ellipse.

    Hair, a shadow or a neighbour touching a dot corrupts the rays on one side: a
    contiguous arc of them.  The conic is fitted to each of ``ARCS`` arcs of
    ``MIN_RAYS`` of the rays; the one that the most edge points agree with (within
    ``INLIER`` px) wins and is fitted again to those points, twice.  Returns what
    :func:`_fit_edge` does.
    """
    res, w, tmp = buf[5], buf[6], buf[8]
    span = int(math.ceil(MIN_RAYS * RAYS))
    best, best_s = -1.0, 0
    for j in range(ARCS):
        s0 = (j * RAYS) // ARCS
        for k in range(RAYS):
            w[k] = 1.0 if ((k - s0) % RAYS) < span and peak[k] > lim and peak[k] > 0.0 else 0.0
        x0, y0, ok = _conic_fit(u, v, w, a, res)
        if not ok:
            continue
        agree = 0.0
        for k in range(RAYS):
            if peak[k] > lim and peak[k] > 0.0 and res[k] < INLIER:
                agree += 1.0
        if agree > best:
            best, best_s = agree, s0
    if best < 0:
        return 0.0, 0.0, False, np.inf, 0.0
    for k in range(RAYS):
        w[k] = 1.0 if ((k - best_s) % RAYS) < span and peak[k] > lim and peak[k] > 0.0 else 0.0
    x0 = y0 = 0.0
    ok = False
    for _ in range(3):
        x0, y0, ok = _conic_fit(u, v, w, a, res)
        for k in range(RAYS):
            w[k] = 1.0 if peak[k] > lim and peak[k] > 0.0 and res[k] < INLIER else 0.0
    n = w.sum()
    spread = 1.4826 * _median_of_used(res, w, tmp) + 0.02
    dx, dy = x0 * a, y0 * a
    clean = ok and n >= MIN_RAYS * RAYS and spread < MAX_SCATTER and math.hypot(dx, dy) < MAX_MOVE * b
    return dx, dy, clean, spread, n


@njit(**JIT)
def _refine_one(img, x, y, a, b, th, sx, sy, sr, buf, box, flat, trust):
    """Step 5 for one blob (ellipse ``(x, y, a, b, th)``, candidate ``(sx, sy, sr)``): ``(x, y, share)``."""
    dx, dy, clean, spread, n = _fit_edge(img, x, y, a, b, th, buf, box, True, 1 if flat else 0)
    if clean:
        # The edge points' scatter over the square root of their number: the standard error of the
        # fit's centre, were the rays independent (neighbouring rays share pixels, so TRUST is large).
        noise = trust * spread / math.sqrt(max(n, 1.0))
        s = min(max((math.hypot(dx, dy) - noise) / max(noise, 1e-9), 0.0), 1.0)
        return x + dx * s, y + dy * s, s
    if sr > 0.0 and a > MERGED * sr:
        # Measured much larger than its candidate and no clean edge: the dot was measured together
        # with a darker region it touches.  Its own edge, from the candidate (inside the dot).
        r0 = max(sr, 1.0)
        dx, dy, clean, spread, n = _fit_edge(img, sx, sy, r0, r0, 0.0, buf, box, True, 2 if flat else 0)
        if clean:
            return sx + dx, sy + dy, 1.0
    return x, y, 0.0


@njit(**JIT)
def _along_weight(major, minor):
    """The first centre's weight along the major axis (:data:`ALONG_MAX`)."""
    ratio = minor / max(major, 1e-9)
    return ALONG_MAX * min(max((ALONG_ROUND - ratio) / (ALONG_ROUND - ALONG_THIN), 0.0), 1.0)


@njit(**JIT)
def _refine(img, x, y, major, minor, angle, sx, sy, sr, trust, ox, oy, share, flat, along):
    rmax = 1.0
    for i in range(len(x)):
        rmax = max(rmax, major[i] / 2.0, minor[i] / 2.0, sr[i])
    buf, box = _scratch(rmax)
    for i in range(len(x)):
        a, b, th = max(major[i] / 2.0, 0.5), max(minor[i] / 2.0, 0.5), math.radians(angle[i])
        ox[i], oy[i], share[i] = _refine_one(img, x[i], y[i], a, b, th, sx[i], sy[i], sr[i], buf, box, flat,
                                             trust[i])
        first = math.hypot(ox[i] - x[i], oy[i] - y[i])
        if AGAIN > 0.0 and share[i] > 0.0 and first > AGAIN:
            # The edge moved the centre far: the rays were normal to an ellipse off the dot (measured with
            # what it touches) and cut its edge obliquely.  Once more, from the edge's centre.
            nx, ny, s = _refine_one(img, ox[i], oy[i], a, b, th, sx[i], sy[i], sr[i], buf, box, flat, trust[i])
            # Only a pass that converges: one that moves further than the first ran off to something else.
            if s > 0.0 and math.hypot(nx - ox[i], ny - oy[i]) < AGAIN_SHRINK * first:
                ox[i], oy[i] = nx, ny
        if along and share[i] > 0.0:
            w = _along_weight(major[i], minor[i])
            c, sn = math.cos(th), math.sin(th)
            t = w * ((x[i] - ox[i]) * c + (y[i] - oy[i]) * sn)
            ox[i] += t * c
            oy[i] += t * sn


def refine_centres(bright: np.ndarray, x, y, major, minor, angle, start=None, flat=False, trust=None,
                   along=False):
    """Centres of blobs measured again from their edges.

    Parameters
    ----------
    bright : numpy.ndarray
        Grey ``uint8`` image with the blobs brighter than their surround (the
        inverted image for black blobs).
    x, y, major, minor, angle : array_like
        The measured ellipses (centre; full axes, px; angle of the major axis,
        degrees).
    start : tuple of array_like, optional
        ``(x, y, radius)`` of each blob's candidate: where a blob measured
        more than ``MERGED`` times its candidate's radius has no clean edge,
        its edge is looked for around the candidate instead.
    flat : bool
        The blobs are black paint (flat): rays with no paint just inside their
        edge point are left out (step 5.2; on ellipses with a minor semi-axis of
        ``FLAT_MINOR`` px or more).
    trust : array_like, optional
        Per blob, how many standard errors of the edge fit the edge's centre must
        be away before the blob moves to it (``TRUST`` for every blob by default).
    along : bool
        Along the major axis of an elongated blob, average the edge's centre with
        the first one (:data:`ALONG_MAX`) where the edge moved it.

    Returns
    -------
    x, y : numpy.ndarray
        New centres (the old ones where the edge is not a clean ellipse).
    used : numpy.ndarray of bool
        Which blobs moved towards the edge's centre.
    """
    args = [np.ascontiguousarray(np.asarray(v, float)).reshape(-1) for v in (x, y, major, minor, angle)]
    n = len(args[0])
    if start is None:
        start = (np.zeros(n), np.zeros(n), np.zeros(n))
    args += [np.ascontiguousarray(np.asarray(v, float)).reshape(-1) for v in start]
    args.append(np.full(n, TRUST) if trust is None else np.ascontiguousarray(np.asarray(trust, float)).reshape(-1))
    ox, oy, share = np.empty(n), np.empty(n), np.empty(n)
    if n:
        _refine(np.ascontiguousarray(bright), *args, ox, oy, share, bool(flat), bool(along))
    return ox, oy, share > 0


@njit(**JIT)
def _from_candidates(img, sx, sy, sr, sb, sth, fx, fy, fmaj, fmin, fang, arcs, out, flat):
    rmax = 1.0
    for i in range(len(sx)):
        rmax = max(rmax, sr[i], fmaj[i] / 2.0, fmin[i] / 2.0)
    buf, box = _scratch(rmax)
    quality = out.shape[1] >= 10        # the caller asked for how each edge looked (edge_ellipses)
    for i in range(len(sx)):
        # The rays start on the candidate's circle, or on the start ellipse given (semi-axes sr >= sb).
        r0 = max(sr[i], 1.0)
        rb = r0 if sb[i] >= sr[i] else max(sb[i], MIN_START_MINOR)
        out[i, :] = 0.0
        dx, dy, clean, spread, n = _fit_edge(img, sx[i], sy[i], r0, rb, sth[i], buf, box, arcs[i] > 0.0,
                                             2 if flat else 0)
        if not clean:
            continue
        # How the edge looks (the edge stage's inputs), read before the check below reuses the buffers: its
        # scatter, the share of rays that found it, and the median and weakest gradient peaks of those rays.
        med = low = 0.0
        if quality:
            med = _median_of_used(buf[2], buf[6], buf[7])
            low = np.inf
            for k in range(RAYS):
                if buf[6][k] > 0.0 and buf[2][k] < low:
                    low = buf[2][k]
        # The conic again on the points the last round kept, for its axes as well as its centre.
        x0, y0, ok, z = _conic_solve(buf[3], buf[4], buf[6], r0, buf[5])
        a, b, th = _conic_axes(z, x0, y0)
        # Within a candidate radius (the start's minor semi-axis) of the candidate, and no larger than the
        # rays reach (REACH px either side of the start: a conic much larger is extrapolated from an arc).
        if not (ok and b > 0.0 and math.hypot(x0, y0) * r0 <= max(rb, 1.5)
                and 2.0 * a * r0 <= 2.0 * (r0 + REACH) + 1.0):
            continue
        if fmaj[i] > 0.0:
            # The measured blob has a clean edge of its own: it is what the candidate led to.
            fa, fb = max(fmaj[i] / 2.0, 0.5), max(fmin[i] / 2.0, 0.5)
            if _fit_edge(img, fx[i], fy[i], fa, fb, math.radians(fang[i]), buf, box, False, 1 if flat else 0)[2]:
                continue
        out[i, 0], out[i, 1] = sx[i] + x0 * r0, sy[i] + y0 * r0
        out[i, 2], out[i, 3], out[i, 4], out[i, 5] = 2.0 * a * r0, 2.0 * b * r0, math.degrees(th), 1.0
        if quality:
            out[i, 6], out[i, 7], out[i, 8], out[i, 9] = spread, n / RAYS, med, low


def edge_ellipses(bright: np.ndarray, x, y, radius, fits=None, arcs=None, flat=False, quality=False, start=None):
    """Ellipses of dots found from their painted edge alone, around candidate centres.

    For a candidate whose intensity measurement was drawn off to a larger dark
    region it touches (a nose tip's dot on the shadow under the nose, an
    edge-on dot beside a brow), the dot's own outline is still the innermost
    clear edge around the candidate: step 5's rays from a circle of the
    candidate's radius, and the conic through their edge points.

    Parameters
    ----------
    bright : numpy.ndarray
        Grey ``uint8`` image, blobs brighter than their surround.
    x, y, radius : array_like
        Candidates' centres and radii, px.
    fits : tuple of array_like, optional
        ``(x, y, major, minor, angle)`` the intensity measurement found from
        each candidate: where that ellipse's own edge is clean, it is kept
        (the row is zeros).
    arcs : array_like of bool, optional
        Where a candidate's whole edge is not a clean ellipse, try its best arc
        (step 5's ``_fit_arcs``; ~12 conic fits more): for dots touched by hair
        on one side.  None: nowhere.
    flat : bool
        Black paint: the flat-paint test of step 5.2, about the ellipse first
        fitted to each candidate's edge.
    quality : bool
        Also return how the edge looked (four more columns: its points' robust scatter about
        the conic, px; the share of the rays that found it; the median and the weakest
        gradient peak of those rays, grey levels a px).  Zeros where ``clean`` is 0.
    start : tuple of array_like, optional
        ``(minor, angle)``: the rays start on the ellipse of semi-axes ``radius`` and ``minor``
        (px, at least :data:`MIN_START_MINOR`) whose major axis is at ``angle`` (radians), not on
        the circle; the edge's centre must then lie within ``max(minor, 1.5)`` px of ``(x, y)``.

    Returns
    -------
    numpy.ndarray, shape (N, 6) or (N, 10)
        ``x, y, major, minor, angle, clean`` per candidate (full axes, px; angle
        of the major axis, degrees); ``clean`` is 1 where the edge made a clean
        ellipse within a candidate radius (and 1.5 px) of the candidate and no
        larger than the rays reach, else the row is zeros.
    """
    args = [np.ascontiguousarray(np.asarray(v, float)).reshape(-1) for v in (x, y, radius)]
    n = len(args[0])
    if start is None:
        start = (args[2], np.zeros(n))
    args += [np.ascontiguousarray(np.asarray(v, float)).reshape(-1) for v in start]
    if fits is None:
        fits = (np.zeros(n),) * 5
    args += [np.ascontiguousarray(np.asarray(v, float)).reshape(-1) for v in fits]
    args.append(np.zeros(n) if arcs is None else np.ascontiguousarray(np.asarray(arcs, float)).reshape(-1))
    out = np.zeros((n, 10 if quality else 6))
    if len(out):
        _from_candidates(np.ascontiguousarray(bright), *args, out, bool(flat))
    return out
