"""Compiled loops of the tracker's geometry: linear triangulation (:func:`.geometry.triangulate`,
:func:`.geometry.held_out_errors`), projection and reprojection errors, and rotation matrices.
(Pose refinement is :mod:`.pose_kernel`.)

As numpy, each solve was ~40 array operations on (components, views, points)
arrays of a few hundred points (the DLT rows, their products, the sum over views,
the adjugate), most of the time in call overhead.  Here each point is one pass.
The arithmetic is numpy's, operation for operation (``JIT_EXACT``: no fused
multiply-add, no reassociation), so the results are the same to the bit:

* view ``s`` of point ``i`` has the rows ``a_r = (uv[i, s, r] * P[s, 2] - P[s, r]) * w[i, s]``
  (r = 0, 1) and adds ``a_0[p] * a_0[q] + a_1[p] * a_1[q]`` to ``M[p, q]`` and
  ``-(a_0[p] * a_0[3] + a_1[p] * a_1[3])`` to ``b[p]``;
* the views are summed in order from 0.0 (as ``ndarray.sum`` over a short middle axis);
* ``M x = b`` is solved by the adjugate, NaN where ``|det| <= 1e-300``.

Since session 22 the depth weights of :func:`.geometry.triangulate`'s second
solve and the projections' matrix products are summed here too, in plain order
where numpy's products fused multiply-adds: the float64 results differ by units
in the last place, and the tracks stored (float32) came out the same.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import JIT_EXACT


@njit(**JIT_EXACT)
def rotation_matrices(w, out):
    """Rodrigues' formula for each rotation vector ``w[i]`` (n, 3) into ``out[i]`` (n, 3, 3).

    ``I + sin(t) K + (1 - cos(t)) K K`` with ``K`` the cross-product matrix of the unit axis (axis
    ``w`` itself where ``t < 1e-15``), operation for operation as the numpy version computed it, which
    it replaced (:func:`.geometry.rodrigues`; ~1 us for a rig's four cameras where numpy's ~15 array
    operations took ~50 us).  The same to the bit but for ``K K``, which numpy's matrix product sums in
    another order for about one batch of four in a thousand (a unit in the last place).
    """
    K = np.zeros((3, 3))
    for i in range(w.shape[0]):
        x, y, z = w[i, 0], w[i, 1], w[i, 2]
        th = np.sqrt(x * x + y * y + z * z)
        ths = 1.0 if th < 1e-15 else th
        kx, ky, kz = x / ths, y / ths, z / ths
        K[0, 0], K[0, 1], K[0, 2] = 0.0, -kz, ky
        K[1, 0], K[1, 1], K[1, 2] = kz, 0.0, -kx
        K[2, 0], K[2, 1], K[2, 2] = -ky, kx, 0.0
        sn, c1 = np.sin(ths), 1.0 - np.cos(ths)
        for a in range(3):
            for b in range(3):
                kk = K[a, 0] * K[0, b] + K[a, 1] * K[1, b] + K[a, 2] * K[2, b]
                out[i, a, b] = (1.0 if a == b else 0.0) + sn * K[a, b] + c1 * kk


@njit(inline="always", **JIT_EXACT)
def _view_terms(P, uv, w, el, i, s, m, b):
    """View ``s`` of point ``i``'s share of the normal equations: upper triangle ``m[s]`` (6,) and ``b[s]`` (3,).

    ``el[i, s] = (cos, sin, k)``: the view's equation along the image direction (cos, sin) is
    weighted ``k`` times the one across it (1: the same, as for a round dot).
    """
    u = uv[i, s, 0]
    v = uv[i, s, 1]
    ws = w[i, s]
    a00 = (u * P[s, 2, 0] - P[s, 0, 0]) * ws
    a01 = (u * P[s, 2, 1] - P[s, 0, 1]) * ws
    a02 = (u * P[s, 2, 2] - P[s, 0, 2]) * ws
    a03 = (u * P[s, 2, 3] - P[s, 0, 3]) * ws
    a10 = (v * P[s, 2, 0] - P[s, 1, 0]) * ws
    a11 = (v * P[s, 2, 1] - P[s, 1, 1]) * ws
    a12 = (v * P[s, 2, 2] - P[s, 1, 2]) * ws
    a13 = (v * P[s, 2, 3] - P[s, 1, 3]) * ws
    k = el[i, s, 2]
    if k != 1.0:
        # The two equations turned to the directions along and across (c, t), the first weighted k.
        c = el[i, s, 0]
        t = el[i, s, 1]
        a00, a10 = k * (c * a00 + t * a10), c * a10 - t * a00
        a01, a11 = k * (c * a01 + t * a11), c * a11 - t * a01
        a02, a12 = k * (c * a02 + t * a12), c * a12 - t * a02
        a03, a13 = k * (c * a03 + t * a13), c * a13 - t * a03
    m[s, 0] = a00 * a00 + a10 * a10
    m[s, 1] = a00 * a01 + a10 * a11
    m[s, 2] = a00 * a02 + a10 * a12
    m[s, 3] = a01 * a01 + a11 * a11
    m[s, 4] = a01 * a02 + a11 * a12
    m[s, 5] = a02 * a02 + a12 * a12
    b[s, 0] = -(a00 * a03 + a10 * a13)
    b[s, 1] = -(a01 * a03 + a11 * a13)
    b[s, 2] = -(a02 * a03 + a12 * a13)


@njit(inline="always", **JIT_EXACT)
def _solve_into(m, b, out, i):
    """``out[i] = M^-1 b`` by the adjugate (``m``: upper triangle m00 m01 m02 m11 m12 m22); NaN if singular."""
    m00, m01, m02, m11, m12, m22 = m[0], m[1], m[2], m[3], m[4], m[5]
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    det = m00 * c00 + m01 * c01 + m02 * c02
    if abs(det) > 1e-300:
        b0, b1, b2 = b[0], b[1], b[2]
        out[i, 0] = (c00 * b0 + c01 * b1 + c02 * b2) / det
        out[i, 1] = (c01 * b0 + c11 * b1 + c12 * b2) / det
        out[i, 2] = (c02 * b0 + c12 * b1 + c22 * b2) / det
    else:
        out[i, 0] = np.nan
        out[i, 1] = np.nan
        out[i, 2] = np.nan


@njit(inline="always", **JIT_EXACT)
def _view_sums(P, uv, w, el, valid, i, ms, bs, msum, bsum):
    """Point ``i``'s normal-equation terms of each view into ``ms[s]``, ``bs[s]``, and their sums (view order).

    A view not ``valid`` adds nothing (zero terms; its ``uv`` and ``w`` are not read).
    """
    for j in range(6):
        msum[j] = 0.0
    for j in range(3):
        bsum[j] = 0.0
    for s in range(w.shape[1]):
        if not valid[i, s]:
            for j in range(6):
                ms[s, j] = 0.0
            for j in range(3):
                bs[s, j] = 0.0
            continue
        _view_terms(P, uv, w, el, i, s, ms, bs)
        for j in range(6):
            msum[j] += ms[s, j]
        for j in range(3):
            bsum[j] += bs[s, j]


@njit(**JIT_EXACT)
def dlt_depth_weighted(P, uv, valid, conf, el):
    """Weighted DLT points ``(n, 3)`` of ``uv`` (n, S, 2), solved twice per point.

    The first solve weights each view by its confidence ``conf`` (n, S), the second by ``100 / depth``
    (depth from the first, at least 1e-3) times it; views not ``valid`` add nothing (their ``uv`` may be NaN).
    NaN for points with fewer than two views.

    The inverse depth turns the DLT's algebraic error into the image-plane error (:func:`.geometry.triangulate`).
    The depths are summed here in plain order where numpy's matrix product fused them: the same points to
    within a few units in the last place.
    """
    n, S = valid.shape
    out = np.empty((n, 3))
    w = np.empty((n, S))
    ms = np.empty((S, 6))
    bs = np.empty((S, 3))
    msum = np.empty(6)
    bsum = np.empty(3)
    for i in range(n):
        views = 0
        for s in range(S):
            w[i, s] = conf[i, s] if valid[i, s] else 0.0
            views += valid[i, s]
        if views < 2:
            out[i, 0] = np.nan
            out[i, 1] = np.nan
            out[i, 2] = np.nan
            continue
        _view_sums(P, uv, w, el, valid, i, ms, bs, msum, bsum)
        _solve_into(msum, bsum, out, i)
        for s in range(S):
            if valid[i, s]:
                depth = out[i, 0] * P[s, 2, 0] + out[i, 1] * P[s, 2, 1] + out[i, 2] * P[s, 2, 2] + P[s, 2, 3]
                w[i, s] = 1.0 / max(abs(depth), 1e-3) * 100.0 * conf[i, s]
        _view_sums(P, uv, w, el, valid, i, ms, bs, msum, bsum)
        _solve_into(msum, bsum, out, i)
    return out


@njit(**JIT_EXACT)
def dlt_held_out(P, uv, w, el, valid):
    """Weighted DLT points ``(S, n, 3)`` of ``uv`` (n, S, 2) with view weights ``w`` (n, S) and elongation ``el``
    (n, S, 3) (:func:`_view_terms`), view ``s`` left out of the sum (all views' sum minus its own); views not
    ``valid`` add nothing."""
    n, S = w.shape
    out = np.empty((S, n, 3))
    ms = np.empty((S, 6))
    bs = np.empty((S, 3))
    msum = np.empty(6)
    bsum = np.empty(3)
    m = np.empty(6)
    b = np.empty(3)
    row = np.empty((1, 3))
    for i in range(n):
        _view_sums(P, uv, w, el, valid, i, ms, bs, msum, bsum)
        for s in range(S):
            for j in range(6):
                m[j] = msum[j] - ms[s, j]
            for j in range(3):
                b[j] = bsum[j] - bs[s, j]
            _solve_into(m, b, row, 0)
            for j in range(3):
                out[s, i, j] = row[0, j]
    return out


@njit(**JIT_EXACT)
def pixels(X, P, out):
    """Corrected pixels ``out`` (N, S, 2) of points ``X`` (1 or S, N, 3) through the projection matrices ``P``.

    ``X[0]`` is seen by every camera, or ``X[s]`` by camera ``s`` alone.  ``h = P[s, :, :3] X + P[s, :, 3]``
    (the product summed in plain order, then the translation added) divided by ``h[2]``; NaN where
    ``h[2] <= 1e-6`` (behind the camera) or NaN.
    """
    S, N = P.shape[0], X.shape[1]
    for s in range(S):
        q = s if X.shape[0] > 1 else 0
        for i in range(N):
            x0 = X[q, i, 0]
            x1 = X[q, i, 1]
            x2 = X[q, i, 2]
            z = (P[s, 2, 0] * x0 + P[s, 2, 1] * x1 + P[s, 2, 2] * x2) + P[s, 2, 3]
            if z > 1e-6:
                out[i, s, 0] = ((P[s, 0, 0] * x0 + P[s, 0, 1] * x1 + P[s, 0, 2] * x2) + P[s, 0, 3]) / z
                out[i, s, 1] = ((P[s, 1, 0] * x0 + P[s, 1, 1] * x1 + P[s, 1, 2] * x2) + P[s, 1, 3]) / z
            else:
                out[i, s, 0] = np.nan
                out[i, s, 1] = np.nan


@njit(**JIT_EXACT)
def pixel_errors(proj, uv, valid, invalid, out):
    """``out`` (N, S): ``|proj - uv|`` (px) where ``valid``, else ``invalid``.

    The length as ``np.linalg.norm`` over the last axis computes it, ``sqrt(dx * dx + dy * dy)``
    (NaN where either point is NaN).
    """
    N, S = valid.shape
    for i in range(N):
        for s in range(S):
            if valid[i, s]:
                dx = proj[i, s, 0] - uv[i, s, 0]
                dy = proj[i, s, 1] - uv[i, s, 1]
                out[i, s] = np.sqrt(dx * dx + dy * dy)
            else:
                out[i, s] = invalid
