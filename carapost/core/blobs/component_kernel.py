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
    looks no further).  Returns the new ``n``, ``done``, ``npend`` and the highest grey level of the
    pixels left out (-1 if none; it may be a pixel the region took in after: never lower than the
    level at which the region next grows).
    """
    # Pixels left out at a higher threshold may now be in.
    k = 0
    top = -1
    for i in range(npend):
        p = pending[i]
        v = int(img[y0 + p // w, x0 + p % w])
        if state[p] == 2 and v >= t:
            state[p] = 1
            region[n] = p
            n += 1
        elif state[p] == 2:
            pending[k] = p
            k += 1
            top = max(top, v)
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
            v = int(img[y0 + qy, x0 + qx])
            if v >= t:
                state[q] = 1
                region[n] = q
                n += 1
            elif state[q] == 0:
                state[q] = 2
                pending[npend] = q
                npend += 1
                top = max(top, v)
    return n, done, npend, top


@njit(**JIT)
def threshold_components(img, xs, ys, reach, step, jump, max_area, out):
    """The region about each seed just before it merges with a larger one (module docstring).

    Parameters
    ----------
    img : ndarray (H, W) uint8
        Blobs brighter than their surround.
    xs, ys : ndarray (N,) float64
        Seeds, px; the region grows from the brightest pixel of the 3x3 about each, in the window of
        half-size ``reach`` about that pixel.
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
    # Each seed's brightest pixel of its 3x3: the region and its window depend on that pixel alone, so
    # candidates of one dot (most share it) are grown once.
    key = np.full(len(xs), -1, np.int64)
    for i in range(len(xs)):
        ix, iy = int(round(xs[i])), int(round(ys[i]))
        if ix < 0 or iy < 0 or ix >= w or iy >= h:
            continue
        sx, sy, peak = ix, iy, -1
        for yy in range(max(iy - 1, 0), min(iy + 2, h)):
            for xx in range(max(ix - 1, 0), min(ix + 2, w)):
                if img[yy, xx] > peak:
                    sx, sy, peak = xx, yy, int(img[yy, xx])
        key[i] = sy * w + sx
    order = np.argsort(key)
    prev = -1
    for q in range(len(xs)):
        i = order[q]
        if key[i] >= 0 and key[i] == prev:
            for c in range(out.shape[1]):
                out[i, c] = out[order[q - 1], c]
            continue
        prev = key[i]
        for c in range(out.shape[1]):
            out[i, c] = 0.0
        if key[i] < 0:
            continue
        sy, sx = key[i] // w, key[i] % w
        peak = int(img[sy, sx])
        x0, y0 = max(sx - reach, 0), max(sy - reach, 0)
        x1, y1 = min(sx + reach + 1, w), min(sy + reach + 1, h)
        ww, hh = x1 - x0, y1 - y0
        if ww < 3 or hh < 3:
            continue
        for p in range(ww * hh):
            state[p] = 0
        seed = (sy - y0) * ww + (sx - x0)
        state[seed] = 1
        region[0] = seed
        n, done, npend = 1, 0, 0
        last = 0                # pixels of the region at the last threshold before it merged
        t = peak
        t_merge = 0
        touches = False
        checked = 0             # region pixels already tested against the window's sides
        while t > 0:
            # Growing past the merge test's bound (or, from the seed, past max_area) is all it needs to know.
            limit = max_area if last == 0 else int(jump * last) + 4
            n, done, npend, top = _grow(img, x0, y0, ww, hh, t, state, region, n, done, pending, npend, limit)
            # Only the window's sides inside the image: a dot at the image's edge has not merged.
            for k in range(checked, n):
                p = region[k]
                px, py = p % ww, p // ww
                if (px == 0 and x0 > 0 or py == 0 and y0 > 0 or px == ww - 1 and x1 < w
                        or py == hh - 1 and y1 < h):
                    touches = True
                    break
            checked = n
            if last > 0 and (n > jump * last + 4 or touches):
                t_merge = t
                break
            if touches or n > max_area:
                last = 0
                break
            last = n
            # The thresholds above the brightest pixel left out change nothing: on to the first at or under it
            # (the same grid of steps from the peak).
            t -= step
            if top < t:
                t = peak - step * ((peak - top + step - 1) // step) if top >= 0 else 0
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
        # The last threshold the region stood at: one step over the merging one, or the lowest over 0.
        level = t_merge + step if t_merge > 0 else peak - step * ((peak - 1) // step)
        out[i, 8], out[i, 9], out[i, 10] = peak, level, t_merge


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
    xs, cs, sn, ia, ib = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for k in range(m):
        j = order[k]
        xs[k] = fx[j]
        cs[k], sn[k] = math.cos(math.radians(fang[j])), math.sin(math.radians(fang[j]))
        ia[k], ib[k] = 1.0 / max(fa[j], 0.5), 1.0 / max(fb[j], 0.5)
    for i in range(len(cx)):
        out[i] = True
        r2 = max(near, cr[i]) ** 2
        for k in range(np.searchsorted(xs, cx[i] - reach), m):
            if xs[k] > cx[i] + reach:
                break
            j = order[k]
            dx, dy = cx[i] - fx[j], cy[i] - fy[j]
            u = (cs[k] * dx + sn[k] * dy) * ia[k]
            v = (-sn[k] * dx + cs[k] * dy) * ib[k]
            if dx * dx + dy * dy < r2 or u * u + v * v < 1.0:
                out[i] = False
                break
