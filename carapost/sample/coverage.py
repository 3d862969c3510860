"""Exact area coverage of small ellipses on the pixel grid.

A painted disc of radius ``r`` projects, to first order around its centre,
onto the ellipse ``{c + J q : |q| <= 1}`` where ``J`` is the Jacobian of the
projection (lens distortion included) times ``r``.  Each pixel's coverage is
the area of the ellipse inside it, computed analytically: the affine map
``J^-1`` turns the ellipse into the unit circle and the pixel square into a
parallelogram, and the area of a circle inside a convex polygon is the sum,
over the polygon's edges, of the signed area the circle shares with the
triangle (centre, edge) - triangles where the edge is inside the circle,
circular sectors where it is outside.  The coverage-weighted centroid is then
the ellipse centre to rounding error (see ``docs/sample.md``); a filled
polygon, or a few samples per pixel, is off by up to a tenth of a pixel.

Pixel ``(i, j)`` covers ``[j - 0.5, j + 0.5] x [i - 0.5, i + 0.5]``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ellipse_coverage", "circle_polygon_area"]


def _edge_area(ax, ay, bx, by):
    """Signed area of the unit circle (centre 0) inside the triangle (0, A, B), elementwise."""
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    ad = ax * dx + ay * dy
    aa = ax * ax + ay * ay
    disc = ad * ad - dd * (aa - 1.0)
    has = (disc > 0) & (dd > 0)
    sq = np.sqrt(np.where(has, disc, 0.0))
    safe = np.where(dd > 0, dd, 1.0)
    t1 = np.where(has, np.clip((-ad - sq) / safe, 0.0, 1.0), 0.0)
    t2 = np.where(has, np.clip((-ad + sq) / safe, 0.0, 1.0), 0.0)
    # A -> P1 and P2 -> B lie outside the circle (sectors), P1 -> P2 inside (triangle).
    p1x, p1y = ax + t1 * dx, ay + t1 * dy
    p2x, p2y = ax + t2 * dx, ay + t2 * dy

    def sector(ux, uy, vx, vy):
        return 0.5 * np.arctan2(ux * vy - uy * vx, ux * vx + uy * vy)

    return (sector(ax, ay, p1x, p1y) + 0.5 * (p1x * p2y - p1y * p2x) + sector(p2x, p2y, bx, by))


def circle_polygon_area(px, py):
    """Area of the unit circle inside convex polygons.

    Parameters
    ----------
    px, py : ndarray, shape (..., K)
        Polygon vertices in order (either orientation).

    Returns
    -------
    ndarray, shape (...)
    """
    qx, qy = np.roll(px, -1, axis=-1), np.roll(py, -1, axis=-1)
    return np.abs(np.sum(_edge_area(px, py, qx, qy), axis=-1))


def ellipse_coverage(centres: np.ndarray, J: np.ndarray):
    """Exact coverage of ellipses ``{c + J q : |q| <= 1}`` on their pixel boxes.

    Parameters
    ----------
    centres : ndarray, shape (M, 2)
        Ellipse centres ``(x, y)``, pixels.
    J : ndarray, shape (M, 2, 2)
        Maps the unit disc to the ellipse (columns: images of the disc's axes).

    Returns
    -------
    x0, y0 : ndarray of int, shape (M,)
        Pixel of the top-left corner of each box.
    cov : ndarray of float32, shape (M, n, n)
        Fraction of each box pixel inside the ellipse (rows are y).
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    J = np.asarray(J, dtype=np.float64).reshape(-1, 2, 2)
    M = len(c)
    if M == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 1, 1), np.float32)
    JJt = J @ J.transpose(0, 2, 1)
    hx = np.sqrt(JJt[:, 0, 0])          # half extents of the ellipse's bounding box
    hy = np.sqrt(JJt[:, 1, 1])
    x0 = np.floor(c[:, 0] - hx + 0.5).astype(np.int64) - 1
    y0 = np.floor(c[:, 1] - hy + 0.5).astype(np.int64) - 1
    n = int(np.max(np.ceil(2 * np.maximum(hx, hy))) + 3)
    Ji = np.linalg.inv(J)
    det = np.abs(np.linalg.det(J))
    # Pixel centres in the circle's frame decide most pixels: a pixel whose
    # centre is farther than its own half-diagonal (in that frame) from the
    # circle is wholly inside or outside; only the ring of boundary pixels
    # needs the exact area.
    gx = x0[:, None] + np.arange(n)[None, :] - c[:, :1]          # (M, n) pixel-centre offsets
    gy = y0[:, None] + np.arange(n)[None, :] - c[:, 1:]
    qx = Ji[:, 0, 0, None, None] * gx[:, None, :] + Ji[:, 0, 1, None, None] * gy[:, :, None]
    qy = Ji[:, 1, 0, None, None] * gx[:, None, :] + Ji[:, 1, 1, None, None] * gy[:, :, None]
    rho = np.hypot(qx, qy)
    half = 0.5 * np.maximum(np.hypot(Ji[:, 0, 0] + Ji[:, 0, 1], Ji[:, 1, 0] + Ji[:, 1, 1]),
                            np.hypot(Ji[:, 0, 0] - Ji[:, 0, 1], Ji[:, 1, 0] - Ji[:, 1, 1]))[:, None, None]
    cov = (rho <= 1.0 - half).astype(np.float64)
    mi, ii, jj = np.nonzero((rho > 1.0 - half) & (rho < 1.0 + half))
    if mi.size:
        # The four corners of each boundary pixel, in the circle's frame.
        sx = np.array([-0.5, 0.5, 0.5, -0.5])
        sy = np.array([-0.5, -0.5, 0.5, 0.5])
        cx = gx[mi, jj][:, None] + sx[None, :]
        cy = gy[mi, ii][:, None] + sy[None, :]
        Jm = Ji[mi]
        px = Jm[:, 0, 0, None] * cx + Jm[:, 0, 1, None] * cy
        py = Jm[:, 1, 0, None] * cx + Jm[:, 1, 1, None] * cy
        cov[mi, ii, jj] = np.clip(circle_polygon_area(px, py) * det[mi], 0.0, 1.0)
    return x0, y0, cov.astype(np.float32)
