"""Sub-pixel ellipse fitting of blobs, vectorised over all blobs of a frame.

Each blob is modelled as a soft-edged ellipse on a flat background::

    m(x, y) = b + gx x + gy y + a * sigmoid(k * (1 - q)),   q^2 = [dx dy] Q [dx dy]^T

with ``Q = [[A, B], [B, C]]`` (the ellipse ``q = 1`` is the half-contrast
boundary), ``a`` the contrast, ``b + gx x + gy y`` the local background (faces are
shaded: a flat background would pull the centre up the gradient) and ``k``
the edge sharpness (optical blur).  Levenberg-Marquardt on all 10 parameters is run on
every blob at once (batched 8x8 solves).  A window that follows the current
ellipse (weight 1 up to 2.5 px beyond the edge, 0 beyond 4 px; a tighter
window measured 1.5x the Cramer-Rao bound instead of 1.2-1.3x: the background
needs pixels) keeps neighbouring markers
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
    """Model, offsets, ``q`` and edge profile of every blob on flattened windows ``(N, P)``."""
    dx = X - p[:, 0:1]
    dy = Y - p[:, 1:2]
    q = p[:, 2:3] * dx * dx
    q += (2 * p[:, 3:4]) * dx * dy
    q += p[:, 4:5] * dy * dy
    np.maximum(q, 0, out=q)
    q += 1e-4
    np.sqrt(q, out=q)
    t = q - 1
    t *= p[:, 7:8]
    np.minimum(t, 30, out=t)
    np.maximum(t, -30, out=t)
    np.exp(t, out=t)
    t += 1
    s = np.reciprocal(t, out=t)
    m = p[:, 5:6] * s
    m += p[:, 6:7] + p[:, 8:9] * X + p[:, 9:10] * Y
    return m, dx, dy, q, s


#: The window reaches this far (px) beyond the blob's edge, tapering over the last RING_TAPER px:
#: enough background for the fit of b, gx, gy whatever the blob's size (a window proportional to
#: the radius wastes pixels on large blobs and starves small ones).
RING_OUT, RING_TAPER = 4.0, 1.5


def _weights(q, p):
    # Geometric-mean radius of the current ellipse: det(Q)^(-1/4).
    det = np.maximum(p[:, 2:3] * p[:, 4:5] - p[:, 3:4] ** 2, 1e-8)
    inv_r = np.sqrt(np.sqrt(det))
    w = (1.0 + RING_OUT * inv_r) - q
    w *= 1.0 / (RING_TAPER * inv_r)
    np.minimum(w, 1.0, out=w)
    np.maximum(w, 0.0, out=w)
    return w


def fit_ellipses(patches: np.ndarray, r0: np.ndarray, iters: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit the soft-ellipse model to bright blobs centred near each window's centre.

    Parameters
    ----------
    patches : ndarray (N, n, n)
        Windows, blob brighter than its surround.
    r0 : ndarray (N,)
        Initial radius guess (px).
    iters : int
        Levenberg-Marquardt iterations.

    Returns
    -------
    params : ndarray (N, 10)
        ``x0, y0`` relative to the window centre, ``A, B, C, a, b, k, gx, gy``.
    ok : ndarray (N,) bool
        The fit converged to a plausible blob inside the window.
    rms : ndarray (N,)
        Weighted RMS residual (grey levels).
    """
    N, n, _ = patches.shape
    h = n // 2
    g = np.arange(-h, h + 1, dtype=np.float32)
    Xs = np.broadcast_to(g[None, :], (n, n)).ravel()
    Ys = np.broadcast_to(g[:, None], (n, n)).ravel()
    # (Restricting the fit to the disc of radius h + 0.5 saved ~20 % of the pixels but lost 1-2 markers
    # of ~1400 in recall on the benchmark frames: the corners do matter for elongated diagonal blobs.)
    X, Y = Xs[None, :].copy(), Ys[None, :].copy()
    P = n * n
    img = np.ascontiguousarray(patches.reshape(N, P), dtype=np.float32)
    p = np.zeros((N, N_PARAMS), np.float32)
    border = np.concatenate([patches[:, 0], patches[:, -1], patches[:, 1:-1, 0], patches[:, 1:-1, -1]], 1)
    bg = np.median(border, 1)
    peak = patches[:, h - 1:h + 2, h - 1:h + 2].mean((1, 2))
    r0 = np.maximum(r0.astype(np.float32), 1.0)
    # Start from the background-subtracted centroid inside r0: a good x0, y0 speeds convergence.
    w0 = np.maximum(img - (bg + 0.5 * (peak - bg))[:, None], 0)
    w0 *= (X ** 2 + Y ** 2 <= (1.5 * r0[:, None]) ** 2)
    sw = w0.sum(1) + 1e-6
    p[:, 0] = np.clip((w0 @ X[0]) / sw, -1.5, 1.5)
    p[:, 1] = np.clip((w0 @ Y[0]) / sw, -1.5, 1.5)
    p[:, 2] = p[:, 4] = 1.0 / r0 ** 2
    p[:, 5] = np.maximum(peak - bg, 1.0) * 1.1
    p[:, 6] = bg
    p[:, 7] = np.clip(1.7 * r0, 2.0, 30.0)
    lam = np.full(N, 1e-2, np.float32)
    m, dx, dy, q, s = _model(p, X, Y)
    W = _weights(q, p)
    res = img - m
    cost = np.einsum("np,np->n", W, res * res)
    eye = np.eye(N_PARAMS, dtype=np.float32)
    # Parameter-major Jacobian: every column write and the weighting are contiguous.
    J = np.empty((N, N_PARAMS, P), np.float32)
    J[:, 6] = 1.0
    J[:, 8] = X
    J[:, 9] = Y
    JW = np.empty_like(J)
    for _ in range(iters):
        a, k = p[:, 5:6], p[:, 7:8]
        ds = s * (1 - s)
        dm_dq = ds
        dm_dq *= -a * k
        dm_dq /= q
        np.multiply(-dm_dq, p[:, 2:3] * dx + p[:, 3:4] * dy, out=J[:, 0])
        np.multiply(-dm_dq, p[:, 3:4] * dx + p[:, 4:5] * dy, out=J[:, 1])
        t = 0.5 * dm_dq * dx
        np.multiply(t, dx, out=J[:, 2])
        np.multiply(t, 2 * dy, out=J[:, 3])
        np.multiply(0.5 * dm_dq * dy, dy, out=J[:, 4])
        J[:, 5] = s
        np.multiply(a * (s * (1 - s)), 1 - q, out=J[:, 7])
        np.multiply(J, W[:, None, :], out=JW)
        H = JW @ J.transpose(0, 2, 1)
        grad = (JW @ res[:, :, None])[:, :, 0]
        D = np.diagonal(H, axis1=1, axis2=2)
        Hd = H + (lam[:, None] * D + 1e-9)[:, :, None] * eye
        try:
            step = np.linalg.solve(Hd, grad[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.zeros_like(grad)
        pn = p + step
        pn[:, 7] = np.clip(pn[:, 7], 0.5, 60.0)
        mn, dxn, dyn, qn, sn = _model(pn, X, Y)
        resn = img - mn
        # Cost on the *old* window so the comparison is fair; the window moves with the accepted fit.
        costn = np.einsum("np,np->n", W, resn * resn)
        better = np.isfinite(costn) & (costn < cost)
        p = np.where(better[:, None], pn, p)
        lam = np.where(better, lam * 0.3, lam * 4.0).astype(np.float32)
        if better.all():   # the common case: take the trial evaluation as it is
            dx, dy, q, s, res = dxn, dyn, qn, sn, resn
        else:              # keep the old evaluation of the rows whose step was refused
            keep = ~better[:, None]
            dx, dy, q, s, res = (np.where(keep, o, nw) for o, nw in
                                 ((dx, dxn), (dy, dyn), (q, qn), (s, sn), (res, resn)))
        W = _weights(q, p)
        cost = np.einsum("np,np->n", W, res * res)
    A, B, C = p[:, 2], p[:, 3], p[:, 4]
    ok = ((A > 0) & (C > 0) & (A * C - B * B > 0) & (p[:, 5] > 0)
          & (np.abs(p[:, 0]) < h - 1) & (np.abs(p[:, 1]) < h - 1))
    rms = np.sqrt(cost / np.maximum(W.sum(1), 1e-6))
    return p, ok, rms


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
