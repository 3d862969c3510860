"""Candidate blob centres and the features the classifier sees.

Blobs are found on an image pyramid: every level (half, quarter, ... of the
full resolution) is searched with one difference-of-Gaussians filter tuned to
blobs of 1-2.5 pixels radius *at that level*, so one cheap filter per octave
covers every size between the radius limits (and, for black dots, a narrower
one on the finest level for dots under one level pixel across beside a dark
outline: :func:`thin_candidates`).  Local maxima of that response are candidates; the classifier (:mod:`.model`) then looks at each candidate's
neighbourhood only, which is far cheaper than classifying every pixel.

All functions work on a "bright blob" image: black blobs are searched for on
the inverted image, so one code path serves both colours (the two colours
still have their own trained weights).
"""
from __future__ import annotations

import threading

import cv2
import numpy as np

from . import candidate_kernel as ck

#: DoG sigmas at a pyramid level (pixels of that level): centre and surround.
SIGMA_C, SIGMA_S = 1.0, 1.8
#: Centre sigma of the narrower DoG on the finest level, ``G(SIGMA_THIN) - G(SIGMA_C)`` (its surround is the
#: ordinary DoG's centre blur, already made): it peaks on dots under 1 level px across, which the ordinary
#: DoG merges with a dark outline beside them (docs/blobs.md, step 1 and "Thin dots beside dark outlines").
SIGMA_THIN = 0.6
#: The narrower DoG's maxima within this many level px of an ordinary one are left out (the same blob).
THIN_APART = 0.5
#: The narrower DoG's floor, in the level's noise (the ordinary DoG's is 0.5): 1.5 keeps 95 % of its maxima
#: within 1 px of the thin black dots (minor semi-axis under 1.2 px) of the 36 black frames of seeds 0-2
#: and a third of all (476 of 1311 a frame).
THIN_FLOOR = 1.5
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


def pyramid(bright: np.ndarray, deepest: int) -> dict[int, np.ndarray]:
    """The uint8 images of pyramid levels ``1 .. deepest`` (level 0 is the input)."""
    out = {}
    cur = bright
    for level in range(1, deepest + 1):
        cur = cv2.pyrDown(cur)
        out[level] = cur
    return out


class Workspace:
    """One thread's reusable images for :func:`padded_level` and :func:`candidates`.

    Level 1's padded image and blurs are ~1 MB each at 1280x720: allocated
    afresh per frame, glibc mapped, page-faulted and unmapped them again (measured:
    ~800 page faults per frame, ~2 ms of system time, and the threads of Detect
    Blobs [Active Range] queue on the process's memory map for each fault).  Reused,
    they cost nothing, whatever the C heap does (see :mod:`carapost.core.heap`).
    """

    def __init__(self):
        self._images: dict = {}

    def image(self, name: str, shape: tuple, dtype=np.float32) -> np.ndarray:
        """The array called ``name`` of ``shape`` and ``dtype`` (contents undefined)."""
        a = self._images.get(name)
        if a is None or a.shape != shape or a.dtype != dtype:
            a = self._images[name] = np.empty(shape, dtype)
        return a


_local = threading.local()


def workspace() -> Workspace:
    """The calling thread's :class:`Workspace` (one per thread: the range operation's pool detects in parallel)."""
    ws = getattr(_local, "workspace", None)
    if ws is None:
        ws = _local.workspace = Workspace()
    return ws


def padded_level(lvl: np.ndarray, border: int, work: Workspace | None = None, key=0) -> np.ndarray:
    """A uint8 pyramid level as float32, its edge replicated ``border`` px (in ``work``'s arrays when given)."""
    if work is None:
        return cv2.copyMakeBorder(lvl, border, border, border, border, cv2.BORDER_REPLICATE).astype(np.float32)
    shape = (lvl.shape[0] + 2 * border, lvl.shape[1] + 2 * border)
    out = work.image(("pad", key), shape)
    # copyMakeBorder and the float32 copy in one pass.
    ck.pad_level(np.ascontiguousarray(lvl, np.uint8), int(border), out)
    return out


def candidates(lvl: np.ndarray, floor: float, work: Workspace | None = None, key=0):
    """Local maxima of the DoG response on one level (float32), with sub-pixel offsets.

    With ``work``, the blurred images are ``work``'s arrays ``key`` (the next
    call with that key overwrites them).

    Returns
    -------
    ys, xs : ndarray int
        Level-pixel coordinates of candidates (away from the border by PATCH_R).
    dog : ndarray float32
        The DoG response at them.
    g : ndarray float32
        The centre-blurred level image (for the Hessian feature).
    ox, oy : ndarray float32
        Sub-pixel offsets of each maximum, by a parabola through each axis's
        neighbours (within half a pixel).  Coarse-octave candidates are whole
        level pixels (2-16 full pixels) off: the fit converges faster and in
        fewer re-centred windows from a better start.
    """
    if work is None:
        g = cv2.GaussianBlur(lvl, (0, 0), SIGMA_C)
        s = cv2.GaussianBlur(lvl, (0, 0), SIGMA_S)
    else:
        g = cv2.GaussianBlur(lvl, (0, 0), SIGMA_C, dst=work.image(("g", key), lvl.shape))
        s = cv2.GaussianBlur(lvl, (0, 0), SIGMA_S, dst=work.image(("s", key), lvl.shape))
    ys, xs, v, ox, oy = _peaks(g, s, floor)
    return ys, xs, v, g, ox, oy


def thin_candidates(lvl: np.ndarray, g: np.ndarray, floor: float, work: Workspace | None = None, key=0):
    """Local maxima of the narrower DoG ``G(SIGMA_THIN) - g`` on one level, with sub-pixel offsets.

    ``g`` is the level's centre blur from :func:`candidates` (the narrower DoG's
    surround).  A dot under one level pixel across beside a dark outline (an
    edge-on cheek or temple dot 1-3 px inside the face's silhouette, on the
    inverted image a thin bright line beside a bright region) is no local maximum
    of the ordinary DoG, whose response to the outline covers it; this one is
    narrow enough to peak on the dot.  Returns ``(ys, xs, dog, ox, oy)`` as
    :func:`candidates` does.
    """
    dst = None if work is None else work.image(("t", key), lvl.shape)
    t = cv2.GaussianBlur(lvl, (0, 0), SIGMA_THIN, dst=dst)
    return _peaks(t, g, floor)


def _peaks(g: np.ndarray, s: np.ndarray, floor: float):
    """Maxima of the DoG ``g - s`` above ``floor`` (:func:`.candidate_kernel.dog_peaks`), the strongest MAX_CANDIDATES."""
    # The floor as float32, as the DoG is compared with it.
    ys, xs, v, ox, oy = ck.dog_peaks(g, s, np.float32(floor), PATCH_R + 1)
    if len(v) > MAX_CANDIDATES:
        keep = np.argpartition(-v, MAX_CANDIDATES)[:MAX_CANDIDATES]
        ys, xs, v, ox, oy = ys[keep], xs[keep], v[keep], ox[keep], oy[keep]
    return ys, xs, v, ox, oy


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
    interpolated between the ring radii.  The detector uses the compiled
    :func:`.candidate_kernel.profile_radius` (the same arithmetic, to the bit;
    ``tests/test_blob_measure_kernel.py``).
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
