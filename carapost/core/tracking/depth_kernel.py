"""Compiled loops of how well a point's views fix it and of its average with the neighbours' prediction.

:func:`.geometry.depth_uncertainty`, :func:`.geometry.information` and
:func:`.engine.fuse_depth` were ~15 numpy operations each on (N, S, 3) arrays of
the tracker's few hundred points, run every frame; here each point is one pass.
The formulas are those of the functions' docstrings; sums run in view order,
so the results agree with the array versions to a few units in the last place
(tests/test_tracking_depth_kernel.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import JIT_EXACT


@njit(inline="always", **JIT_EXACT)
def _offset(X, C, i, s):
    """The vector from camera ``s``'s centre to point ``i`` and its squared length."""
    d0 = X[i, 0] - C[s, 0]
    d1 = X[i, 1] - C[s, 1]
    d2 = X[i, 2] - C[s, 2]
    return d0, d1, d2, d0 * d0 + d1 * d1 + d2 * d2


@njit(**JIT_EXACT)
def depth_spread(X, C, f, valid, u, mm):
    """Unit mean viewing direction ``u`` (N, 3) and depth error per px ``mm`` (N,) of points ``X`` (N, 3).

    ``C`` (S, 3) camera centres, ``f`` (S,) focal lengths (px), ``valid`` (N, S) each point's views.
    ``mm``: the mean of ``distance / f`` over the views divided by the sine of the widest angle between two
    of them (inf with fewer than two views or parallel rays); ``u`` NaN without views or for a NaN point.
    """
    N, S = valid.shape
    dirs = np.empty((S, 3))
    for i in range(N):
        n = 0
        scale = 0.0
        u0 = 0.0
        u1 = 0.0
        u2 = 0.0
        for s in range(S):
            if not valid[i, s]:
                continue
            d0, d1, d2, dist2 = _offset(X, C, i, s)
            dist = np.sqrt(dist2)
            dirs[n, 0] = d0 / dist
            dirs[n, 1] = d1 / dist
            dirs[n, 2] = d2 / dist
            u0 += dirs[n, 0]
            u1 += dirs[n, 1]
            u2 += dirs[n, 2]
            scale += dist / f[s]
            n += 1
        cos_min = 1.0
        for a in range(n):
            for b in range(a + 1, n):
                c = dirs[a, 0] * dirs[b, 0] + dirs[a, 1] * dirs[b, 1] + dirs[a, 2] * dirs[b, 2]
                if c < cos_min:        # a NaN cosine (a NaN point) is passed over
                    cos_min = c
        sin = np.sqrt(min(max(1.0 - cos_min * cos_min, 0.0), 1.0))
        mm[i] = scale / n / sin if (n >= 2 and sin > 1e-9) else np.inf
        norm = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if n == 0 or not norm > 0.0:
            u[i, 0] = np.nan
            u[i, 1] = np.nan
            u[i, 2] = np.nan
        else:
            u[i, 0] = u0 / norm
            u[i, 1] = u1 / norm
            u[i, 2] = u2 / norm


@njit(**JIT_EXACT)
def view_information(X, C, f, valid, weight, out):
    """``out`` (N, 3, 3): each point's sum over its views of ``(f w / d)² (I - r rᵀ)``.

    ``r`` the unit ray from camera ``s`` (centre ``C[s]``, focal length ``f[s]`` px) to ``X[i]``, ``d`` its
    length, ``w = weight[i, s]``.  NaN for a NaN point with views, zero without views.
    """
    N, S = valid.shape
    for i in range(N):
        for a in range(3):
            for b in range(3):
                out[i, a, b] = 0.0
        for s in range(S):
            if not valid[i, s]:
                continue
            d0, d1, d2, dist2 = _offset(X, C, i, s)
            g = f[s] * f[s] / dist2 * weight[i, s] * weight[i, s]
            dist = np.sqrt(dist2)
            r0 = d0 / dist
            r1 = d1 / dist
            r2 = d2 / dist
            out[i, 0, 0] += g * (1.0 - r0 * r0)
            out[i, 1, 1] += g * (1.0 - r1 * r1)
            out[i, 2, 2] += g * (1.0 - r2 * r2)
            out[i, 0, 1] -= g * r0 * r1
            out[i, 0, 2] -= g * r0 * r2
            out[i, 1, 2] -= g * r1 * r2
        out[i, 1, 0] = out[i, 0, 1]
        out[i, 2, 0] = out[i, 0, 2]
        out[i, 2, 1] = out[i, 1, 2]


