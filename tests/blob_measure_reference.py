"""The numpy implementation of :func:`carapost.core.blobs.centre.measure` before it was compiled.

Test-only reference: ``tests/test_blob_measure_kernel.py`` checks that the compiled
kernel (:mod:`carapost.core.blobs.measure_kernel`) computes the same mathematics.
Vectorised over all blobs of one window size: a few dozen numpy reductions over
``(N, n*n)`` float32 arrays (``dtype=np.float64`` computes the same in double precision).
"""
from __future__ import annotations

import numpy as np

from carapost.core.blobs.centre import MIX, PASSES, RING, SLOPE_K, TAPER_IN, TAPER_OUT


def extract(img: np.ndarray, ix: np.ndarray, iy: np.ndarray, h: int) -> np.ndarray:
    """``(N, 2h+1, 2h+1)`` float32 windows centred on integer pixels (``img`` padded by >= h)."""
    g = np.arange(-h, h + 1)
    idx = (iy[:, None, None] + g[None, :, None]) * img.shape[1] + (ix[:, None, None] + g[None, None, :])
    return img.ravel()[idx].astype(np.float32)


class _Grid:
    """Pixel and half-pixel coordinates of one window size (cached)."""

    _cache: dict = {}

    def __new__(cls, h: int, dtype=np.float32):
        if (h, dtype) not in cls._cache:
            self = super().__new__(cls)
            n = 2 * h + 1
            g = np.arange(-h, h + 1, dtype=dtype)
            self.X = np.broadcast_to(g[None, :], (n, n)).ravel().copy()
            self.Y = np.broadcast_to(g[:, None], (n, n)).ravel().copy()
            gh = np.arange(-h, h, dtype=dtype) + 0.5
            self.GX = np.broadcast_to(gh[None, :], (n - 1, n - 1)).ravel().copy()
            self.GY = np.broadcast_to(gh[:, None], (n - 1, n - 1)).ravel().copy()
            # Products of the plane's basis (1, x, y) for the normal equations: (P, 6).
            self.quad = np.stack([np.ones_like(self.X), self.X, self.Y, self.X * self.X, self.X * self.Y,
                                  self.Y * self.Y], 1)
            self.centre9 = np.flatnonzero((np.abs(self.X) <= 1) & (np.abs(self.Y) <= 1))
            cls._cache[(h, dtype)] = self
        return cls._cache[(h, dtype)]


def _box3(a: np.ndarray) -> np.ndarray:
    """3x3 mean of ``(N, m, m)`` with the edge rows and columns replicated."""
    p = np.pad(a, ((0, 0), (1, 1), (1, 1)), mode="edge")
    r = p[:, :-2] + p[:, 1:-1] + p[:, 2:]
    return (r[:, :, :-2] + r[:, :, 1:-1] + r[:, :, 2:]) * a.dtype.type(1.0 / 9.0)


