"""The numpy version of step 5 (the centre from the painted edge), kept as a reference for its kernel.

``carapost/core/blobs/edges.py`` computes the same, blob by blob, compiled: this
version samples the full-frame Sobel gradients with ``cv2.remap`` (which
quantises sample positions to 1/32 px) and fits all blobs' conics in batches.
``tests/test_blob_edges.py`` checks that both agree.
"""
from __future__ import annotations

import threading

import cv2
import numpy as np

from scipy.ndimage import map_coordinates

from carapost.core.blobs.edges import (AGAIN, AGAIN_SHRINK, ALONG_MAX, ALONG_ROUND, ALONG_THIN, ARC_MOVE, ARC_MOVE_FLAT,
                                       ARCS, COARSE, FLAT, FLAT_MINOR, INLIER, INNER, INSIDE, MAX_MOVE, MAX_SCATTER, MERGED, MIN_RAYS,
                                       RAYS, REACH, STEP, TRUST, WEAK)

_T = np.arange(-REACH, REACH + 1e-9, STEP, dtype=np.float32)
_PHI = np.linspace(0.0, 2.0 * np.pi, RAYS, endpoint=False)
_COS, _SIN = np.cos(_PHI).astype(np.float32), np.sin(_PHI).astype(np.float32)


_buffers = threading.local()


