"""The numpy implementations of the candidate stage's noise estimate, DoG maxima, sub-pixel offsets and features.

Test-only reference: ``tests/test_blob_measure_kernel.py`` checks that the compiled
kernels (:mod:`carapost.core.blobs.candidate_kernel`) compute the same.
"""
from __future__ import annotations

import cv2
import numpy as np

from carapost.core.blobs.features import (_INNER_IDX, _RING_IDX, _SECTOR_IDX, FEATURE_NAMES, MAX_CANDIDATES, PATCH_R,
                                          SIGMA_C, SIGMA_S, _xx, _yy)


def noise_sigma_reference(img: np.ndarray) -> float:
    """Noise estimate, as :func:`carapost.core.blobs.features.noise_sigma` (``np.partition``'s median)."""
    rows = img[::8].astype(np.int16)
    d = np.abs(np.diff(rows, axis=1)).ravel()
    if d.size == 0:
        return 1.0
    med = float(np.partition(d, d.size // 2)[d.size // 2])
    return max(0.5, 1.4826 * med / np.sqrt(2.0))


def maxima_reference(dog: np.ndarray, floor: float, b: int):
    """Pixels of ``dog`` above ``floor`` and >= their 8 neighbours, ``b`` px or more inside (row-major)."""
    peak = (dog >= cv2.dilate(dog, None)) & (dog > floor)
    peak[:b] = False
    peak[-b:] = False
    peak[:, :b] = False
    peak[:, -b:] = False
    return np.nonzero(peak)


def candidates_reference(lvl: np.ndarray, floor: float, work=None, key=0):
    """Local maxima of the DoG response on one level and their sub-pixel offsets, as
    :func:`carapost.core.blobs.features.candidates` (``work`` and ``key`` are ignored)."""
    g = cv2.GaussianBlur(lvl, (0, 0), SIGMA_C)
    dog = g - cv2.GaussianBlur(lvl, (0, 0), SIGMA_S)
    ys, xs = maxima_reference(dog, floor, PATCH_R + 1)
    v = dog[ys, xs]
    if len(v) > MAX_CANDIDATES:
        keep = np.argpartition(-v, MAX_CANDIDATES)[:MAX_CANDIDATES]
        ys, xs, v = ys[keep], xs[keep], v[keep]
    return (ys, xs, v, g, *subpixel_reference(dog, ys, xs))


def subpixel_reference(dog: np.ndarray, ys: np.ndarray, xs: np.ndarray):
    """Sub-pixel offsets of DoG maxima, as :func:`carapost.core.blobs.features.candidates` gives them (float32)."""
    W = dog.shape[1]
    d = dog.ravel()
    c = ys * W + xs
    l, r, u, b, m = d[c - 1], d[c + 1], d[c - W], d[c + W], d[c]
    dx = 0.5 * (l - r) / np.minimum(l + r - 2 * m, -1e-6)
    dy = 0.5 * (u - b) / np.minimum(u + b - 2 * m, -1e-6)
    return np.clip(dx, -0.5, 0.5), np.clip(dy, -0.5, 0.5)


def features_reference(lvl: np.ndarray, g: np.ndarray, ys: np.ndarray, xs: np.ndarray, dog: np.ndarray,
                       level: int, noise: float) -> np.ndarray:
    """Feature vectors of candidates on one level, as :func:`carapost.core.blobs.features.features`."""
    n = len(ys)
    if n == 0:
        return np.zeros((0, len(FEATURE_NAMES)), np.float32)
    idx = (ys[:, None] + _yy.ravel()[None, :]) * lvl.shape[1] + (xs[:, None] + _xx.ravel()[None, :])
    P = lvl.ravel()[idx]                                   # (N, 81)
    rings = np.stack([P[:, i].mean(1) for i in _RING_IDX], 1)
    centre, outer = rings[:, 0], rings[:, 3]
    # Level noise: pyrDown averages ~4 pixels per level step.
    lnoise = noise / (2.0 ** level)
    contrast = np.maximum(centre - outer, 0.5 * lnoise + 1e-3)
    sectors = np.stack([P[:, i].mean(1) for i in _SECTOR_IDX], 1)
    asym = np.abs(P - P[:, ::-1]).mean(1)                  # reversed ravel == 180-degree rotation
    # Hessian of the centre-blurred image by central differences.
    W = g.shape[1]
    gf = g.ravel()
    c0 = ys * W + xs
    dxx = gf[c0 + 1] + gf[c0 - 1] - 2 * gf[c0]
    dyy = gf[c0 + W] + gf[c0 - W] - 2 * gf[c0]
    dxy = 0.25 * (gf[c0 + W + 1] + gf[c0 - W - 1] - gf[c0 + W - 1] - gf[c0 - W + 1])
    tr, det = dxx + dyy, dxx * dyy - dxy * dxy
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0))
    l1, l2 = tr / 2 - disc, tr / 2 + disc                  # l1 most negative for a bright blob
    ratio = np.where(l1 < 0, l2 / np.minimum(l1, -1e-6), -1.0)
    F = np.empty((n, len(FEATURE_NAMES)), np.float32)
    F[:, 0] = np.log(contrast / lnoise)
    F[:, 1:4] = (centre[:, None] - rings[:, 1:4]) / contrast[:, None]
    F[:, 4] = sectors.std(1) / contrast
    F[:, 5] = (sectors.max(1) - sectors.min(1)) / contrast
    F[:, 6] = asym / contrast
    F[:, 7] = np.clip(ratio, -1, 1)
    F[:, 8] = dog / contrast
    F[:, 9] = outer / 255.0
    F[:, 10] = centre / 255.0
    F[:, 11] = level / 4.0
    F[:, 12] = np.log(np.maximum(dog, 1e-3) / lnoise)
    F[:, 13] = P[:, _INNER_IDX].std(1) / contrast
    return F


