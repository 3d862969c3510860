"""An elongated dot's position along its major axis, from its profile along that axis (compiled; docs/blobs.md,
step 7).

A dot seen obliquely is a short line.  Across it, its two long edges are close and
steep, and step 3 places it to a few hundredths of a pixel; along it, its position
rests on its two ends alone, each a faint blurred step, and the half-contrast map's
centroid follows whatever the skin's texture and shade add beyond them (white
thin dots: 0.47 px RMS along the axis, 0.21 across).  Here the dot's profile along
its axis, the mean of a narrow band about the axis, is fitted with the profile of
a blurred segment on a sloped background:

    p(t) = a (Φ((t - t1) / s) - Φ((t - t2) / s)) + b0 + b1 t,

six parameters by Levenberg-Marquardt.  The dot's centre along the axis is the
segment's middle, ``(t1 + t2) / 2``: each end is found from the whole step, not
from where it crosses half the contrast.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import JIT
from ..linalg_kernel import lm_scratch, marquardt_step, next_damping, normal_equations

#: Parameters: height, the two ends, the blur, the background's level and slope.
NPAR = 6
#: Samples along the axis (px apart), and across it (px apart) within each band.
STEP_ALONG, STEP_ACROSS = 0.5, 0.25
#: The profile reaches this far (px) beyond the measured ends.
BEYOND = 4.0
#: The band about the axis: half-width ``CORE_SHARE`` of the measured minor axis, at least ``CORE_MIN`` px.  (Less
#: the mean of two bands beside it, to take off shade that varies across the line, the profile was noisier: white
#: centre RMS 0.1241 px against 0.1214, black 0.0871 against 0.0868.)
CORE_SHARE, CORE_MIN = 0.15, 0.75
#: Levenberg-Marquardt: iterations at most, the damping's start; a step that moves the middle less than
#: ``STILL`` px ends it.
ITERATIONS, DAMPING, STILL = 60, 1e-3, 5e-3
#: The blur's bounds (px): a step is no sharper than the pixels, and a wider one is no end of a dot.
BLUR_MIN, BLUR_MAX = 0.3, 4.0
#: Largest samples along the axis per dot (the profile of a dot up to ~60 px long).
MOST = 160

_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)


@njit(**JIT)
def _sample(img, x, y):
    """Bilinear sample of ``img`` at (x, y), the border replicated."""
    H, W = img.shape
    x = min(max(x, 0.0), W - 1.0)
    y = min(max(y, 0.0), H - 1.0)
    ix = min(int(x), W - 2)
    iy = min(int(y), H - 2)
    fx = x - ix
    fy = y - iy
    top = img[iy, ix] * (1.0 - fx) + img[iy, ix + 1] * fx
    bot = img[iy + 1, ix] * (1.0 - fx) + img[iy + 1, ix + 1] * fx
    return top * (1.0 - fy) + bot * fy


@njit(**JIT)
def _band(img, cx, cy, ux, uy, t, half):
    """Mean of the samples across the axis at ``t``, from ``-half`` to ``half`` px off it."""
    s = 0.0
    k = int(math.floor(half / STEP_ACROSS + 1e-9))
    px, py = cx + ux * t, cy + uy * t
    for j in range(-k, k + 1):
        v = j * STEP_ACROSS
        s += _sample(img, px - uy * v, py + ux * v)
    return s / (2 * k + 1)


@njit(inline="always", **JIT)
def _cdf(z, pdf):
    """The standard normal distribution function at ``z``, from its density ``pdf`` there (Abramowitz and
    Stegun 26.2.17, error under 7.5e-8): the density is needed anyway, and this is cheaper than ``erfc``."""
    k = 1.0 / (1.0 + 0.2316419 * abs(z))
    tail = pdf * k * (0.319381530 + k * (-0.356563782 + k * (1.781477937 + k * (-1.821255978 + k * 1.330274429))))
    return 1.0 - tail if z >= 0.0 else tail


@njit(**JIT)
def _cost(t, p, n, q, res, phi):
    """Sum of squared residuals of ``q`` over the profile; residuals in ``res``, the two ends' Gaussian
    densities and the segment's unit profile in ``phi`` (3, n), for :func:`_jacobian`."""
    a, t1, t2, s, b0, b1 = q[0], q[1], q[2], q[3], q[4], q[5]
    cost = 0.0
    for i in range(n):
        z1 = (t[i] - t1) / s
        z2 = (t[i] - t2) / s
        d1 = _INV_SQRT2PI * math.exp(-0.5 * z1 * z1)
        d2 = _INV_SQRT2PI * math.exp(-0.5 * z2 * z2)
        box = _cdf(z1, d1) - _cdf(z2, d2)
        r = a * box + b0 + b1 * t[i] - p[i]
        res[i] = r
        phi[0, i] = d1
        phi[1, i] = d2
        phi[2, i] = box
        cost += r * r
    return cost


