"""Small dense solves shared by the compiled kernels (the tracker's pose refinement, the blob detector's
Gaussian and profile fits).  The solves are compiled with ``JIT_EXACT``: a caller compiled with ``fastmath`` does
not change their arithmetic (numba compiles a called function with its own options)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .jit import JIT, JIT_EXACT


@njit(**JIT_EXACT)
def cholesky_solve(H, g, ridge, n, L, d):
    """``d[:n] = -(H + diag(ridge))^-1 g`` for a symmetric ``H`` (n, n) by Cholesky; False if not positive definite.

    ``L`` (n, n) is the caller's scratch for the factor (only its lower triangle is written); ``ridge`` (n,) is
    added to the diagonal (a damping or a tiny regulariser).
    """
    for a in range(n):
        for b in range(a + 1):
            acc = H[a, b] + (ridge[a] if a == b else 0.0)
            for c in range(b):
                acc -= L[a, c] * L[b, c]
            if a == b:
                if not acc > 0.0:
                    return False
                L[a, a] = math.sqrt(acc)
            else:
                L[a, b] = acc / L[b, b]
    for a in range(n):                       # L y = -g, y kept in d
        acc = -g[a]
        for c in range(a):
            acc -= L[a, c] * d[c]
        d[a] = acc / L[a, a]
    for a in range(n - 1, -1, -1):           # Lᵀ d = y
        acc = d[a]
        for c in range(a + 1, n):
            acc -= L[c, a] * d[c]
        d[a] = acc / L[a, a]
    return True


@njit(**JIT)
def normal_equations(J, res, npar, n, JtJ, Jtr):
    """``JtJ = J Jᵀ`` and ``Jtr = J res`` over the first ``n`` columns of ``J`` (npar, >= n), a Jacobian stored a
    row per parameter (so that the sums run along contiguous rows).

    Compiled with ``JIT``: its sums may be reordered (vectorised); the blob fits that use it keep float32 answers.
    """
    for i in range(npar):
        s = 0.0
        for k in range(n):
            s += J[i, k] * res[k]
        Jtr[i] = s
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += J[i, k] * J[j, k]
            JtJ[i, j] = s
            JtJ[j, i] = s


@njit(**JIT_EXACT)
def marquardt_step(JtJ, Jtr, lam, npar, ridge, L, step, q, trial):
    """Levenberg-Marquardt's step for the damping ``lam``: ``JtJ`` with ``lam`` times each parameter's curvature
    (Marquardt's scaling, plus 1e-12) added to its diagonal, solved by :func:`cholesky_solve` into ``step``
    (``ridge`` and ``L`` the caller's scratch), and ``trial = q + step``; False if not positive definite."""
    for i in range(npar):
        ridge[i] = lam * JtJ[i, i] + 1e-12
    if not cholesky_solve(JtJ, Jtr, ridge, npar, L, step):
        return False
    for i in range(npar):
        trial[i] = q[i] + step[i]
    return True


@njit(**JIT_EXACT)
def next_damping(lam, lowered):
    """Levenberg-Marquardt's damping after a step, and whether the fit ends at a minimum: a third of it after a step
    that lowered the cost, ten times after one that did not; past 1e8 no step lowers it."""
    if lowered:
        return max(lam / 3.0, 1e-9), False
    return lam * 10.0, lam * 10.0 > 1e8


@njit(**JIT_EXACT)
def lm_scratch(npar):
    """A Levenberg-Marquardt fit's arrays for ``npar`` parameters: ``(params, trial, step, JtJ, Jtr, L, ridge)``."""
    return (np.empty(npar), np.empty(npar), np.empty(npar), np.empty((npar, npar)), np.empty(npar),
            np.zeros((npar, npar)), np.empty(npar))
