"""A small vectorised triangle rasteriser with a depth buffer (numpy only).

Pixel ``(i, j)`` is sampled at its centre ``(x=j, y=i)``.  Triangles are
grouped by the size of their pixel bounding boxes, and every candidate pixel of
a group is tested at once; the nearest triangle wins each pixel (maximum of
``1/z``, interpolated linearly in the image, as perspective requires).
Barycentric weights returned are perspective-correct, so attributes
interpolate as on the 3D surface.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rasterize", "interpolate"]

_SIZES = (2, 3, 4, 8, 16, 32, 64, 128, 256)
_CHUNK = 400_000        # candidate pixels per batch (bounds memory)


def rasterize(xy: np.ndarray, depth: np.ndarray, tris: np.ndarray, width: int, height: int):
    """Rasterise triangles with a depth test.

    Parameters
    ----------
    xy : ndarray, shape (V, 2)
        Vertex positions in pixels (NaN: vertex not projected; its triangles are skipped).
    depth : ndarray, shape (V,)
        Vertex depth (> 0 in front of the camera).
    tris : ndarray of int, shape (T, 3)
    width, height : int

    Returns
    -------
    tri : ndarray of int32, shape (height, width)
        Index of the visible triangle, -1 where none.
    bary : ndarray of float32, shape (3, height, width)
        Perspective-correct barycentric weights of the visible triangle's vertices.
    """
    H, W = int(height), int(width)
    tri_map = np.full(H * W, -1, np.int32)
    bary = np.zeros((3, H * W), np.float32)
    tris = np.asarray(tris)
    if len(tris) == 0:
        return tri_map.reshape(H, W), bary.reshape(3, H, W)
    x = xy[:, 0][tris]
    y = xy[:, 1][tris]
    iz = 1.0 / np.where(depth > 0, depth, np.nan)[tris]
    xa, xb, xc = x[:, 0], x[:, 1], x[:, 2]
    ya, yb, yc = y[:, 0], y[:, 1], y[:, 2]
    # (Reductions over an axis of length 3 are slow in numpy: spell them out.)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(xa + xb + xc + ya + yb + yc) & np.isfinite(iz[:, 0] + iz[:, 1] + iz[:, 2])
        x0 = np.ceil(np.minimum(np.minimum(xa, xb), xc))
        x1 = np.floor(np.maximum(np.maximum(xa, xb), xc))
        y0 = np.ceil(np.minimum(np.minimum(ya, yb), yc))
        y1 = np.floor(np.maximum(np.maximum(ya, yb), yc))
        area = (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa)
        ok &= (x1 >= 0) & (x0 <= W - 1) & (y1 >= 0) & (y0 <= H - 1) & (x1 >= x0) & (y1 >= y0)
        ok &= np.abs(area) > 1e-12
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return tri_map.reshape(H, W), bary.reshape(3, H, W)
    x0 = np.maximum(x0[idx], 0).astype(np.int64)
    y0 = np.maximum(y0[idx], 0).astype(np.int64)
    x1 = np.minimum(x1[idx], W - 1).astype(np.int64)
    y1 = np.minimum(y1[idx], H - 1).astype(np.int64)
    # Barycentric set-up in float32, relative to the first vertex.
    xa, ya = xa[idx], ya[idx]
    inv = (1.0 / area[idx]).astype(np.float32)
    dxb, dyb = (xb[idx] - xa).astype(np.float32), (yb[idx] - ya).astype(np.float32)
    dxc, dyc = (xc[idx] - xa).astype(np.float32), (yc[idx] - ya).astype(np.float32)
    iz = iz[idx].astype(np.float32)
    ex0 = (x0 - xa).astype(np.float32)
    fy0 = (y0 - ya).astype(np.float32)
    # Candidate boxes: width and height each rounded up to one of _SIZES.
    nsz = len(_SIZES)
    bw = np.searchsorted(_SIZES, x1 - x0 + 1)
    bh = np.searchsorted(_SIZES, y1 - y0 + 1)
    key = bw * (nsz + 1) + bh
    parts = []
    eps = np.float32(-1e-6)
    for kk in np.unique(key):
        sel = np.flatnonzero(key == kk)
        iw, ih = divmod(int(kk), nsz + 1)
        # Triangles larger than the largest size (right in front of a lens) are
        # rare: they get a box of their own size.
        sw = _SIZES[iw] if iw < nsz else int((x1 - x0 + 1)[sel].max())
        sh = _SIZES[ih] if ih < nsz else int((y1 - y0 + 1)[sel].max())
        oy, ox = np.divmod(np.arange(sw * sh), sw)
        oxf, oyf = ox.astype(np.float32), oy.astype(np.float32)
        step = max(1, _CHUNK // (sw * sh))
        for c in range(0, sel.size, step):
            k = sel[c:c + step]
            e = oxf[None, :] + ex0[k, None]        # pixel centre minus first vertex
            f = oyf[None, :] + fy0[k, None]
            ik = inv[k, None]
            b1 = (e * dyc[k, None] - f * dxc[k, None]) * ik
            b2 = (f * dxb[k, None] - e * dyb[k, None]) * ik
            r, cidx = np.nonzero((b1 >= eps) & (b2 >= eps) & (b1 + b2 <= 1.0 - eps))
            if r.size:
                parts.append((k[r], cidx.astype(np.int32), ox[cidx], oy[cidx], b1[r, cidx], b2[r, cidx]))
    if not parts:
        return tri_map.reshape(H, W), bary.reshape(3, H, W)
    tri_i = np.concatenate([p[0] for p in parts])
    px = x0[tri_i] + np.concatenate([p[2] for p in parts])
    py = y0[tri_i] + np.concatenate([p[3] for p in parts])
    b1 = np.concatenate([p[4] for p in parts])
    b2 = np.concatenate([p[5] for p in parts])
    # Boxes are rounded up in size and clipped to the image: keep pixels in both.
    keep = (px <= x1[tri_i]) & (py <= y1[tri_i])
    if not np.all(keep):
        tri_i, px, py, b1, b2 = tri_i[keep], px[keep], py[keep], b1[keep], b2[keep]
    q = iz[tri_i]
    w0 = (1.0 - b1 - b2) * q[:, 0]
    w1 = b1 * q[:, 1]
    w2 = b2 * q[:, 2]
    z = w0 + w1 + w2                                   # 1 / depth, linear in the image
    pix = py * W + px
    zbuf = np.full(H * W, -np.inf, np.float32)
    np.maximum.at(zbuf, pix, z)
    win = np.flatnonzero(z >= zbuf[pix])
    p = pix[win]
    rz = 1.0 / z[win]
    tri_map[p] = idx[tri_i[win]]
    bary[0, p] = w0[win] * rz
    bary[1, p] = w1[win] * rz
    bary[2, p] = w2[win] * rz
    return tri_map.reshape(H, W), bary.reshape(3, H, W)


def interpolate(tri_map: np.ndarray, bary: np.ndarray, tris: np.ndarray, attrs: np.ndarray,
                fill) -> np.ndarray:
    """Per-pixel attributes from per-vertex ones.

    Parameters
    ----------
    tri_map, bary : outputs of :func:`rasterize`
    tris : ndarray of int, shape (T, 3)
    attrs : ndarray, shape (C, V)
        One row per attribute (planar: each is gathered contiguously).
    fill : array_like, shape (C,)
        Value of pixels without a triangle.

    Returns
    -------
    ndarray of float32, shape (C, H, W)
    """
    H, W = tri_map.shape
    C = attrs.shape[0]
    out = np.empty((C, H * W), np.float32)
    out[:] = np.asarray(fill, np.float32)[:, None]
    t = tri_map.ravel()
    cov = np.flatnonzero(t >= 0)
    if cov.size:
        vi = tris[t[cov]]                                  # (n, 3)
        b = bary.reshape(3, -1)[:, cov]
        v0, v1, v2 = vi[:, 0], vi[:, 1], vi[:, 2]
        for c in range(C):
            a = attrs[c]
            out[c, cov] = a[v0] * b[0] + a[v1] * b[1] + a[v2] * b[2]
    return out.reshape(C, H, W)