@njit(**JIT)
def _jacobian(t, n, q, phi, J):
    """The model's derivatives at ``q`` (``phi``: what :func:`_cost` kept), a row per parameter."""
    a, t1, t2, s = q[0], q[1], q[2], q[3]
    for i in range(n):
        z1 = (t[i] - t1) / s
        z2 = (t[i] - t2) / s
        J[0, i] = phi[2, i]
        J[1, i] = -a * phi[0, i] / s
        J[2, i] = a * phi[1, i] / s
        J[3, i] = a * (-phi[0, i] * z1 + phi[1, i] * z2) / s
        J[4, i] = 1.0
        J[5, i] = t[i]


@njit(**JIT)
def fit_profiles(img, xs, ys, angles, majors, minors, out):
    """Fit the blurred segment to each dot's profile along its major axis.

    Parameters
    ----------
    img : ndarray (H, W) uint8
        The search image (blobs bright).
    xs, ys, angles, majors, minors : ndarray (N,) float64
        The measured ellipses: centre (px), major axis' direction (degrees), full axes (px).
    out : ndarray (N, 6) float64
        Filled with ``t1, t2, blur, height, rms residual, ok`` per dot: the segment's ends (px along the
        major axis from the centre), its blur (px), its height over the background, and 1.0 where the
        fit converged to a segment brighter than its surround with both ends inside the profile (0.0
        otherwise).
    """
    t = np.empty(MOST)
    p = np.empty(MOST)
    res = np.empty(MOST)
    res_t = np.empty(MOST)
    phi = np.empty((3, MOST))
    phi_t = np.empty((3, MOST))
    J = np.empty((NPAR, MOST))
    q, trial, step, JtJ, Jtr, L, ridge = lm_scratch(NPAR)
    for k in range(len(xs)):
        for j in range(6):
            out[k, j] = 0.0
        a = math.radians(angles[k])
        ux, uy = math.cos(a), math.sin(a)
        reach = 0.5 * majors[k] + BEYOND
        n = min(2 * int(math.floor(reach / STEP_ALONG)) + 1, MOST)
        if n < NPAR + 3:
            continue
        half = 0.5 * (n - 1) * STEP_ALONG
        core = max(CORE_SHARE * minors[k], CORE_MIN)
        top = -math.inf
        for i in range(n):
            t[i] = -half + i * STEP_ALONG
            p[i] = _band(img, xs[k], ys[k], ux, uy, t[i], core)
            top = max(top, p[i])
        # The start: a segment 0.8 of the measured major axis long, on the level of the profile's first sample.
        q[0], q[1], q[2], q[3], q[4], q[5] = max(top - p[0], 1.0), -0.4 * majors[k], 0.4 * majors[k], 1.0, p[0], 0.0
        lam = DAMPING
        cost = _cost(t, p, n, q, res, phi)
        _jacobian(t, n, q, phi, J)
        normal_equations(J, res, NPAR, n, JtJ, Jtr)
        done = False
        for _ in range(ITERATIONS):
            solved = marquardt_step(JtJ, Jtr, lam, NPAR, ridge, L, step, q, trial)
            # A segment: brighter than its surround, its ends in order and inside the profile, a blur in bounds.
            if (solved and trial[0] > 0.0 and -half <= trial[1] < trial[2] <= half
                    and BLUR_MIN <= trial[3] <= BLUR_MAX):
                new = _cost(t, p, n, trial, res_t, phi_t)
            else:
                new = math.inf
            lowered = new < cost
            if lowered:
                # The trial's arrays become the fit's (the old ones are the next trial's scratch).
                q, trial, res, res_t, phi, phi_t = trial, q, res_t, res, phi_t, phi
                cost = new
                _jacobian(t, n, q, phi, J)
                normal_equations(J, res, NPAR, n, JtJ, Jtr)
            # A step that no longer moves the centre, or no step that lowers the cost: a minimum.
            lam, done = next_damping(lam, lowered)
            if done or (lowered and abs(step[1] + step[2]) * 0.5 < STILL):
                done = True
                break
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = q[1], q[2], q[3], q[0]
        out[k, 4] = math.sqrt(cost / n)
        out[k, 5] = 1.0 if done else 0.0
