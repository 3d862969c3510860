"""The light's relative slope about each detection (compiled; docs/blobs.md, step 8).

The helmet's lights fall off across the face and the face's curvature turns it
from them, so the light is a slope across a dot: the image is ``L(x) A(x)``, the
light times the albedo.  A black dot's contrast against the skin is then ``L(x)``
times the albedo's step, larger on the lit side, and a centre that weighs the
contrast (step 3's inside map and gradient lines, step 7's profile) is pulled
towards the light: by ``ε a² / 4`` along an axis of semi-axis ``a`` for the inside
map's centroid, where ``ε`` is the light's slope over its level (``∇L / L``).

This module measures ``ε`` (:func:`light_slopes`): the plane fitted (least squares)
to the grey levels of the skin about each detection, in a square window ``a +
RING_OUT`` px about it less the dot's ellipse grown ``RING_GROW`` times and by
``RING_PAD`` px, divided by the plane's level at the detection; and moves the
detections back (:func:`pull_back`).
"""
from __future__ import annotations

import math

from numba import njit

from ..jit import JIT

#: The window's half-size beyond the semi-major axis, px.
RING_OUT = 6.0
#: The pixels of the dot and its edge left out: its ellipse grown this many times, plus RING_PAD px.
RING_GROW, RING_PAD = 1.6, 1.0
#: Fewer ring pixels than this, or a plane darker than MIN_LEVEL grey levels at the dot: no slope (0).
MIN_PIXELS, MIN_LEVEL = 8, 5.0


@njit(inline="always", **JIT)
def _slope(img, x, y, a, b, co, si):
    """``(∂L/∂x, ∂L/∂y) / L`` at ``(x, y)`` for a dot of semi-axes ``(a, b)`` whose major axis is ``(co, si)``."""
    h_img, w_img = img.shape
    ga, gb = RING_GROW * a + RING_PAD, RING_GROW * b + RING_PAD
    h = int(math.ceil(a + RING_OUT))
    ix, iy = int(math.floor(x + 0.5)), int(math.floor(y + 0.5))
    r0, r1 = max(iy - h, 0), min(iy + h + 1, h_img)
    c0, c1 = max(ix - h, 0), min(ix + h + 1, w_img)
    # The normal equations of v = p0 + p1 dx + p2 dy over the ring's pixels (a 0/1 weight per pixel, so
    # that each row's loop is vectorised).
    iga, igb = 1.0 / ga, 1.0 / gb
    n = sx = sy = sxx = sxy = syy = sv = sxv = syv = 0.0
    for r in range(r0, r1):
        dy = r - y
        u0, w0 = dy * si * iga, dy * co * igb
        # A row's slice, indexed by the loop's counter: no test for negative indices, so the loop vectorises.
        row = img[r, c0:c1]
        for k in range(len(row)):
            dx = c0 + k - x
            u = dx * co * iga + u0
            w = w0 - dx * si * igb
            m = 1.0 if u * u + w * w > 1.0 else 0.0
            v = m * float(row[k])
            n += m
            sx += m * dx
            sy += m * dy
            sxx += m * dx * dx
            sxy += m * dx * dy
            syy += m * dy * dy
            sv += v
            sxv += v * dx
            syv += v * dy
    if n < MIN_PIXELS:
        return 0.0, 0.0
    # The symmetric system M p = (sxv, syv, sv), M = [[sxx, sxy, sx], [sxy, syy, sy], [sx, sy, n]],
    # by its cofactors.
    a00, a01, a02 = syy * n - sy * sy, sx * sy - sxy * n, sxy * sy - syy * sx
    a11, a12, a22 = sxx * n - sx * sx, sxy * sx - sxx * sy, sxx * syy - sxy * sxy
    det = sxx * a00 + sxy * a01 + sx * a02
    if not det > 1e-9:
        return 0.0, 0.0
    level = (a02 * sxv + a12 * syv + a22 * sv) / det
    if level < MIN_LEVEL:
        return 0.0, 0.0
    return (a00 * sxv + a01 * syv + a02 * sv) / det / level, (a01 * sxv + a11 * syv + a12 * sv) / det / level


@njit(**JIT)
def light_slopes(img, x, y, major, minor, angle, out):
    """``out[i] = (∂L/∂x, ∂L/∂y) / L`` at detection ``i`` (per px), from a plane fitted to ``img`` about it.

    ``img`` is the grey image as recorded (the skin bright, black paint dark);
    ``major``, ``minor`` full axes (px), ``angle`` degrees.  Pixels of the window
    outside the image are not used; no plane (too few pixels, or darker than
    ``MIN_LEVEL``) is a slope of 0.
    """
    for i in range(len(x)):
        th = math.radians(angle[i])
        out[i, 0], out[i, 1] = _slope(img, x[i], y[i], 0.5 * major[i], 0.5 * minor[i], math.cos(th), math.sin(th))


@njit(**JIT)
def pull_back(img, x, y, major, minor, angle, upto, steepest):
    """Move black detections (in place: ``x``, ``y``) by ``-ε s² / 4`` along each axis of their ellipse.

    ``ε`` is the light's relative slope along the axis (:func:`light_slopes`; one steeper than
    ``steepest`` a px counts as ``steepest``), ``s`` the semi-axis, at most ``upto`` px.
    """
    for i in range(len(x)):
        a, b = 0.5 * major[i], 0.5 * minor[i]
        th = math.radians(angle[i])
        co, si = math.cos(th), math.sin(th)
        ex, ey = _slope(img, x[i], y[i], a, b, co, si)
        e = math.sqrt(ex * ex + ey * ey)
        if e > steepest:
            ex, ey = ex * steepest / e, ey * steepest / e
        sa, sb = min(a, upto), min(b, upto)
        pa = (ex * co + ey * si) * sa * sa / 4.0
        pb = (ey * co - ex * si) * sb * sb / 4.0
        x[i] -= pa * co - pb * si
        y[i] -= pa * si + pb * co
