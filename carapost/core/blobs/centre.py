"""Sub-pixel centre and ellipse of blobs, closed form, vectorised over all blobs of a frame.

Two centre estimates are made in each blob's window and blended:

- the **radial symmetry centre** (Parthasarathy, Nature Methods 9, 2012): the point
  nearest, in least squares, to every line through a pixel along the local intensity
  gradient.  The lines of a point-symmetric blob (a disc, and an ellipse too) come in
  pairs reflected through its centre, so the solution is the centre whatever the
  edge profile.  Each line is weighted by its squared gradient, so the edge pixels
  (those that say where the blob is) count and flat skin does not: on isolated discs
  this alone is within 1.05-1.1x the Cramér-Rao bound;
- the **centroid of the half-contrast "inside" map** ``clip(2 d / a - 0.5, 0, 1)``
  (``d`` the background-subtracted window, ``a`` the contrast): inside and outside
  pixels are 1 and 0 whatever the noise, so only edge pixels carry it.  It is
  steadier than the lines where the paint's edge is uneven (oblique dots, textured
  skin) but locks a little to the pixel grid.

On the sample takes' frames the centroid's median error was half the lines' (0.04 vs
0.10 px), on isolated discs at SNR 150 the lines' was two thirds of the centroid's;
``0.3 lines + 0.7 centroid`` kept the best of each (0.05 px median on the sample
frames, 1.1-1.4x the bound on discs).  The background is a plane fitted to a ring just
outside the blob about the current centre; its slope is kept only where it exceeds
what noise alone gives (a noisy slope tilts every gradient line).  Weights taper off
with the distance from the current centre and the solve is repeated about the new
centre, so the window is symmetric about the answer.

The ellipse (axes, angle) is from the second moments of the inside map about the
centre.  The arithmetic is compiled per-blob loops (:mod:`.measure_kernel`, numba):
as numpy reductions over all blobs of one window size it cost ~36 ms per frame of
per-call overhead; the numpy version is kept as the tests' reference
(``tests/blob_measure_reference.py``).
"""
from __future__ import annotations

import numpy as np

from . import measure_kernel

#: Window half-sizes (px); each blob gets the smallest that holds its edge plus BORDER px.
WINDOWS = (5, 7, 10, 14, 20, 28)
#: Background beyond the blob's edge the window must hold (px).
BORDER = 3.5
#: The weights are 1 up to TAPER_IN px beyond the blob's (major) radius, 0 beyond TAPER_OUT.
TAPER_IN, TAPER_OUT = 1.5, 3.0
#: The background plane is fitted to the ring from RING[0] to RING[1] px beyond the blob's radius.
RING = (1.5, 3.5)
#: Radial-symmetry solves, each about the previous answer, from a window centred on a candidate.
PASSES = 3
#: A background slope is kept only beyond this many standard deviations of its noise.
SLOPE_K = 4.0
#: Weight of the radial-symmetry centre in the blend (the rest is the inside map's centroid).
MIX = 0.3
#: The blob's core is the inside of this fraction of its moment ellipse (the ``core_std`` measurement).
CORE = 0.6
#: Names of the per-blob measurements :func:`measure` returns in ``extra`` (stage 2 of the classifier sees them).
MEASURE_NAMES = ("contrast", "line_rms", "sharpness", "border_std", "slope", "fill", "edge_share", "background",
                 "core_std")


def window_for(radius: np.ndarray) -> np.ndarray:
    """Window half-size for blobs of (major) radius ``radius`` px."""
    need = np.ceil(np.asarray(radius, float) + BORDER + 0.5)
    w = np.asarray(WINDOWS)
    return w[np.minimum(np.searchsorted(w, need), len(w) - 1)]


def _constants() -> np.ndarray:
    """The kernel's constants, in :func:`.measure_kernel.measure_one`'s (and ``measure_extra``'s) order."""
    return np.array([TAPER_IN, TAPER_OUT, RING[0], RING[1], SLOPE_K, MIX, CORE * CORE], np.float64)


def measure_at(img: np.ndarray, ix: np.ndarray, iy: np.ndarray, half: np.ndarray, r0: np.ndarray, noise: float,
               passes: int = PASSES):
    """Centre, ellipse and edge measurements of bright blobs in windows of one image.

    Parameters
    ----------
    img : ndarray (H, W)
        Bright-blob image (uint8 or float32), padded so that every window lies inside it.
    ix, iy : ndarray of int (N,)
        Window centres (pixels of ``img``), the blob near them.
    half : ndarray of int (N,)
        Window half-sizes (:func:`window_for`); each blob may have its own.
    r0, noise, passes
        As for :func:`measure`.

    Returns
    -------
    tuple
        As for :func:`measure`, centres relative to ``(ix, iy)``.
    """
    img = np.ascontiguousarray(img)
    ix = np.ascontiguousarray(ix, np.int64)
    iy = np.ascontiguousarray(iy, np.int64)
    half = np.ascontiguousarray(half, np.int64)
    n = len(ix)
    if n and half.min() < 2:
        raise ValueError("measure_at: windows must be at least 5 px square")
    if n and (ix.min() - half.max() < 0 or iy.min() - half.max() < 0 or ix.max() + half.max() >= img.shape[1]
              or iy.max() + half.max() >= img.shape[0]):
        raise ValueError("measure_at: a window reaches outside the image (pad it by the largest half-size)")
    # The radius as float32 first, as the weights were always computed from it.
    r = np.asarray(r0, np.float32).astype(np.float64)
    out = np.zeros((n, 6))
    extra = np.zeros((n, len(MEASURE_NAMES)))
    measure_kernel.measure_at(img, ix, iy, half, r, float(noise), int(passes), _constants(), out, extra,
                              np.zeros((n, 3)), np.zeros(0))
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4], out[:, 5] > 0.5, extra


def measure(patches: np.ndarray, r0: np.ndarray, noise: float, passes: int = PASSES):
    """Centre, ellipse and edge measurements of bright blobs near each window's centre.

    Parameters
    ----------
    patches : ndarray (N, n, n)
        Windows (blob brighter than its surround), the blob near the centre pixel.
    r0 : ndarray (N,)
        Radius guess (px): sizes the tapered weights and the background ring.
    noise : float
        Image noise (grey levels).
    passes : int
        Radial-symmetry solves (fewer suffice when the window is already centred on the blob).

    Returns
    -------
    x, y : ndarray
        Centre relative to the window's centre pixel.
    major, minor, angle : ndarray
        Full axis lengths (px) and major-axis direction (degrees, +x towards +y, in [-90, 90)).
    ok : ndarray of bool
        A finite centre well inside the window with a contrast above half the noise.
    extra : ndarray (N, len(MEASURE_NAMES))
        Contrast, RMS distance of the gradient lines from the centre (px), edge sharpness
        (1/px), background residual, background slope x radius / contrast, fill of the
        moment ellipse, share of the window's gradient energy on the blob's edge, the
        background plane's level at the centre, and the spread of the values inside the
        blob's core (the inner :data:`CORE` of its moment ellipse) over the contrast.
    """
    N, n, _ = patches.shape
    h = n // 2
    # The windows stacked vertically are one image whose k-th window is centred on (h, k n + h).
    img = np.ascontiguousarray(patches, dtype=np.float32).reshape(N * n, n)
    return measure_at(img, np.full(N, h), np.arange(N) * n + h, np.full(N, h), r0, noise, passes)
