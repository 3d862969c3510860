"""Compiled loops of the tracker's geometry: linear triangulation (:func:`.geometry.triangulate`,
:func:`.geometry.held_out_errors`), projection and reprojection errors, and pose refinement's
residuals and Jacobian (:func:`.geometry.refine_poses`).

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

The matrix products of the depth weights and projections stay numpy's: BLAS
fuses their multiply-adds, which plain loops would not reproduce.
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


@njit(**JIT_EXACT)
def _view_terms(P, uv, w, el, i, s, m, b):
    """View ``s`` of point ``i``'s share of the normal equations: upper triangle ``m`` (6,) and ``b`` (3,).

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
    m[0] = a00 * a00 + a10 * a10
    m[1] = a00 * a01 + a10 * a11
    m[2] = a00 * a02 + a10 * a12
    m[3] = a01 * a01 + a11 * a11
    m[4] = a01 * a02 + a11 * a12
    m[5] = a02 * a02 + a12 * a12
    b[0] = -(a00 * a03 + a10 * a13)
    b[1] = -(a01 * a03 + a11 * a13)
    b[2] = -(a02 * a03 + a12 * a13)


@njit(**JIT_EXACT)
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


@njit(**JIT_EXACT)
def _view_sums(P, uv, w, el, i, ms, bs, msum, bsum):
    """Point ``i``'s normal-equation terms of each view into ``ms[s]``, ``bs[s]``, and their sums (view order)."""
    for j in range(6):
        msum[j] = 0.0
    for j in range(3):
        bsum[j] = 0.0
    for s in range(w.shape[1]):
        _view_terms(P, uv, w, el, i, s, ms[s], bs[s])
        for j in range(6):
            msum[j] += ms[s, j]
        for j in range(3):
            bsum[j] += bs[s, j]


@njit(**JIT_EXACT)
def dlt_solve(P, uv, w, el):
    """Weighted DLT points ``(n, 3)`` of ``uv`` (n, S, 2) with view weights ``w`` (n, S) (0: not a view)
    and each view's elongation ``el`` (n, S, 3) (:func:`_view_terms`)."""
    n, S = w.shape
    out = np.empty((n, 3))
    ms = np.empty((S, 6))
    bs = np.empty((S, 3))
    msum = np.empty(6)
    bsum = np.empty(3)
    for i in range(n):
        _view_sums(P, uv, w, el, i, ms, bs, msum, bsum)
        _solve_into(msum, bsum, out, i)
    return out


@njit(**JIT_EXACT)
def dlt_held_out(P, uv, w, el):
    """Points ``(S, n, 3)`` of :func:`dlt_solve` with view ``s`` left out of the sum (all views' sum minus its own)."""
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
        _view_sums(P, uv, w, el, i, ms, bs, msum, bsum)
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
def pose_residuals(xc, obs, good, K, r, Jx):
    """Gauss-Newton residuals ``r`` (S, N, 2) and image Jacobians ``Jx`` (S, N, 2, 3) of camera-frame points ``xc``.

    For :func:`.geometry.refine_poses`: ``z`` floored at 1e-6 where ``|z| <= 1e-6``, ``u = f x + k y``,
    ``v = fa y`` (K's skew ``k``), ``r = (u + cx) - obs`` (0 where not ``good``),
    ``d(u, v) / d xc = [[f, k, -u], [0, fa, -v]] / z``, each as numpy's array expressions computed it.
    """
    S, N = good.shape
    for s in range(S):
        f = K[s, 0, 0]
        k = K[s, 0, 1]
        fa = K[s, 1, 1]
        cx = K[s, 0, 2]
        cy = K[s, 1, 2]
        for i in range(N):
            z = xc[s, i, 2]
            if not abs(z) > 1e-6:
                z = 1e-6
            x = xc[s, i, 0] / z
            y = xc[s, i, 1] / z
            u = f * x + k * y
            v = fa * y
            if good[s, i]:
                r[s, i, 0] = u + cx - obs[s, i, 0]
                r[s, i, 1] = v + cy - obs[s, i, 1]
            else:
                r[s, i, 0] = 0.0
                r[s, i, 1] = 0.0
            Jx[s, i, 0, 0] = f / z
            Jx[s, i, 0, 1] = k / z
            Jx[s, i, 0, 2] = -u / z
            Jx[s, i, 1, 0] = 0.0
            Jx[s, i, 1, 1] = fa / z
            Jx[s, i, 1, 2] = -v / z


@njit(**JIT_EXACT)
def pose_weighted_jacobian(xc, Jx, JxR, r, good, huber, Jw, rw):
    """Huber-weighted pose Jacobian ``Jw`` (S, N, 2, 6) and residuals ``rw`` (S, N, 2).

    Rotation columns ``cross(xc, row of Jx)`` (``d xc / d omega = -[xc]x``), position columns ``-JxR``
    (``Jx @ R``, numpy's product), both rows times ``w = sqrt(min(1, huber / max(|r|, 1e-12)))``
    (0 where not ``good``; NaN propagates through min and max as in numpy).
    """
    S, N = good.shape
    for s in range(S):
        for i in range(N):
            r0 = r[s, i, 0]
            r1 = r[s, i, 1]
            w = 0.0
            if good[s, i]:
                nr = np.sqrt(r0 * r0 + r1 * r1)
                m = nr if (nr > 1e-12 or np.isnan(nr)) else 1e-12
                q = huber / m
                w = np.sqrt(q if (q < 1.0 or np.isnan(q)) else 1.0)
            a0 = xc[s, i, 0]
            a1 = xc[s, i, 1]
            a2 = xc[s, i, 2]
            for row in range(2):
                b0 = Jx[s, i, row, 0]
                b1 = Jx[s, i, row, 1]
                b2 = Jx[s, i, row, 2]
                Jw[s, i, row, 0] = (a1 * b2 - a2 * b1) * w
                Jw[s, i, row, 1] = (a2 * b0 - a0 * b2) * w
                Jw[s, i, row, 2] = (a0 * b1 - a1 * b0) * w
                for c in range(3):
                    Jw[s, i, row, 3 + c] = -JxR[s, i, row, c] * w
            rw[s, i, 0] = r0 * w
            rw[s, i, 1] = r1 * w


@njit(**JIT_EXACT)
def pixels(m, P, out):
    """Corrected pixels ``out`` (N, S, 2) of ``m`` (S, N, 3), the points' ``X @ P[s, :, :3].T``.

    Adds each camera's translation column (``h = m + P[s, :, 3]``) and divides by ``h[2]``; NaN where
    ``h[2] <= 1e-6`` (behind the camera) or NaN, as :meth:`.geometry.RigState.project` did with arrays.
    """
    S, N = m.shape[0], m.shape[1]
    for s in range(S):
        t0 = P[s, 0, 3]
        t1 = P[s, 1, 3]
        t2 = P[s, 2, 3]
        for i in range(N):
            z = m[s, i, 2] + t2
            if z > 1e-6:
                out[i, s, 0] = (m[s, i, 0] + t0) / z
                out[i, s, 1] = (m[s, i, 1] + t1) / z
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
