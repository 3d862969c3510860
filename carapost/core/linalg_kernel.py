"""Small dense solves shared by the compiled kernels (the tracker's pose refinement, the blob detector's
Gaussian fit).  Compiled with ``JIT_EXACT``: a caller compiled with ``fastmath`` does not change this
arithmetic (numba compiles a called function with its own options)."""
from __future__ import annotations

import math

from numba import njit

from .jit import JIT_EXACT


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
