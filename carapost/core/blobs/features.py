"""Candidate blob centres and the features the classifier sees.

Blobs are found on an image pyramid: every level (half, quarter, ... of the
full resolution) is searched with one difference-of-Gaussians filter tuned to
blobs of 1-2.5 pixels radius *at that level*, so one cheap filter per octave
covers every size between the radius limits.  Local maxima of that response
are candidates; the classifier (:mod:`.model`) then looks at each candidate's
neighbourhood only, which is far cheaper than classifying every pixel.

All functions work on a "bright blob" image: black blobs are searched for on
the inverted image, so one code path serves both colours (the two colours
still have their own trained weights).
"""
from __future__ import annotations

import cv2
import numpy as np

from . import candidate_kernel as ck

#: DoG sigmas at a pyramid level (pixels of that level): centre and surround.
SIGMA_C, SIGMA_S = 1.0, 1.8
#: Half-size of the patch the features are computed on (level pixels).
PATCH_R = 4
#: Candidates kept per level at most (strongest first): bounds the time on textured images.
MAX_CANDIDATES = 4000

FEATURE_NAMES = (
    "log_cnr", "prof1", "prof2", "prof3", "sector_std", "sector_range", "asym", "hess_ratio",
    "dog_rel", "bg_level", "centre_level", "level", "log_dog_noise", "inner_std",
)

_yy, _xx = np.mgrid[-PATCH_R:PATCH_R + 1, -PATCH_R:PATCH_R + 1]
_dd = np.hypot(_xx, _yy)
_RINGS = [(_dd <= 1.01), (_dd > 1.01) & (_dd <= 2.01), (_dd > 2.01) & (_dd <= 3.01), (_dd > 3.01) & (_dd <= 4.3)]
_RING_IDX = [np.flatnonzero(m.ravel()) for m in _RINGS]
_sect = np.floor((np.arctan2(_yy, _xx) + np.pi) / (2 * np.pi) * 8).astype(int) % 8
_SECTOR_IDX = [np.flatnonzero((_RINGS[3] & (_sect == k)).ravel()) for k in range(8)]
_INNER_IDX = np.flatnonzero((_dd <= 2.01).ravel())
# The same, concatenated with their bounds, for the compiled features.
_RINGS_CAT, _RINGS_PTR = np.concatenate(_RING_IDX), np.cumsum([0] + [len(i) for i in _RING_IDX])
_SECTORS_CAT, _SECTORS_PTR = np.concatenate(_SECTOR_IDX), np.cumsum([0] + [len(i) for i in _SECTOR_IDX])


def level_band(level: int) -> tuple[float, float]:
    """Semi-major axes (full-resolution px) a pyramid level is responsible for."""
    lo = 0.0 if level <= 1 else 2.0 ** (level - 1) * 2.0
    return lo, 2.0 ** level * 2.5


def levels_for(min_major: float, max_major: float) -> list[int]:
    """Pyramid levels needed for blobs whose major axis lies in ``[min_major, max_major]``."""
    out = []
    for level in range(1, 8):
        lo, hi = level_band(level)
        if lo > max_major / 2:
            break
        if hi >= min_major / 2:
            out.append(level)
    return out or [1]


def noise_sigma(img: np.ndarray) -> float:
    """Robust estimate of the per-pixel noise (grey levels) from horizontal differences (``img`` uint8).

    The median absolute difference of neighbours on every 8th row (noise is
    stationary), over sqrt(2), as a standard deviation (x 1.4826); at least 0.5.
    """
    med = ck.median_abs_diff(np.ascontiguousarray(img, np.uint8), 8)
    if med < 0:
        return 1.0
    return max(0.5, 1.4826 * float(med) / np.sqrt(2.0))


def pyramid(bright: np.ndarray, levels: list[int]) -> dict[int, np.ndarray]:
    """The float32 images of the requested pyramid levels (level 0 is the input)."""
    out = {}
    cur = bright
    for level in range(1, max(levels) + 1):
        cur = cv2.pyrDown(cur)
        if level in levels:
            out[level] = cur.astype(np.float32)
    return out