def _taper(d: np.ndarray, r: np.ndarray) -> np.ndarray:
    """1 up to ``r + TAPER_IN``, falling linearly to 0 at ``r + TAPER_OUT``."""
    t = (r[:, None] + TAPER_OUT - d) * d.dtype.type(1.0 / (TAPER_OUT - TAPER_IN))
    return np.clip(t, 0.0, 1.0, out=t)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two ``(N, P)`` arrays."""
    return np.einsum("np,np->n", a, b)


def _plane(P, G, cx, cy, r, noise):
    """Background plane (b, gx, gy) from the ring outside the blob about (cx, cy), and the ring (weights)."""
    dxc = G.X - cx[:, None]
    dyc = G.Y - cy[:, None]
    dc = np.sqrt(dxc * dxc + dyc * dyc)
    ring = ((dc >= r[:, None] + RING[0]) & (dc <= r[:, None] + RING[1])).astype(P.dtype)
    m = ring @ G.quad                                                # (N, 6): sums of 1, x, y, xx, xy, yy
    A = np.stack([m[:, [0, 1, 2]], m[:, [1, 3, 4]], m[:, [2, 4, 5]]], 1)
    A += 1e-3 * np.eye(3, dtype=P.dtype)
    rp = ring * P
    rhs = np.stack([rp.sum(1), rp @ G.X, rp @ G.Y], 1)
    plane = np.linalg.solve(A, rhs[:, :, None])[:, :, 0]
    # A slope noise alone could give is dropped (soft threshold): at SNR 150 the noise of the
    # fitted slope cost 40 % over the Cramér-Rao bound on a flat background.
    sl = np.hypot(plane[:, 1], plane[:, 2])
    sl_noise = noise / np.sqrt(np.maximum(_dot(ring, dc * dc) / 2.0, 1e-6))
    plane[:, 1:] *= (np.maximum(sl - SLOPE_K * sl_noise, 0.0) / np.maximum(sl, 1e-9))[:, None]
    return plane, ring


def _lines(gx, gy, G, cx, cy, r, noise, lim):
    """One radial-symmetry solve about (cx, cy); returns the new centre, the weights and the gradients.

    Line: through (GX, GY) along (gx, gy), normal n = (-gy, gx).  Minimise
    sum w (n . (c - p))^2, i.e. solve (sum w n n^T) c = sum w n (n . p).
    """
    g2 = gx * gx + gy * gy
    w = _taper(np.hypot(G.GX - cx[:, None], G.GY - cy[:, None]), r)
    # Lines of pure noise would pull the answer towards the window's centre: the weight
    # of the weakest is dropped.
    w *= np.maximum(g2 - noise * noise, 0.0)
    wgx, wgy = w * gx, w * gy
    sxx, syy, sxy = _dot(wgy, gy), _dot(wgx, gx), -_dot(wgx, gy)
    npx = gx * G.GY - gy * G.GX
    bx, by = -_dot(wgy, npx), _dot(wgx, npx)
    det = sxx * syy - sxy * sxy
    good = det > 1e-12 * (sxx + syy) ** 2 + 1e-20
    safe = np.where(good, det, 1.0)
    cx = np.clip(np.where(good, (syy * bx - sxy * by) / safe, cx), -lim, lim).astype(cx.dtype)
    cy = np.clip(np.where(good, (sxx * by - sxy * bx) / safe, cy), -lim, lim).astype(cy.dtype)
    return cx, cy, w, gx, gy


def measure_reference(patches: np.ndarray, r0: np.ndarray, noise: float, passes: int = PASSES, dtype=np.float32):
    """The numpy measurement: parameters and returns as :func:`carapost.core.blobs.centre.measure`.

    ``dtype`` is the arithmetic's precision (the detector's was float32; float64
    computes the same mathematics with rounding the kernel's comparison can ignore).
    """
    N, n, _ = patches.shape
    h = n // 2
    G = _Grid(h, dtype)
    P = np.ascontiguousarray(patches, dtype=dtype).reshape(N, n * n)
    r = np.maximum(np.asarray(r0, np.float32).astype(dtype), 1.0)
    Pw = P.reshape(N, n, n)
    # Gradients on the half-pixel grid (2x2 differences: symmetric about each grid point),
    # then a 3x3 mean, which steadies each line's direction: without it the centre was
    # 3.4x the Cramér-Rao bound at SNR 15 instead of 1.1x.
    s = Pw[:, 1:, 1:] - Pw[:, :-1, :-1]
    t = Pw[:, 1:, :-1] - Pw[:, :-1, 1:]
    gx0 = _box3(0.5 * (s - t)).reshape(N, -1)
    gy0 = _box3(0.5 * (s + t)).reshape(N, -1)
    cx = np.zeros(N, dtype)
    cy = np.zeros(N, dtype)
    lim = dtype(h - 1)
    for _ in range(max(1, passes)):
        plane, ring = _plane(P, G, cx, cy, r, noise)
        # A plane only shifts every gradient by its slope.
        cx, cy, w, gx, gy = _lines(gx0 - plane[:, 1:2], gy0 - plane[:, 2:3], G, cx, cy, r, noise, lim)
    D = P - plane[:, 0:1] - plane[:, 1:2] * G.X - plane[:, 2:3] * G.Y
    a_n = D[:, G.centre9].max(1)
    a = np.maximum(a_n, 0.5 * noise + 1e-3)
    g2 = gx * gx + gy * gy
    # How well the lines meet: weighted RMS distance of the lines from the centre (px).
    dist = gx * (cy[:, None] - G.GY) - gy * (cx[:, None] - G.GX)
    line_rms = np.sqrt(_dot(w, dist * dist) / np.maximum(_dot(w, g2), 1e-9))
    border_std = np.sqrt(_dot(ring, D * D) / np.maximum(ring.sum(1), 1.0))
    inside = np.clip(D * (2.0 / a)[:, None] - 0.5, 0.0, 1.0)
    # The inside map's centroid about the lines' centre, then the blend.
    dx = G.X - cx[:, None]
    dy = G.Y - cy[:, None]
    ins = inside * _taper(np.hypot(dx, dy), r)
    m0 = np.maximum(ins.sum(1), 1e-6)
    cx = cx + (1.0 - MIX) * _dot(ins, dx) / m0
    cy = cy + (1.0 - MIX) * _dot(ins, dy) / m0
    dx = G.X - cx[:, None]
    dy = G.Y - cy[:, None]
    ins = inside * _taper(np.hypot(dx, dy), r)
    m0 = np.maximum(ins.sum(1), 1e-6)
    mxx, myy, mxy = _dot(ins, dx * dx) / m0, _dot(ins, dy * dy) / m0, _dot(ins, dx * dy) / m0
    tr, det = mxx + myy, mxx * myy - mxy * mxy
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0))
    # A uniform ellipse of semi-axes (A, B) has second moments A^2/4, B^2/4: full axes 4 sqrt(l).
    major = 4.0 * np.sqrt(np.maximum(tr / 2 + disc, 1e-6))
    minor = 4.0 * np.sqrt(np.maximum(tr / 2 - disc, 1e-6))
    angle = 0.5 * np.degrees(np.arctan2(2 * mxy, mxx - myy))
    angle = (angle + 90.0) % 180.0 - 90.0
    fill = m0 / np.maximum(np.pi * major * minor / 4.0, 1e-6)
    # The core: 0.6 of the moment ellipse (q = 1 on a uniform ellipse's edge).  Paint is
    # uniform there; a pupil has the lights' glints in it, a brow clump has gaps.
    mdet = np.maximum(mxx * myy - mxy * mxy, 1e-6)
    q = (myy[:, None] * dx * dx - 2 * mxy[:, None] * dx * dy + mxx[:, None] * dy * dy) / (4.0 * mdet[:, None])
    core = (q < 0.36).astype(dtype)
    nc = np.maximum(core.sum(1), 1.0)
    cmean = _dot(core, D) / nc
    core_std = np.sqrt(np.maximum(_dot(core, D * D) / nc - cmean * cmean, 0.0)) / a
    background = plane[:, 0] + plane[:, 1] * cx + plane[:, 2] * cy
    wt = _taper(np.hypot(G.GX - cx[:, None], G.GY - cy[:, None]), r)
    g = np.sqrt(g2)
    wg2 = _dot(wt, g2)
    # Sharpness: gradient-weighted mean gradient over contrast (1 / edge width).
    sharp = wg2 / np.maximum(_dot(wt, g), 1e-6) / a
    # Share of the window's gradient energy on the blob's edge (other structures put it elsewhere).
    edge_share = wg2 / np.maximum(g2.sum(1), 1e-6)
    slope = np.hypot(plane[:, 1], plane[:, 2]) * r / a
    ok = (np.isfinite(cx) & np.isfinite(cy) & (np.abs(cx) < h - 1.5) & (np.abs(cy) < h - 1.5)
          & (a_n > 0.5 * noise))
    extra = np.stack([a, line_rms, sharp, border_std, slope, fill, edge_share, background, core_std], 1)
    return cx.astype(np.float64), cy.astype(np.float64), major, minor, angle, ok, extra