def _gradients(bright: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # Reused output buffers: a fresh 3.7 MB array per image costs more in page faults (~1 ms
    # each here) than the filter itself.
    key = bright.shape
    if getattr(_buffers, "key", None) != key:
        _buffers.key = key
        _buffers.gx = np.empty(key, np.float32)
        _buffers.gy = np.empty(key, np.float32)
    gx = cv2.Sobel(bright, cv2.CV_32F, 1, 0, dst=_buffers.gx, ksize=3, scale=0.125)
    gy = cv2.Sobel(bright, cv2.CV_32F, 0, 1, dst=_buffers.gy, ksize=3, scale=0.125)
    return gx, gy


def _edge_points(gx, gy, cx, cy, a, b, th):
    """Edge points (N, RAYS) x and y, and each ray's peak fall of intensity."""
    f32 = np.float32
    ca, sa = np.cos(th).astype(f32)[:, None], np.sin(th).astype(f32)[:, None]
    a, b = a.astype(f32)[:, None], b.astype(f32)[:, None]
    ex, ey = a * _COS, b * _SIN
    px, py = cx.astype(f32)[:, None] + ca * ex - sa * ey, cy.astype(f32)[:, None] + sa * ex + ca * ey
    # The ellipse's outward normal at parameter phi is (b cos phi, a sin phi) in its own axes.
    n0x, n0y = b * _COS, a * _SIN
    norm = np.hypot(n0x, n0y)
    n0x /= norm
    n0y /= norm
    nx, ny = ca * n0x - sa * n0y, sa * n0x + ca * n0y
    n = len(cx)
    mx = (px[..., None] + nx[..., None] * _T).reshape(n * RAYS, -1)
    my = (py[..., None] + ny[..., None] * _T).reshape(n * RAYS, -1)
    sx = cv2.remap(gx, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE).reshape(n, RAYS, -1)
    sy = cv2.remap(gy, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE).reshape(n, RAYS, -1)
    sx *= nx[..., None]
    sy *= ny[..., None]
    fall = sx
    fall += sy
    np.negative(fall, out=fall)
    # The innermost clear peak on the 1 px grid, then uphill on the 0.25 px samples.
    coarse = fall[..., ::COARSE]
    top = coarse.max(axis=2, keepdims=True)
    lo = np.concatenate([np.full_like(coarse[..., :1], -np.inf), coarse[..., :-1]], axis=2)
    hi = np.concatenate([coarse[..., 1:], np.full_like(coarse[..., :1], -np.inf)], axis=2)
    peaks = (coarse >= INNER * top) & (coarse >= lo) & (coarse >= hi)
    k = np.clip(np.argmax(peaks, axis=2) * COARSE, 1, len(_T) - 2)
    for _ in range(COARSE):
        f0 = np.take_along_axis(fall, k[..., None], 2)[..., 0]
        fm = np.take_along_axis(fall, (k - 1)[..., None], 2)[..., 0]
        fp = np.take_along_axis(fall, (k + 1)[..., None], 2)[..., 0]
        k = np.where((fm > f0) & (k > 1), k - 1, np.where((fp > f0) & (k < len(_T) - 2), k + 1, k))
    k = k[..., None]
    g0 = np.take_along_axis(fall, k - 1, 2)[..., 0].astype(float)
    g1 = np.take_along_axis(fall, k, 2)[..., 0].astype(float)
    g2 = np.take_along_axis(fall, k + 1, 2)[..., 0].astype(float)
    curv = g0 - 2.0 * g1 + g2
    off = np.where(curv < 0, 0.5 * (g0 - g2) / np.where(curv < 0, curv, -1.0), 0.0)
    t = _T[k[..., 0]] + np.clip(off, -1.0, 1.0) * STEP
    return px + nx * t, py + ny * t, g1


def _conic_centres(u, v, w, scale):
    """Weighted algebraic conic fits, batched; centres (in u, v units) and geometric residuals (px).

    ``u``, ``v`` are edge points relative to the current centre divided by
    ``scale`` (so every blob's fit is equally well conditioned).
    """
    M = np.stack([u * u, u * v, v * v, u, v, np.ones_like(u)], axis=-1)          # (N, R, 6)
    S = np.matmul(np.swapaxes(M * w[..., None], 1, 2), M)
    _, vec = np.linalg.eigh(S)
    A, B, C, D, E, _F = np.moveaxis(vec[:, :, 0], 1, 0)
    det = 4.0 * A * C - B * B
    safe = np.where(np.abs(det) > 1e-12, det, 1.0)
    x0, y0 = (B * E - 2.0 * C * D) / safe, (B * D - 2.0 * A * E) / safe
    alg = np.matmul(M, vec[:, :, :1])[..., 0]
    gu = 2.0 * A[:, None] * u + B[:, None] * v + D[:, None]
    gv = B[:, None] * u + 2.0 * C[:, None] * v + E[:, None]
    res = alg / np.maximum(np.hypot(gu, gv), 1e-12) * scale[:, None]
    return x0, y0, det > 0, res, vec[:, :, 0]


def _median_of_used(r: np.ndarray, used: np.ndarray) -> np.ndarray:
    """Per row, the (lower) median of ``r`` where ``used``; infinity for a row with none."""
    r = np.sort(np.where(used, r, np.inf), axis=1)
    n = used.sum(axis=1)
    return r[np.arange(len(r)), np.maximum((n - 1) // 2, 0)]


def _levels(img, px, py):
    """Bilinear intensities at ``(px, py)``, positions clamped into the image (as the kernel's ``_level``)."""
    H, W = img.shape
    px, py = np.clip(px, 0.0, W - 1.0), np.clip(py, 0.0, H - 1.0)
    return map_coordinates(img.astype(np.float64), [py.ravel(), px.ravel()], order=1, mode="nearest").reshape(px.shape)


def _drop_unpainted(img, x, y, a, b, th, ex, ey, peak):
    """``edges._drop_unpainted`` for many blobs: zero the peaks of rays with no paint just inside their edge."""
    q = np.arange(8) * np.pi / 4.0
    ux, uy = 0.35 * a[:, None] * np.cos(q), 0.35 * b[:, None] * np.sin(q)
    ca, sa = np.cos(th)[:, None], np.sin(th)[:, None]
    px = np.concatenate([x[:, None], x[:, None] + ca * ux - sa * uy], axis=1)
    py = np.concatenate([y[:, None], y[:, None] + sa * ux + ca * uy], axis=1)
    core = np.median(_levels(img, px, py), axis=1)[:, None]
    ex, ey = ex.astype(float), ey.astype(float)
    dx, dy = ex - x[:, None], ey - y[:, None]
    r = np.hypot(dx, dy)
    rs = np.maximum(r, 1e-12)
    dx, dy = dx / rs, dy / rs
    d = np.minimum(INSIDE, 0.5 * r)
    inside = _levels(img, ex - dx * d, ey - dy * d)
    outside = _levels(img, ex + dx * INSIDE, ey + dy * INSIDE)
    valid = (peak > 0) & (r >= 1e-6) & (core - outside > 0)
    ratio = np.where(valid, (core - inside) / np.where(valid, core - outside, 1.0), np.nan)
    enough = valid.sum(axis=1) >= MIN_RAYS * RAYS
    usual = np.full(len(x), np.inf)
    if enough.any():
        usual[enough] = np.nanmedian(ratio[enough], axis=1)
    drop = valid & (ratio > usual[:, None] + FLAT)
    return np.where(drop, 0.0, peak)


def _conic_axes(z, x0, y0):
    """``edges._conic_axes`` for many conics: semi-axes and angle; zeros where not a real ellipse."""
    z = np.where((z[:, 0] + z[:, 2] < 0)[:, None], -z, z)
    A, B, C, D, E, F = z.T
    f0 = A * x0 * x0 + B * x0 * y0 + C * y0 * y0 + D * x0 + E * y0 + F
    mean, half = 0.5 * (A + C), np.hypot(0.5 * (A - C), 0.5 * B)
    l1, l2 = mean - half, mean + half
    real = (l1 * l2 > 0) & (f0 * l1 < 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        a, b = np.sqrt(np.where(real, -f0 / l1, 0.0)), np.sqrt(np.where(real, -f0 / l2, 0.0))
    return a, b, np.where(real, 0.5 * np.arctan2(B, A - C) + 0.5 * np.pi, 0.0)


def _robust(u, v, good, scale):
    """Step 5.3 for many blobs: three rounds of the conic, dropping points three robust deviations off."""
    w = good.astype(float)
    for _ in range(3):
        x0, y0, ok, res, _z = _conic_centres(u, v, w, scale)
        spread = 1.4826 * _median_of_used(np.abs(res), w > 0) + 0.02
        w = (good & (np.abs(res) < 3.0 * spread[:, None])).astype(float)
    return x0, y0, ok, spread, w


def _fit_edges(gx, gy, x, y, a, b, th, flat_img=None, mode=1):
    """Edge conic centres of many blobs: (dx, dy) in px, clean, spread, n.

    ``flat_img``: the image of the flat-paint test; ``mode`` 1 tests about the given ellipses, 2 about the
    ellipses first fitted (as the kernel's ``flat`` argument).
    """
    ex, ey, peak = _edge_points(gx, gy, x, y, a, b, th)
    lim = WEAK * np.median(peak, axis=1, keepdims=True)
    test = flat_img is not None and FLAT > 0
    if test and mode == 1:
        wide = b >= FLAT_MINOR
        if wide.any():
            peak[wide] = _drop_unpainted(flat_img, x[wide], y[wide], a[wide], b[wide], th[wide], ex[wide], ey[wide],
                                         peak[wide])
    scale = a
    u, v = (ex - x[:, None]) / scale[:, None], (ey - y[:, None]) / scale[:, None]
    good = (peak > lim) & (peak > 0)
    x0, y0, ok, spread, w = _robust(u, v, good, scale)
    if test and mode == 2:
        _x, _y, ok2, _r, z = _conic_centres(u, v, w, scale)
        fa, fb, fth = _conic_axes(z, _x, _y)
        wide = np.flatnonzero(ok & ok2 & (fb * scale >= FLAT_MINOR))
        if len(wide):
            s = scale[wide]
            new = _drop_unpainted(flat_img, x[wide] + _x[wide] * s, y[wide] + _y[wide] * s, fa[wide] * s, fb[wide] * s,
                                  fth[wide], ex[wide], ey[wide], peak[wide])
            again = wide[(new != peak[wide]).any(axis=1)]
            peak[wide] = new
            good = (peak > lim) & (peak > 0)
            if len(again):
                r = _robust(u[again], v[again], good[again], scale[again])
                for arr, val in zip((x0, y0, ok, spread, w), r):
                    arr[again] = val
    dx, dy = x0 * scale, y0 * scale
    n = w.sum(axis=1)
    clean = ok & (n >= MIN_RAYS * RAYS) & (spread < MAX_SCATTER) & (np.hypot(dx, dy) < MAX_MOVE * b)
    redo = np.flatnonzero(~clean & (np.hypot(dx, dy) > (ARC_MOVE_FLAT if flat_img is not None else ARC_MOVE)))
    if len(redo) and ARCS > 0:
        out = _fit_arcs(u[redo], v[redo], good[redo], scale[redo], b[redo])
        for arr, new in zip((dx, dy, clean, spread, n), out):
            arr[redo] = new
    return dx, dy, clean, spread, n


def _fit_arcs(u, v, good, scale, b):
    """The best arc's ellipse of each blob (``edges._fit_arcs``), batched."""
    span = int(np.ceil(MIN_RAYS * RAYS))
    k = np.arange(RAYS)
    agree = np.full((ARCS, len(u)), -1.0)
    for j in range(ARCS):
        s0 = (j * RAYS) // ARCS
        w = good & (((k - s0) % RAYS) < span)
        _x0, _y0, ok, res, _z = _conic_centres(u, v, w.astype(float), scale)
        agree[j] = np.where(ok, (good & (np.abs(res) < INLIER)).sum(axis=1), -1.0)
    # The first arc with the most agreeing points, as the kernel's strict ``>`` picks.
    best = np.argmax(agree, axis=0)
    s0 = (best * RAYS) // ARCS
    w = good & (((k[None, :] - s0[:, None]) % RAYS) < span)
    for _ in range(3):
        x0, y0, ok, res, _z = _conic_centres(u, v, w.astype(float), scale)
        w = good & (np.abs(res) < INLIER)
    n = w.sum(axis=1).astype(float)
    spread = 1.4826 * _median_of_used(np.abs(res), w) + 0.02
    dx, dy = x0 * scale, y0 * scale
    clean = ok & (agree.max(axis=0) >= 0) & (n >= MIN_RAYS * RAYS) & (spread < MAX_SCATTER) & (np.hypot(dx, dy) < MAX_MOVE * b)
    return dx, dy, clean, spread, n


def _refine_once(gx, gy, x, y, a, b, th, start, flat_img, trust):
    """Step 5 once from the ellipses ``(x, y, a, b, th)``: new centres and each one's share of the edge's move."""
    x, y = x.copy(), y.copy()
    dx, dy, clean, spread, n = _fit_edges(gx, gy, x, y, a, b, th, flat_img)
    shift = np.hypot(dx, dy)
    # The edge points' scatter over the square root of their number: the standard error of the fit's
    # centre, were the rays independent (neighbouring rays share pixels, so TRUST is large).
    noise = np.where(clean, trust * spread / np.sqrt(np.maximum(n, 1.0)), 1.0)
    share = np.where(clean, np.clip((shift - noise) / np.maximum(noise, 1e-9), 0.0, 1.0), 0.0)
    x += dx * share
    y += dy * share
    if start is not None:
        sx, sy, sr = start
        retry = np.flatnonzero(~clean & (sr > 0) & (a > MERGED * sr))
        if len(retry):
            r0 = np.maximum(sr[retry], 1.0)
            dx2, dy2, clean2, _s, _n = _fit_edges(gx, gy, sx[retry], sy[retry], r0, r0, np.zeros(len(retry)), flat_img,
                                                  mode=2)
            got = retry[clean2]
            x[got], y[got] = sx[got] + dx2[clean2], sy[got] + dy2[clean2]
            share[got] = 1.0
    return x, y, share


def refine_centres(bright: np.ndarray, x, y, major, minor, angle, start=None, flat=False, trust=None,
                   along=False):
    """:func:`carapost.core.blobs.edges.refine_centres`, in numpy (same arguments and results)."""
    x = np.asarray(x, float).copy()
    y = np.asarray(y, float).copy()
    if not len(x):
        return x, y, np.zeros(0, bool)
    a = np.maximum(np.asarray(major, float) / 2.0, 0.5)
    b = np.maximum(np.asarray(minor, float) / 2.0, 0.5)
    th = np.deg2rad(np.asarray(angle, float))
    gx, gy = _gradients(bright)
    flat_img = bright if flat else None
    start = None if start is None else tuple(np.asarray(v, float) for v in start)
    trust = np.full(len(x), TRUST) if trust is None else np.asarray(trust, float)
    x1, y1, share = _refine_once(gx, gy, x, y, a, b, th, start, flat_img, trust)
    moved = np.hypot(x1 - x, y1 - y)
    again = np.flatnonzero((share > 0) & (moved > AGAIN)) if AGAIN > 0 else np.zeros(0, int)
    if len(again):
        sub = None if start is None else tuple(v[again] for v in start)
        x2, y2, s2 = _refine_once(gx, gy, x1[again], y1[again], a[again], b[again], th[again], sub, flat_img,
                                  trust[again])
        take = (s2 > 0) & (np.hypot(x2 - x1[again], y2 - y1[again]) < AGAIN_SHRINK * moved[again])
        x1[again[take]], y1[again[take]] = x2[take], y2[take]
    if along:
        # The first centre's weight along the major axis of an elongated blob the edge moved.
        ratio = np.asarray(minor, float) / np.maximum(np.asarray(major, float), 1e-9)
        w = ALONG_MAX * np.clip((ALONG_ROUND - ratio) / (ALONG_ROUND - ALONG_THIN), 0.0, 1.0) * (share > 0)
        t = w * ((x - x1) * np.cos(th) + (y - y1) * np.sin(th))
        x1, y1 = x1 + t * np.cos(th), y1 + t * np.sin(th)
    return x1, y1, share > 0