@njit(**JIT_EXACT)
def fuse_points(X, info, pred, var, rows, info_scale, gate2, out, post):
    """``out`` = ``X`` with each row of ``rows`` moved to its information-weighted mean with ``pred``.

    The measurement's information is ``info[i] * info_scale``, the prediction's ``I / var[i]``.  The
    disagreement's squared Mahalanobis distance under both covariances is
    ``dxᵀ Jm dx - (Jm dx)ᵀ (Jm + Jp)⁻¹ Jm dx`` (Woodbury; ``Jm`` alone is singular for two parallel rays);
    rows where it exceeds ``gate2``, or with a NaN prediction or information, are left as measured.
    The mean is ``X + (Jm + Jp)⁻¹ Jp (pred - X)``.  ``post[i]``: the mean's variance, the largest diagonal
    element of ``(Jm + Jp)⁻¹`` (mm², an upper bound's stand-in for its largest eigenvalue; inf where not
    averaged).
    """
    N = X.shape[0]
    J = np.empty((3, 3))
    A = np.empty((3, 3))
    for i in range(N):
        out[i, 0] = X[i, 0]
        out[i, 1] = X[i, 1]
        out[i, 2] = X[i, 2]
        post[i] = np.inf
        if not rows[i]:
            continue
        finite = np.isfinite(pred[i, 0]) and np.isfinite(pred[i, 1]) and np.isfinite(pred[i, 2])
        for a in range(3):
            for b in range(3):
                J[a, b] = info[i, a, b] * info_scale
                finite = finite and np.isfinite(J[a, b])
        if not finite:
            continue
        dx0 = X[i, 0] - pred[i, 0]
        dx1 = X[i, 1] - pred[i, 1]
        dx2 = X[i, 2] - pred[i, 2]
        j0 = J[0, 0] * dx0 + J[0, 1] * dx1 + J[0, 2] * dx2
        j1 = J[1, 0] * dx0 + J[1, 1] * dx1 + J[1, 2] * dx2
        j2 = J[2, 0] * dx0 + J[2, 1] * dx1 + J[2, 2] * dx2
        for a in range(3):
            for b in range(3):
                A[a, b] = J[a, b] + (1.0 / var[i] if a == b else 0.0)
        # A is symmetric positive definite: its inverse by the adjugate.
        c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
        c01 = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
        c02 = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
        c11 = A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
        c12 = A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]
        c22 = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        det = (A[0, 0] * c00 + A[0, 1] * (A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2])
               + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))
        if not abs(det) > 0.0:
            continue
        s0 = (c00 * j0 + c01 * j1 + c02 * j2) / det
        s1 = (c01 * j0 + c11 * j1 + c12 * j2) / det
        s2 = (c02 * j0 + c12 * j1 + c22 * j2) / det
        md2 = dx0 * j0 + dx1 * j1 + dx2 * j2 - (j0 * s0 + j1 * s1 + j2 * s2)
        if not md2 <= gate2:
            continue
        post[i] = max(c00, max(c11, c22)) / det
        # The step (Jm + Jp)^-1 Jp (pred - X) = -(Jm + Jp)^-1 dx / var.
        out[i, 0] -= (c00 * dx0 + c01 * dx1 + c02 * dx2) / det / var[i]
        out[i, 1] -= (c01 * dx0 + c11 * dx1 + c12 * dx2) / det / var[i]
        out[i, 2] -= (c02 * dx0 + c12 * dx1 + c22 * dx2) / det / var[i]
