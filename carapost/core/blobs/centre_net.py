"""Step 9 of blob detection: a learned correction of each detection's centre.

Steps 3-8 measure a dot's centre from its own pixels with fixed rules (intensity
moments, the painted edge, the profile along an oblique dot, the light's slope).
What is left of their error is mostly the skin around the dot: its texture,
shading and sheen move the edge and the moments alike, by an amount the image
shows but no fixed rule reads (docs/blobs.md, "White centre RMS").  This step
reads it: a small network (one or two tanh layers) looks at the grey levels
about the detection, sampled on a grid in the detection's own frame (``GRID`` x
``GRID`` points spanning its semi-axes plus ``MARGIN`` px either way; the levels
as a share of the dot's contrast over its surround), with the ellipse's
semi-axes, their ratio and the contrast over the image's noise, and answers how
far the centre is off along and across the ellipse.  It was trained (``tools/train_blob_model.py
--centre-only``) on detections of generated sample takes and images whose true
centres are known, never on the benchmark's takes.

The correction is taken in full on textured skin only: where the dot's surround
varies (robust deviation of the grid's border) by ``TEX_FULL`` times the
image's noise or more; not at all at ``TEX_FROM`` or less, and in between in
proportion.  An isolated dot on a flat surround (the brim's printed dots, the
isolated discs of the Cramér-Rao benchmark: 0.4-0.9) is measured near the bound
already, and a network's small errors would only add to it.  A correction is
at most ``MAX_SHIFT`` px either way.

Each detection's inputs and its pass through the network are one compiled loop
(:func:`_errors`, without the interpreter's lock); :func:`centre_inputs` and
:meth:`CentreNet.error` are the same two halves for the training tool.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit

from ..jit import JIT
from .edges import _median

#: Grid points along each axis of the detection's frame.
GRID = 13
#: How far the grid reaches beyond each semi-axis, px.
MARGIN = 2.5
#: Texture (the grid border's robust deviation over the image's noise) at which the correction starts, and at
#: which it is taken in full.
TEX_FROM, TEX_FULL = 1.0, 1.5
#: Largest correction along either axis, px.
MAX_SHIFT = 1.0
#: The inputs after the grid's levels.
GEOMETRY_NAMES = ("semi_major", "semi_minor", "axis_ratio", "log_contrast_noise")
#: Number of inputs.
N_INPUTS = GRID * GRID + len(GEOMETRY_NAMES)

_BORDER = np.array([i * GRID + j for i in range(GRID) for j in range(GRID)
                    if i in (0, GRID - 1) or j in (0, GRID - 1)])
_CORE = np.array([i * GRID + j for i in range(GRID // 2 - 1, GRID // 2 + 2) for j in range(GRID // 2 - 1, GRID // 2 + 2)])


@njit(**JIT)
def _inputs_one(img, x, y, a, b, co, si, noise, grid, border, tmp, row):
    """One detection's inputs into ``row`` (``N_INPUTS``); returns its texture.

    ``grid`` (``GRID * GRID``), ``border`` and ``tmp`` (``len(_BORDER)``) are scratch.  Grid point ``(i, j)``
    lies at ``u = (a + MARGIN) g_j`` along the major axis ``(co, si)`` and ``v = (b + MARGIN) g_i`` across it,
    ``g`` running evenly from -1 to 1; its level is bilinear, the image's edge replicated.
    """
    h, w = img.shape
    step = 2.0 / (GRID - 1)
    su, sv = a + MARGIN, b + MARGIN
    # Inside the image with a pixel to spare (nearly always), no point needs clamping.
    reach = su + sv
    inside = x - reach >= 0.0 and y - reach >= 0.0 and x + reach <= w - 2.0 and y + reach <= h - 2.0
    for i in range(GRID):
        v = sv * (-1.0 + i * step)
        for j in range(GRID):
            u = su * (-1.0 + j * step)
            px, py = x + co * u - si * v, y + si * u + co * v
            if not inside:
                px, py = min(max(px, 0.0), w - 1.0), min(max(py, 0.0), h - 1.0)
            ix, iy = min(int(px), w - 2), min(int(py), h - 2)
            fx, fy = px - ix, py - iy
            top = img[iy, ix] + fx * (float(img[iy, ix + 1]) - img[iy, ix])
            bottom = img[iy + 1, ix] + fx * (float(img[iy + 1, ix + 1]) - img[iy + 1, ix])
            grid[i * GRID + j] = top + fy * (bottom - top)
    for k in range(len(_BORDER)):
        border[k] = grid[_BORDER[k]]
    surround = _median(border, tmp)
    core = 0.0
    for k in range(len(_CORE)):
        core += grid[_CORE[k]]
    contrast = core / len(_CORE) - surround
    scale = contrast if abs(contrast) >= 1.0 else 1.0
    for k in range(GRID * GRID):
        row[k] = (grid[k] - surround) / scale
    n = GRID * GRID
    row[n], row[n + 1], row[n + 2] = a, b, b / max(a, 1e-3)
    row[n + 3] = math.log(max(abs(contrast), 1.0) / noise)
    for k in range(len(_BORDER)):
        border[k] = abs(border[k] - surround)
    return 1.4826 * _median(border, tmp) / noise


@njit(**JIT)
def _all_inputs(img, x, y, a, b, co, si, noise, out, texture):
    """:func:`_inputs_one` for every detection (rows of ``out``, and ``texture``)."""
    grid = np.empty(GRID * GRID)
    border, tmp = np.empty(len(_BORDER)), np.empty(len(_BORDER))
    for k in range(len(x)):
        texture[k] = _inputs_one(img, x[k], y[k], a[k], b[k], co[k], si[k], noise, grid, border, tmp, out[k])


@njit(inline="always", **JIT)
def _tanh_layer(x, n, wt, b, out):
    """``out = tanh(x[:n] @ wt.T + b)``, in float32 (``x``, ``wt``, ``out``): ``wt`` is the layer's weights
    transposed (its rows are contiguous, and each unit's sum vectorises, 16 lanes at a time).

    float32 and one ``expf`` for each tanh (libm's tanh cost twice as much; float64 and ``exp`` 17 % more for
    step 9 in all): the answers move by under 1e-6 px, the weights themselves being float32.
    """
    for j in range(len(b)):
        wj = wt[j]
        acc = np.float32(0.0)
        for i in range(n):
            acc += x[i] * wj[i]
        q = acc + b[j]
        d = math.exp(np.float32(-2.0) * abs(q))
        out[j] = math.copysign((np.float32(1.0) - d) / (np.float32(1.0) + d), q)


@njit(**JIT)
def _errors(img, x, y, a, b, co, si, noise, mean, std, w1t, b1, wht, bh, w2, b2, err, texture):
    """Step 9's network on every detection: its error along and across (``err``, ``(n, 2)``) and its texture.

    The inputs of :func:`_inputs_one`, standardised, through one or two tanh layers (``bh`` empty: one) and a
    linear output, one detection at a time (compiled and without the interpreter's lock: the range operation's
    threads detect in parallel, and numpy's matrix products here queued them on each other).  The weights are
    as :attr:`CentreNet.kernel_arrays` gives them.
    """
    grid = np.empty(GRID * GRID)
    border, tmp = np.empty(len(_BORDER)), np.empty(len(_BORDER))
    row = np.empty(N_INPUTS)
    z = np.empty(N_INPUTS, np.float32)
    h1, h2 = np.empty(len(b1), np.float32), np.empty(len(bh), np.float32)
    for k in range(len(x)):
        texture[k] = _inputs_one(img, x[k], y[k], a[k], b[k], co[k], si[k], noise, grid, border, tmp, row)
        for i in range(N_INPUTS):
            z[i] = (row[i] - mean[i]) / std[i]
        _tanh_layer(z, N_INPUTS, w1t, b1, h1)
        last = h1
        if len(bh):
            _tanh_layer(h1, len(b1), wht, bh, h2)
            last = h2
        e0, e1 = b2[0], b2[1]
        for j in range(len(last)):
            e0 += last[j] * w2[j, 0]
            e1 += last[j] * w2[j, 1]
        err[k, 0], err[k, 1] = e0, e1


def _geometry(x, y, major, minor, angle):
    th = np.deg2rad(np.asarray(angle, np.float64))
    return (np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
            0.5 * np.asarray(major, np.float64), 0.5 * np.asarray(minor, np.float64), np.cos(th), np.sin(th))


def centre_inputs(img: np.ndarray, x, y, major, minor, angle, noise: float):
    """The network's inputs for detections of ``img`` (and how textured each one's surround is).

    Parameters
    ----------
    img : ndarray (H, W) uint8
        The image the detections were found in (either polarity: the levels are taken relative to the dot's
        contrast over its surround, whose sign they lose).
    x, y, major, minor, angle : array_like
        The detections (centre; full axes, px; major axis angle, degrees).
    noise : float
        The image's noise (grey levels, :func:`.features.noise_sigma`).

    Returns
    -------
    inputs : ndarray (n, N_INPUTS) float32
    texture : ndarray (n,)
        The grid border's robust deviation over ``noise``.
    """
    geo = _geometry(x, y, major, minor, angle)
    n = len(geo[0])
    out, texture = np.empty((n, N_INPUTS)), np.empty(n)
    if n:
        _all_inputs(np.ascontiguousarray(img, np.uint8), *geo, float(noise), out, texture)
    return out.astype(np.float32), texture


@dataclass
class CentreNet:
    """Standardisation, one or two tanh hidden layers and a linear output: the centre's error (px) along and
    across.  ``w1``, ``b1``: the first layer; ``wh``, ``bh``: the second (None: none); ``w2``, ``b2``: the output."""

    mean: np.ndarray
    std: np.ndarray
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    wh: np.ndarray | None = None
    bh: np.ndarray | None = None

    def error(self, inputs: np.ndarray) -> np.ndarray:
        """``(n, 2)`` estimated error of each centre along and across its ellipse's major axis, px."""
        if len(inputs) == 0:
            return np.zeros((0, 2), np.float32)
        h = np.tanh(((inputs - self.mean) / self.std) @ self.w1 + self.b1)
        if self.wh is not None:
            h = np.tanh(h @ self.wh + self.bh)
        return h @ self.w2 + self.b2

    @cached_property
    def kernel_arrays(self) -> tuple:
        """The weights as :func:`_errors` takes them (contiguous; the hidden layers transposed, float32)."""
        wh = np.zeros((0, 0)) if self.wh is None else self.wh.T
        bh = np.zeros(0) if self.bh is None else self.bh
        f64, f32 = np.float64, np.float32
        return tuple(np.ascontiguousarray(v, t) for v, t in ((self.mean, f64), (self.std, f64), (self.w1.T, f32),
                                                             (self.b1, f32), (wh, f32), (bh, f32), (self.w2, f64),
                                                             (self.b2, f64)))

    def arrays(self, prefix: str) -> dict:
        named = dict(mean=self.mean, std=self.std, w1=self.w1, b1=self.b1, w2=self.w2, b2=self.b2)
        if self.wh is not None:
            named.update(wh=self.wh, bh=self.bh)
        return {prefix + k: np.asarray(v, np.float32) for k, v in named.items()}

    @classmethod
    def from_arrays(cls, z, prefix: str) -> "CentreNet":
        names = ("mean", "std", "w1", "b1", "w2", "b2") + (("wh", "bh") if prefix + "wh" in z else ())
        return cls(*(np.asarray(z[prefix + k], np.float32) for k in names))


def corrected_centres(img: np.ndarray, rec: np.ndarray, noise: float, net: CentreNet):
    """Step 9: the centres of detections ``rec`` (:data:`~carapost.core.detections.DET_DTYPE`) less the
    error ``net`` reads in ``img`` about them, in full on textured skin only (module docstring).

    Returns ``(x, y)`` float64 arrays.
    """
    x, y, a, b, co, si = _geometry(rec["x"], rec["y"], rec["major"], rec["minor"], rec["angle"])
    n = len(x)
    if n == 0:
        return x, y
    err, texture = np.empty((n, 2)), np.empty(n)
    _errors(np.ascontiguousarray(img, np.uint8), x, y, a, b, co, si, float(noise), *net.kernel_arrays, err,
            texture)
    share = np.clip((texture - TEX_FROM) / (TEX_FULL - TEX_FROM), 0.0, 1.0)
    err = np.clip(err, -MAX_SHIFT, MAX_SHIFT) * share[:, None]
    return x - (err[:, 0] * co - err[:, 1] * si), y - (err[:, 0] * si + err[:, 1] * co)
