"""A faint thin dot measured as an elliptical Gaussian on a plane (compiled; docs/blobs.md, step 6).

A dot seen edge-on in the shade (the underside of the chin, a jaw at the face's
silhouette) is a line a few grey levels deep and about one pixel across.  Step 3
weighs whatever its window holds, and where the shade curves more than its plane
can follow, the half-contrast map takes in a patch of shade around the line: the
blob is measured round, several pixels across and up to 1.4 px off.  A model of
the right shape, fitted to the pixels, locks onto the line instead:

    m(x, y) = b0 + bx dx + by dy + A exp(-(a dx² + 2 b dx dy + c dy²) / 2),  dx = x - cx, dy = y - cy,

nine parameters, fitted by Levenberg-Marquardt (Marquardt's scaling of the
normal equations' diagonal), each blob in its own window, all in one call.
The inverse covariance ``(a, b, c)`` has no angle to wrap, so one start (a round
Gaussian at the detection's centre) finds lines of any direction.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import JIT
from ..linalg_kernel import lm_scratch, marquardt_step, next_damping, normal_equations
from .edges import _median

#: Parameters: centre (2), inverse covariance (3), amplitude, plane (3).
NPAR = 9
#: Levenberg-Marquardt: iterations at most, the damping's start, and what ends it: a step that moves the centre
#: less than ``STILL`` px (a fit not ended so is not used).
ITERATIONS, DAMPING, STILL = 100, 1e-3, 1e-2
#: Pixels where the Gaussian's exponent is over this are off it (its value 0).
TAIL = 25.0
#: The start: a round Gaussian of this standard deviation (px) at the detection's centre.
START_SIGMA = 1.5


@njit(**JIT)
def _cost(win, x0, y0, w, h, p, res, gau):
    """Sum of squared residuals of parameters ``p`` over the window; each residual kept in ``res`` and the
    Gaussian's value in ``gau`` (for :func:`_jacobian`)."""
    cx, cy, a, b, c, amp, b0, bx, by = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8]
    cost = 0.0
    n = 0
    for iy in range(h):
        dy = y0 + iy - cy
        for ix in range(w):
            dx = x0 + ix - cx
            q = 0.5 * (a * dx * dx + 2.0 * b * dx * dy + c * dy * dy)
            # Most of a thin line's window lies many standard deviations off it: exp(-TAIL) is 1e-11 of the height.
            e = math.exp(-q) if q < TAIL else 0.0
            r = b0 + bx * dx + by * dy + amp * e - win[n]
            gau[n] = e
            res[n] = r
            cost += r * r
            n += 1
    return cost


@njit(**JIT)
def _jacobian(x0, y0, w, h, p, gau, J):
    """The model's derivatives at ``p`` (``gau``: the Gaussian's values there), ``J`` (NPAR, pixels): a row
    per parameter, so that the normal equations' sums run along contiguous rows."""
    cx, cy, a, b, c, amp, bx, by = p[0], p[1], p[2], p[3], p[4], p[5], p[7], p[8]
    n = 0
    for iy in range(h):
        dy = y0 + iy - cy
        for ix in range(w):
            dx = x0 + ix - cx
            e = gau[n]
            ae = amp * e
            J[0, n] = -bx + ae * (a * dx + b * dy)
            J[1, n] = -by + ae * (b * dx + c * dy)
            J[2, n] = -0.5 * ae * dx * dx
            J[3, n] = -ae * dx * dy
            J[4, n] = -0.5 * ae * dy * dy
            J[5, n] = e
            J[6, n] = 1.0
            J[7, n] = dx
            J[8, n] = dy
            n += 1