def greedy_nms_reference(pts: np.ndarray, score: np.ndarray, clash) -> np.ndarray:
    """Indices kept by greedy suppression: the best first, dropping those that clash with a kept one.

    ``clash(i, j, d)`` is vectorised over candidate pairs within ``clash.reach`` px.
    """
    n = len(pts)
    if n < 2:
        return np.arange(n)
    from scipy.spatial import cKDTree

    pairs = cKDTree(pts).query_pairs(clash.reach, output_type="ndarray")
    if len(pairs) == 0:
        return np.arange(n)
    d = np.hypot(*(pts[pairs[:, 0]] - pts[pairs[:, 1]]).T)
    pairs = pairs[clash(pairs[:, 0], pairs[:, 1], d)]
    nbr: dict[int, list[int]] = {}
    for i, j in pairs.tolist():
        nbr.setdefault(i, []).append(j)
        nbr.setdefault(j, []).append(i)
    alive = np.ones(n, bool)
    for i in np.argsort(-score, kind="stable").tolist():
        if alive[i]:
            for j in nbr.get(i, ()):
                alive[j] = False
    return np.flatnonzero(alive)


def fit_features_reference(cand, sel, logit1, x, y, major, minor, extra, rescued) -> np.ndarray:
    """Stage 2's inputs as numpy expressions (``detector._fit_features`` before it was compiled)."""
    from carapost.core.blobs.model import FIT_FEATURE_NAMES

    moved = np.hypot(x - cand.x[sel], y - cand.y[sel])
    contrast, line_rms, sharp, border_std, slope, fill, edge_share, background, core_std = extra.T
    light = background if cand.white else 255.0 - background
    r = np.maximum(0.5 * major, 0.5)
    F = np.zeros((len(sel), len(FIT_FEATURE_NAMES)), np.float32)
    F[:, 0] = np.clip(logit1[sel], -30, 30)
    F[:, 1] = np.log(np.clip(contrast, 1e-3, 1e4) / cand.noise)
    F[:, 2] = np.log(np.clip(major, 0.5, 500))
    F[:, 3] = np.clip(minor / np.maximum(major, 1e-6), 0, 1)
    F[:, 4] = np.clip(line_rms / r, 0, 5)
    F[:, 5] = np.log(np.clip(sharp, 1e-3, 10))
    F[:, 6] = np.clip(border_std / np.maximum(contrast, 1e-3), 0, 5)
    F[:, 7] = np.clip(slope, 0, 10)
    F[:, 8] = np.clip(fill, 0, 5)
    F[:, 9] = np.clip(edge_share, 0, 1)
    F[:, 10] = np.clip(moved / np.maximum(cand.radius[sel], 1.0), 0, 5)
    F[:, 11] = np.clip(contrast / np.maximum(light, 1.0), 0, 5)
    F[:, 12] = np.clip(core_std, 0, 5)
    F[:, 13] = rescued
    return F
