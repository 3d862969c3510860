"""Sub-pixel ellipse fitting of blobs, vectorised over all blobs of a frame.

Each blob is modelled as a soft-edged ellipse on a flat background::

    m(x, y) = b + gx x + gy y + a * sigmoid(k * (1 - q)),   q^2 = [dx dy] Q [dx dy]^T

with ``Q = [[A, B], [B, C]]`` (the ellipse ``q = 1`` is the half-contrast
boundary), ``a`` the contrast, ``b + gx x + gy y`` the local background (faces are
shaded: a flat background would pull the centre up the gradient) and ``k``
the edge sharpness (optical blur).  Levenberg-Marquardt on all 10 parameters is run on
every blob at once (batched 8x8 solves).  A window that follows the current
ellipse (weight 1 inside 1.6 radii, 0 beyond 2.2) keeps neighbouring markers
and skin structure out of the fit.

Why a model fit and not a centroid: the centroid weighs every window pixel's
noise equally, while the least-squares fit weighs pixels by how much they tell
about the position (the edge), which reaches the Cramér-Rao bound; for a
symmetric blob the centre is unbiased even when the edge profile is not
exactly a sigmoid.
"""
from __future__ import annotations

import numpy as np

N_PARAMS = 10  # x0, y0, A, B, C, a, b, k, gx, gy


def extract(img: np.ndarray, ix: np.ndarray, iy: np.ndarray, h: int) -> np.ndarray:
    """``(N, 2h+1, 2h+1)`` float32 windows centred on integer pixels (img padded by >= h)."""
    g = np.arange(-h, h + 1)
    idx = (iy[:, None, None] + g[None, :, None]) * img.shape[1] + (ix[:, None, None] + g[None, None, :])
    return img.ravel()[idx].astype(np.float32)


def _model(p, X, Y):
    dx = X - p[:, 0, None, None]
    dy = Y - p[:, 1, None, None]
    A, B, C = p[:, 2, None, None], p[:, 3, None, None], p[:, 4, None, None]
    q2 = A * dx * dx + 2 * B * dx * dy + C * dy * dy
    q = np.sqrt(np.maximum(q2, 0) + 1e-4)
    k = p[:, 7, None, None]
    s = 1.0 / (1.0 + np.exp(-np.clip(k * (1 - q), -30, 30)))
    m = p[:, 6, None, None] + p[:, 8, None, None] * X + p[:, 9, None, None] * Y + p[:, 5, None, None] * s
    return m, dx, dy, q, s


def _weights(q):
    return np.clip((2.2 - q) / 0.6, 0.0, 1.0)