@njit(**JIT)
def fit_gaussians(img, xs, ys, halfs, out):
    """Fit the elliptical Gaussian on a plane to each blob's window.

    Parameters
    ----------
    img : ndarray (H, W) uint8
        The search image (blobs bright).
    xs, ys : ndarray (N,) float64
        Starting centres (px).
    halfs : ndarray (N,) int64
        Each window's half-size: the window is ``2 half + 1`` px square about the rounded centre
        (cut by the image's border).
    out : ndarray (N, 8) float64
        Filled with ``cx, cy, mxx, myy, mxy, amplitude, rms residual, ok`` per blob: the centre, the
        Gaussian's covariance (px²), its height above the plane, and 1.0 where the fit converged to a
        positive definite Gaussian brighter than the plane (0.0 otherwise).
    """
    H, W = img.shape
    p, trial, step, JtJ, Jtr, L, ridge = lm_scratch(NPAR)
    most = 1
    for k in range(len(halfs)):
        most = max(most, (2 * halfs[k] + 1) ** 2)
    win = np.empty(most)
    flat = np.empty(most)
    res = np.empty(most)
    gau = np.empty(most)
    res_t = np.empty(most)
    gau_t = np.empty(most)
    J = np.empty((NPAR, most))
    for k in range(len(xs)):
        for j in range(8):
            out[k, j] = 0.0
        hw = halfs[k]
        ix0 = max(int(round(xs[k])) - hw, 0)
        iy0 = max(int(round(ys[k])) - hw, 0)
        ix1 = min(int(round(xs[k])) + hw + 1, W)
        iy1 = min(int(round(ys[k])) + hw + 1, H)
        w, h = ix1 - ix0, iy1 - iy0
        if w < 5 or h < 5:
            continue
        n = w * h
        for iy in range(h):
            for ix in range(w):
                win[iy * w + ix] = float(img[iy0 + iy, ix0 + ix])
        base = _median(win[:n], flat)
        cxi = min(max(int(round(xs[k])) - ix0, 0), w - 1)
        cyi = min(max(int(round(ys[k])) - iy0, 0), h - 1)
        inv = 1.0 / (START_SIGMA * START_SIGMA)
        p[0], p[1], p[2], p[3], p[4] = xs[k], ys[k], inv, 0.0, inv
        p[5], p[6], p[7], p[8] = win[cyi * w + cxi] - base, base, 0.0, 0.0
        lam = DAMPING
        cost = _cost(win, ix0, iy0, w, h, p, res, gau)
        _jacobian(ix0, iy0, w, h, p, gau, J)
        normal_equations(J, res, NPAR, n, JtJ, Jtr)
        done = False
        for _ in range(ITERATIONS):
            solved = marquardt_step(JtJ, Jtr, lam, NPAR, ridge, L, step, p, trial)
            # Only a positive definite Gaussian is a blob.
            if solved and trial[2] > 0.0 and trial[4] > 0.0 and trial[2] * trial[4] > trial[3] * trial[3]:
                new = _cost(win, ix0, iy0, w, h, trial, res_t, gau_t)
            else:
                new = math.inf
            lowered = new < cost
            if lowered:
                # The trial's arrays become the fit's (the old ones are the next trial's scratch).
                p, trial, res, res_t, gau, gau_t = trial, p, res_t, res, gau_t, gau
                cost = new
                _jacobian(ix0, iy0, w, h, p, gau, J)
                normal_equations(J, res, NPAR, n, JtJ, Jtr)
            # A step that no longer moves the centre, or no step that lowers the cost: a minimum.
            lam, done = next_damping(lam, lowered)
            if done or (lowered and math.hypot(step[0], step[1]) < STILL):
                done = True
                break
        det = p[2] * p[4] - p[3] * p[3]
        out[k, 0], out[k, 1] = p[0], p[1]
        if det > 0.0:
            out[k, 2], out[k, 3], out[k, 4] = p[4] / det, p[2] / det, -p[3] / det
        out[k, 5] = p[5]
        out[k, 6] = math.sqrt(cost / n)
        out[k, 7] = 1.0 if (done and det > 0.0 and p[2] > 0.0 and p[5] > 0.0) else 0.0