def candidates(lvl: np.ndarray, floor: float):
    """Local maxima of the DoG response on one level.

    Returns
    -------
    ys, xs : ndarray int
        Level-pixel coordinates of candidates (away from the border by PATCH_R).
    dog : ndarray float32
        The DoG response at them.
    g : ndarray float32
        The centre-blurred level image (for the Hessian feature).
    """
    g = cv2.GaussianBlur(lvl, (0, 0), SIGMA_C)
    dog = g - cv2.GaussianBlur(lvl, (0, 0), SIGMA_S)
    # The floor as float32, as the DoG is compared with it.
    ys, xs = ck.dog_maxima(dog, np.float32(floor), PATCH_R + 1)
    v = dog[ys, xs]
    if len(v) > MAX_CANDIDATES:
        keep = np.argpartition(-v, MAX_CANDIDATES)[:MAX_CANDIDATES]
        ys, xs, v = ys[keep], xs[keep], v[keep]
    return ys, xs, v, g, dog


def subpixel(dog: np.ndarray, ys: np.ndarray, xs: np.ndarray):
    """Sub-pixel offsets (dx, dy) of DoG maxima by a parabola through each axis's neighbours.

    Coarse-octave candidates are whole level pixels (2-16 full pixels) off; the
    fit converges faster and in fewer re-centred windows from a better start.
    """
    W = dog.shape[1]
    d = dog.ravel()
    c = ys * W + xs
    l, r, u, b, m = d[c - 1], d[c + 1], d[c - W], d[c + W], d[c]
    dx = 0.5 * (l - r) / np.minimum(l + r - 2 * m, -1e-6)
    dy = 0.5 * (u - b) / np.minimum(u + b - 2 * m, -1e-6)
    return np.clip(dx, -0.5, 0.5), np.clip(dy, -0.5, 0.5)


def features(lvl: np.ndarray, g: np.ndarray, ys: np.ndarray, xs: np.ndarray, dog: np.ndarray,
             level: int, noise: float) -> np.ndarray:
    """Feature vectors ``(N, len(FEATURE_NAMES))`` of candidates on one level.

    Every feature is normalised by the blob's own contrast (or the noise), so
    the classifier sees shape, not brightness: the radial profile, how uniform
    the surround is (eye corners and brows are not), 180-degree symmetry, the
    Hessian eigenvalue ratio (edges and hairs are elongated), contrast-to-noise.
    """
    n = len(ys)
    F = np.empty((n, len(FEATURE_NAMES)), np.float32)
    if n:
        ck.candidate_features(lvl, g, np.asarray(ys, np.int64), np.asarray(xs, np.int64), np.asarray(dog, np.float64),
                              int(level), float(noise), _RINGS_CAT, _RINGS_PTR, _SECTORS_CAT, _SECTORS_PTR,
                              _INNER_IDX, PATCH_R, F)
    return F


def profile_radius(F: np.ndarray) -> np.ndarray:
    """Half-contrast radius (level px) from the radial profile features.

    The profile ``(centre - ring_k) / contrast`` rises from 0 at the centre to
    1 in the surround; the radius is where it crosses 0.5, linearly
    interpolated between the ring radii.
    """
    radii = np.array([0.0, 1.5, 2.5, 3.6])
    prof = np.concatenate([np.zeros((len(F), 1), np.float32), F[:, 1:4]], 1)
    prof = np.maximum.accumulate(np.clip(prof, 0, None), axis=1)
    r = np.full(len(F), 3.6)
    done = np.zeros(len(F), bool)
    for k in range(1, 4):
        hit = ~done & (prof[:, k] >= 0.5)
        t = (0.5 - prof[hit, k - 1]) / np.maximum(prof[hit, k] - prof[hit, k - 1], 1e-6)
        r[hit] = radii[k - 1] + t * (radii[k] - radii[k - 1])
        done |= hit
    return np.clip(r, 0.7, 3.6)
