"""Compiled threshold components about candidates: a dot found before it merges with what it touches.

A small dot touching a larger dark region (the nose tip's thin dot above the nostrils'
shadow, a lower-lip dot against the open mouth, an edge-on dot at the face's outline) is,
on the "bright blob" image, a bright patch on the rim of a wider, dimmer one.  Thresholded
from the dot's own peak downwards, the connected region holding it grows slowly while it is
the dot, then jumps when the threshold reaches the level of what it touches.  The region
just before that jump is the dot: its weighted centroid and second moments give an ellipse
from which step 5's rays find the dot's own edge (:func:`.edges.edge_ellipses`,
``start=``).  The idea is that of maximally stable extremal regions (Matas et al. 2002),
followed from one seed in a small window instead of over the whole image.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import JIT

#: Columns of :func:`threshold_components`' output.
COMPONENT_COLUMNS = ("x", "y", "area", "a", "b", "angle", "fill", "ok", "peak", "level", "merge")


@njit(**JIT)
def _grow(img, x0, y0, w, h, t, state, region, n, done, pending, npend, limit):
    """Grow the region (``region[:n]``) over the 4-connected pixels of the window at or above ``t``.

    ``state`` per window pixel: 0 not seen, 1 in the region, 2 seen below an earlier threshold (also
    listed in ``pending``, to be looked at again).  ``done`` region pixels have had their
    neighbours looked at.  Stops once the region has more than ``limit`` pixels (the caller then
    looks no further).  Returns the new ``n``, ``done`` and ``npend``.
    """
    # Pixels left out at a higher threshold may now be in.
    k = 0
    for i in range(npend):
        p = pending[i]
        if state[p] == 2 and img[y0 + p // w, x0 + p % w] >= t:
            state[p] = 1
            region[n] = p
            n += 1
        elif state[p] == 2:
            pending[k] = p
            k += 1
    npend = k
    while done < n and n <= limit:
        p = region[done]
        done += 1
        py, px = p // w, p % w
        for d in range(4):
            qx, qy = px, py
            if d == 0:
                qx -= 1
            elif d == 1:
                qx += 1
            elif d == 2:
                qy -= 1
            else:
                qy += 1
            if qx < 0 or qy < 0 or qx >= w or qy >= h:
                continue
            q = qy * w + qx
            if state[q] == 1:
                continue
            if img[y0 + qy, x0 + qx] >= t:
                state[q] = 1
                region[n] = q
                n += 1
            elif state[q] == 0:
                state[q] = 2
                pending[npend] = q
                npend += 1
    return n, done, npend


@njit(**JIT)
def threshold_components(img, xs, ys, reach, step, jump, max_area, out):
    """The region about each seed just before it merges with a larger one (module docstring).

    Parameters
    ----------
    img : ndarray (H, W) uint8
        Blobs brighter than their surround.
    xs, ys : ndarray (N,) float64
        Seeds, px; the region grows from the brightest pixel of the 3x3 about each.
    reach : int
        Half-size of the window searched, px: a region reaching its edge has merged.
    step : int
        Grey levels the threshold falls by each time.
    jump : float
        The region has merged when its area grows past ``jump`` times the last one's, plus 4 px.
    max_area : int
        A region larger than this before it merges is no dot looked for (``ok`` 0).
    out : ndarray (N, len(COMPONENT_COLUMNS)) float64
        Written: the region's centroid weighted by each pixel's grey level over the threshold at
        which it merged, its pixel count, the semi-axes and angle (degrees) of the uniform
        ellipse with its second moments, the share of that ellipse it fills, and ``ok`` (0 where
        the seed's region merged at once).
    """
    h, w = img.shape
    side = 2 * reach + 1
    state = np.zeros(side * side, np.uint8)
    region = np.empty(side * side, np.int64)
    pending = np.empty(side * side, np.int64)
    for i in range(len(xs)):
        for c in range(out.shape[1]):
            out[i, c] = 0.0
        ix, iy = int(round(xs[i])), int(round(ys[i]))
        x0, y0 = max(ix - reach, 0), max(iy - reach, 0)
        x1, y1 = min(ix + reach + 1, w), min(iy + reach + 1, h)
        ww, hh = x1 - x0, y1 - y0
        if ww < 3 or hh < 3 or ix < 0 or iy < 0 or ix >= w or iy >= h:
            continue
        for p in range(ww * hh):
            state[p] = 0
        sx, sy, peak = ix, iy, -1
        for yy in range(max(iy - 1, y0), min(iy + 2, y1)):
            for xx in range(max(ix - 1, x0), min(ix + 2, x1)):
                if img[yy, xx] > peak:
                    sx, sy, peak = xx, yy, int(img[yy, xx])
        seed = (sy - y0) * ww + (sx - x0)
        state[seed] = 1
        region[0] = seed
        n, done, npend = 1, 0, 0
        last = 0                # pixels of the region at the last threshold before it merged
        t = peak
        t_merge = 0
        touches = False
        while t > 0:
            checked = n
            # Growing past the merge test's bound (or, from the seed, past max_area) is all it needs to know.
            limit = max_area if last == 0 else int(jump * last) + 4
            n, done, npend = _grow(img, x0, y0, ww, hh, t, state, region, n, done, pending, npend, limit)
            # Only the window's sides inside the image: a dot at the image's edge has not merged.
            for k in range(checked - 1 if checked == 1 else checked, n):
                p = region[k]
                px, py = p % ww, p // ww
                if (px == 0 and x0 > 0 or py == 0 and y0 > 0 or px == ww - 1 and x1 < w
                        or py == hh - 1 and y1 < h):
                    touches = True
                    break
            if last > 0 and (n > jump * last + 4 or touches):
                t_merge = t
                break
            if touches or n > max_area:
                last = 0
                break
            last = n
            t -= step
        if last == 0:
            continue
        sw = swx = swy = 0.0
        mx = my = 0.0
        for k in range(last):
            p = region[k]
            px, py = p % ww, p // ww
            wgt = float(img[y0 + py, x0 + px]) - t_merge
            sw += wgt
            swx += wgt * px
            swy += wgt * py
            mx += px
            my += py
        mx /= last
        my /= last
        cxx = cyy = cxy = 0.0
        for k in range(last):
            p = region[k]
            dx, dy = p % ww - mx, p // ww - my
            cxx += dx * dx
            cyy += dy * dy
            cxy += dx * dy
        # A pixel is a unit square: its own second moment is 1/12 an axis.
        cxx = cxx / last + 1.0 / 12.0
        cyy = cyy / last + 1.0 / 12.0
        cxy /= last
        tr, det = cxx + cyy, cxx * cyy - cxy * cxy
        disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
        a, b = 2.0 * math.sqrt(tr / 2.0 + disc), 2.0 * math.sqrt(max(tr / 2.0 - disc, 1e-6))
        out[i, 0] = x0 + swx / sw if sw > 0 else x0 + mx
        out[i, 1] = y0 + swy / sw if sw > 0 else y0 + my
        out[i, 2] = last
        out[i, 3], out[i, 4] = a, b
        out[i, 5] = 0.5 * math.degrees(math.atan2(2.0 * cxy, cxx - cyy))
        out[i, 6] = last / (math.pi * a * b)
        out[i, 7] = 1.0
        out[i, 8], out[i, 9], out[i, 10] = peak, t + step, t_merge


@njit(**JIT)
def unexplained(cx, cy, cr, fx, fy, fa, fb, fang, near, out):
    """Mark in ``out`` the points that no ellipse explains.

    A point is explained by an ellipse (centre ``fx, fy``, semi-axes ``fa >= fb``, major axis at ``fang``
    degrees) whose centre lies within ``max(near, cr)`` px of it, or that holds it.
    """
    m = len(fx)
    reach = near
    for j in range(m):
        reach = max(reach, fa[j])
    for i in range(len(cx)):
        reach = max(reach, cr[i])
    order = np.argsort(fx)
    xs = np.empty(m)
    for k in range(m):
        xs[k] = fx[order[k]]
    for i in range(len(cx)):
        out[i] = True
        lo = np.searchsorted(xs, cx[i] - reach)
        r2 = max(near, cr[i]) ** 2
        for k in range(lo, m):
            if xs[k] > cx[i] + reach:
                break
            j = order[k]
            dx, dy = cx[i] - fx[j], cy[i] - fy[j]
            if dx * dx + dy * dy < r2:
                out[i] = False
                break
            c, s = math.cos(math.radians(fang[j])), math.sin(math.radians(fang[j]))
            u = (c * dx + s * dy) / max(fa[j], 0.5)
            v = (-s * dx + c * dy) / max(fb[j], 0.5)
            if u * u + v * v < 1.0:
                out[i] = False
                break
