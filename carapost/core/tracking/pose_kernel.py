"""Compiled Gauss-Newton refinement of a rig's camera poses on fixed points (:func:`.geometry.refine_poses`).

Each iteration of the array version built the (S, N, 2, 6) weighted Jacobian and
its normal equations with ~25 numpy operations, most of the time in call
overhead for the tracker's few hundred points.  Here each camera's normal
equations are summed in one pass over its observations and solved by a 6 x 6
Cholesky factorisation.  The arithmetic is the same model (pinhole with skew,
Huber weights, rotation update on the left), summed in another order: the poses
agree with the array version's to ~1e-12 (tests/test_tracking_pose_kernel.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import JIT_EXACT
from ..linalg_kernel import cholesky_solve
from .geometry_kernel import rotation_matrices


@njit(**JIT_EXACT)
def _normal_equations(K, R, C, X, obs, good, s, huber, H, g):
    """Camera ``s``'s Huber-weighted normal equations ``H`` (6, 6) and gradient ``g`` (6,) on points ``X``.

    The unknowns are a rotation vector applied on the left of ``R[s]`` and a shift of ``C[s]``.
    A point behind or on the camera's plane (``|z| <= 1e-6``) is taken at ``z = 1e-6``.
    """
    f = K[s, 0, 0]
    k = K[s, 0, 1]
    fa = K[s, 1, 1]
    cx = K[s, 0, 2]
    cy = K[s, 1, 2]
    for a in range(6):
        g[a] = 0.0
        for b in range(6):
            H[a, b] = 0.0
    row = np.empty(6)
    for i in range(X.shape[0]):
        if not good[s, i]:
            continue
        d0 = X[i, 0] - C[s, 0]
        d1 = X[i, 1] - C[s, 1]
        d2 = X[i, 2] - C[s, 2]
        x0 = R[s, 0, 0] * d0 + R[s, 0, 1] * d1 + R[s, 0, 2] * d2
        x1 = R[s, 1, 0] * d0 + R[s, 1, 1] * d1 + R[s, 1, 2] * d2
        z = R[s, 2, 0] * d0 + R[s, 2, 1] * d1 + R[s, 2, 2] * d2
        x2 = z
        if not abs(z) > 1e-6:
            z = 1e-6
        u = f * (x0 / z) + k * (x1 / z)
        v = fa * (x1 / z)
        r0 = u + cx - obs[s, i, 0]
        r1 = v + cy - obs[s, i, 1]
        nr = np.sqrt(r0 * r0 + r1 * r1)
        q = huber / max(nr, 1e-12)
        w = np.sqrt(min(q, 1.0))
        if np.isnan(nr):
            continue
        for rr in range(2):
            # d(u, v) / d xc: [[f, k, -u], [0, fa, -v]] / z
            if rr == 0:
                j0, j1, j2, res = f / z, k / z, -u / z, r0
            else:
                j0, j1, j2, res = 0.0, fa / z, -v / z, r1
            # Rotation columns: d xc / d omega = -[xc]x, so J_rot = xc x J_row; position columns: -J_row R.
            row[0] = (x1 * j2 - x2 * j1) * w
            row[1] = (x2 * j0 - x0 * j2) * w
            row[2] = (x0 * j1 - x1 * j0) * w
            for c in range(3):
                row[3 + c] = -(j0 * R[s, 0, c] + j1 * R[s, 1, c] + j2 * R[s, 2, c]) * w
            rw = res * w
            for a in range(6):
                g[a] += row[a] * rw
                for b in range(a, 6):
                    H[a, b] += row[a] * row[b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]


@njit(**JIT_EXACT)
def refine_rig(K, R, C, X, obs, good, active, iterations, huber):
    """Gauss-Newton on the poses ``R`` (S, 3, 3), ``C`` (S, 3) in place, points ``X`` (N, 3) fixed.

    ``obs`` (S, N, 2) corrected pixels, ``good`` (S, N) which of them count, ``active`` (S,) the cameras to
    refine.  Stops after ``iterations`` or once no camera's step exceeds 1e-7 (rad or mm).
    """
    S = R.shape[0]
    H = np.empty((6, 6))
    g = np.empty(6)
    d = np.empty(6)
    L = np.zeros((6, 6))
    ridge = np.full(6, 1e-9)                  # H is positive semi-definite: a camera seeing too little stays put
    w = np.empty((1, 3))
    Q = np.empty((1, 3, 3))
    Rn = np.empty((3, 3))
    for _ in range(iterations):
        biggest = 0.0
        for s in range(S):
            if not active[s]:
                continue
            _normal_equations(K, R, C, X, obs, good, s, huber, H, g)
            if not cholesky_solve(H, g, ridge, 6, L, d):
                continue
            for a in range(6):
                biggest = max(biggest, abs(d[a]))
            w[0, 0], w[0, 1], w[0, 2] = d[0], d[1], d[2]
            rotation_matrices(w, Q)
            for a in range(3):
                for b in range(3):
                    Rn[a, b] = Q[0, a, 0] * R[s, 0, b] + Q[0, a, 1] * R[s, 1, b] + Q[0, a, 2] * R[s, 2, b]
            for a in range(3):
                for b in range(3):
                    R[s, a, b] = Rn[a, b]
                C[s, a] += d[3 + a]
        if biggest < 1e-7:
            break