def fit_ellipses(patches: np.ndarray, r0: np.ndarray, iters: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Fit the soft-ellipse model to bright blobs centred near each window's centre.

    Parameters
    ----------
    patches : ndarray (N, n, n)
        Windows, blob brighter than its surround.
    r0 : ndarray (N,)
        Initial radius guess (px).

    Returns
    -------
    params : ndarray (N, 8)
        ``x0, y0`` relative to the window centre, ``A, B, C, a, b, k, gx, gy``.
    ok : ndarray (N,) bool
        The fit converged to a plausible blob inside the window.
    """
    N, n, _ = patches.shape
    h = n // 2
    g = np.arange(-h, h + 1, dtype=np.float32)
    X, Y = g[None, None, :], g[:, None, None].reshape(1, n, 1)
    p = np.zeros((N, N_PARAMS), np.float32)
    border = np.concatenate([patches[:, 0], patches[:, -1], patches[:, 1:-1, 0], patches[:, 1:-1, -1]], 1)
    bg = np.median(border, 1)
    peak = patches[:, h - 1:h + 2, h - 1:h + 2].mean((1, 2))
    r0 = np.maximum(r0.astype(np.float32), 1.0)
    # Start from the background-subtracted centroid inside r0: a good x0, y0 speeds convergence.
    w0 = np.clip(patches - (bg + 0.5 * (peak - bg))[:, None, None], 0, None)
    w0 *= (X ** 2 + Y ** 2 <= (1.5 * r0[:, None, None]) ** 2)
    sw = w0.sum((1, 2)) + 1e-6
    p[:, 0] = np.clip((w0 * X).sum((1, 2)) / sw, -1.5, 1.5)
    p[:, 1] = np.clip((w0 * Y).sum((1, 2)) / sw, -1.5, 1.5)
    p[:, 2] = p[:, 4] = 1.0 / r0 ** 2
    p[:, 5] = np.maximum(peak - bg, 1.0) * 1.1
    p[:, 6] = bg
    p[:, 7] = np.clip(1.7 * r0, 2.0, 30.0)
    lam = np.full(N, 1e-2, np.float32)
    m, dx, dy, q, s = _model(p, X, Y)
    W = _weights(q)
    res = patches - m
    cost = (W * res * res).sum((1, 2))
    eye = np.eye(N_PARAMS, dtype=np.float32)
    J = np.empty((N, n, n, N_PARAMS), np.float32)
    J[..., 6] = 1.0
    J[..., 8] = X
    J[..., 9] = Y
    Jf = J.reshape(N, n * n, N_PARAMS)
    for _ in range(iters):
        a, k = p[:, 5, None, None], p[:, 7, None, None]
        ds = s * (1 - s)
        dm_dq = -a * ds * k / q
        A, B, C = p[:, 2, None, None], p[:, 3, None, None], p[:, 4, None, None]
        J[..., 0] = -dm_dq * (A * dx + B * dy)
        J[..., 1] = -dm_dq * (B * dx + C * dy)
        J[..., 2] = 0.5 * dm_dq * dx * dx
        J[..., 3] = dm_dq * dx * dy
        J[..., 4] = 0.5 * dm_dq * dy * dy
        J[..., 5] = s
        J[..., 7] = a * ds * (1 - q)
        JWt = (Jf * W.reshape(N, n * n, 1)).transpose(0, 2, 1)
        H = JWt @ Jf                                   # batched BLAS: far faster than einsum
        grad = (JWt @ res.reshape(N, n * n, 1))[:, :, 0]
        D = np.diagonal(H, axis1=1, axis2=2)
        Hd = H + (lam[:, None] * D + 1e-9)[:, :, None] * eye
        try:
            step = np.linalg.solve(Hd, grad[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.zeros_like(grad)
        pn = p + step
        pn[:, 7] = np.clip(pn[:, 7], 0.5, 60.0)
        mn, dxn, dyn, qn, sn = _model(pn, X, Y)
        resn = patches - mn
        # Cost on the *old* window so the comparison is fair; the window moves with the accepted fit.
        costn = (W * resn * resn).sum((1, 2))
        better = np.isfinite(costn) & (costn < cost)
        bb = better[:, None, None]
        p = np.where(better[:, None], pn, p)
        m, dx, dy, q, s = (np.where(bb, mn, m), np.where(bb, dxn, dx), np.where(bb, dyn, dy),
                           np.where(bb, qn, q), np.where(bb, sn, s))
        res = patches - m
        W = np.where(bb, _weights(q), W)
        cost = np.where(better, (W * res * res).sum((1, 2)), cost)
        lam = np.where(better, lam * 0.3, lam * 4.0).astype(np.float32)
    A, B, C = p[:, 2], p[:, 3], p[:, 4]
    ok = ((A > 0) & (C > 0) & (A * C - B * B > 0) & (p[:, 5] > 0)
          & (np.abs(p[:, 0]) < h - 1) & (np.abs(p[:, 1]) < h - 1))
    return p, ok


def ellipse_axes(p: np.ndarray):
    """Full axis lengths (major, minor) and angle (degrees, major axis from +x towards +y)."""
    A, B, C = p[:, 2].astype(np.float64), p[:, 3].astype(np.float64), p[:, 4].astype(np.float64)
    tr, det = A + C, A * C - B * B
    disc = np.sqrt(np.maximum((A - C) ** 2 / 4 + B * B, 0))
    lmin = np.maximum(tr / 2 - disc, 1e-9)   # smallest eigenvalue of Q <-> major axis
    lmax = np.maximum(tr / 2 + disc, 1e-9)
    major = 2.0 / np.sqrt(lmin)
    minor = 2.0 / np.sqrt(lmax)
    # Eigenvector of lmin: (B, lmin - A) or (lmin - C, B).
    ang = np.degrees(np.arctan2(lmin - A, B))
    ang = np.where(np.abs(B) < 1e-12, np.where(A <= C, 0.0, 90.0), ang)
    ang = (ang + 90.0) % 180.0 - 90.0
    del det
    return major, minor, ang
