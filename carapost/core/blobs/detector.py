"""Blob detection on one image: candidates, classification, fitting, filters.

The four steps of the guide's "Blob detection algorithm":

1. candidate centres — local maxima of a per-octave DoG on an image pyramid
   (:mod:`.features`);
2. the classifier — probability that the candidate is a blob centre
   (:mod:`.model`); candidates below the threshold are dropped;
3. the boundary — the half-contrast iso-line of a soft-edged ellipse fitted in
   a window scaled to the blob (:mod:`.fit`);
4. the ellipse — centre, axes and angle of that boundary; then the size filter
   on the longest axis and removal of duplicates found on two octaves.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..detections import COLOR_BLACK, COLOR_WHITE, DET_DTYPE
from ..errors import CaraError
from . import features as fe
from .fit import ellipse_axes, extract, fit_ellipses
from .model import BlobModel, default_model


@dataclass
class Candidates:
    """Classifier inputs of one image (used by training and diagnostics)."""

    x: np.ndarray          #: full-resolution centre estimates
    y: np.ndarray
    level: np.ndarray      #: pyramid level each came from
    feats: np.ndarray      #: (N, F) features


def as_grey_u8(image) -> np.ndarray:
    """The image as a 2-D uint8 array.

    Colour (H, W, 3 or 4; BGR as OpenCV reads) is converted to grey; 16-bit
    images are scaled to 8 bits (``v / 257``); anything else is refused.

    Raises
    ------
    CaraError
        For an image that is not 2-D grey or 3-D colour, or not uint8/uint16.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(np.ascontiguousarray(img), code)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim != 2:
        raise CaraError(f"blob detection needs a grey (H, W) or colour (H, W, 3) image, not shape {img.shape}")
    if img.dtype == np.uint16:
        img = ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CaraError(f"blob detection needs 8- or 16-bit images, not {img.dtype}")
    if min(img.shape) < 8:
        raise CaraError(f"image of {img.shape[1]}x{img.shape[0]} pixels is too small for blob detection")
    return np.ascontiguousarray(img)


def find_candidates(img: np.ndarray, white: bool, min_major: float, max_major: float) -> tuple[Candidates, np.ndarray]:
    """Step 1: candidate centres and their features (``img`` is grey uint8).

    Returns the candidates and the "bright blob" image (inverted for black).
    """
    bright = img if white else cv2.bitwise_not(img)
    noise = fe.noise_sigma(img)
    levels = fe.levels_for(min_major, max_major)
    pyr = fe.pyramid(bright, levels)
    xs_all, ys_all, lv_all, f_all = [], [], [], []
    b = fe.PATCH_R + 1
    for level, lvl in pyr.items():
        if min(lvl.shape) < 2 * b + 3:
            continue
        lnoise = noise / 2.0 ** level
        padded = cv2.copyMakeBorder(lvl, b, b, b, b, cv2.BORDER_REPLICATE)
        ys, xs, dog, g = fe.candidates(padded, max(0.6, 0.5 * lnoise))
        if len(ys) == 0:
            continue
        f_all.append(fe.features(padded, g, ys, xs, dog, level, noise))
        scale = 2.0 ** level
        xs_all.append((xs - b + 0.5) * scale - 0.5)
        ys_all.append((ys - b + 0.5) * scale - 0.5)
        lv_all.append(np.full(len(xs), level, np.int8))
    if not f_all:
        z = np.zeros(0)
        return Candidates(z, z, z.astype(np.int8), np.zeros((0, len(fe.FEATURE_NAMES)), np.float32)), bright
    return Candidates(np.concatenate(xs_all), np.concatenate(ys_all), np.concatenate(lv_all),
                      np.concatenate(f_all)), bright


def fit_level(level: int) -> int:
    """Pyramid level the blobs found on ``level`` are fitted on.

    Small blobs are fitted at full resolution (their centre accuracy matters
    most); blobs of 8 px radius and more have edges long enough that fitting two
    octaves down loses little, and keeps every window at 29x29 pixels or less.
    """
    return max(0, level - 2)


def _window(level: int) -> int:
    """Fit window half-size (pixels of the fit level) for blobs found on ``level``: ~2.3 radii."""
    return int(3 * 2 ** (level - fit_level(level)) + 2)


def fit_candidates(bright: np.ndarray, x: np.ndarray, y: np.ndarray, level: np.ndarray):
    """Steps 3-4: fit ellipses; returns full-resolution (x, y, major, minor, angle, ok)."""
    n = len(x)
    out = [np.zeros(n, np.float64) for _ in range(5)]
    ok = np.zeros(n, bool)
    if n == 0:
        return (*out, ok)
    imgs = {0: bright}
    for f in range(1, fit_level(int(level.max())) + 1):
        imgs[f] = cv2.pyrDown(imgs[f - 1])
    for lv in np.unique(level):
        sel = np.flatnonzero(level == lv)
        f = fit_level(int(lv))
        sc = 2.0 ** f
        img = imgs[f]
        h = _window(int(lv))
        pad = cv2.copyMakeBorder(img, h, h, h, h, cv2.BORDER_REPLICATE)
        # Full-resolution pixel centre x maps to (x + 0.5) / sc - 0.5 on level f.
        fx, fy = (x[sel] + 0.5) / sc - 0.5, (y[sel] + 0.5) / sc - 0.5
        ix = np.clip(np.rint(fx).astype(np.int64), 0, img.shape[1] - 1)
        iy = np.clip(np.rint(fy).astype(np.int64), 0, img.shape[0] - 1)
        patches = extract(pad, ix + h, iy + h, h)
        p, good = fit_ellipses(patches, np.full(len(sel), 1.5 * 2.0 ** (lv - f)))
        major, minor, ang = ellipse_axes(p)
        out[0][sel] = (ix + p[:, 0] + 0.5) * sc - 0.5
        out[1][sel] = (iy + p[:, 1] + 0.5) * sc - 0.5
        out[2][sel], out[3][sel], out[4][sel] = major * sc, minor * sc, ang
        ok[sel] = good & np.isfinite(major) & (major < 2 * h + 1)
    return (*out, ok)


def _dedupe(x, y, minor, score) -> np.ndarray:
    """Indices to keep when one blob was found twice (two octaves, two maxima)."""
    order = np.argsort(-score, kind="stable")
    keep: list[int] = []
    if len(order) == 0:
        return np.zeros(0, np.int64)
    pts = np.stack([x, y], 1)
    taken = np.zeros(len(x), bool)
    # Blobs are sparse: a grid hash keeps this linear.
    cell = 8.0
    grid: dict[tuple[int, int], list[int]] = {}
    for i in order:
        cx, cy = int(pts[i, 0] // cell), int(pts[i, 1] // cell)
        rad = max(2.0, 0.5 * minor[i])
        reach = int(np.ceil(rad / cell))
        clash = False
        for gx in range(cx - reach - 1, cx + reach + 2):
            for gy in range(cy - reach - 1, cy + reach + 2):
                for j in grid.get((gx, gy), ()):
                    if np.hypot(*(pts[i] - pts[j])) < max(rad, max(2.0, 0.5 * minor[j])):
                        clash = True
                        break
                if clash:
                    break
            if clash:
                break
        if not clash:
            keep.append(i)
            taken[i] = True
            grid.setdefault((cx, cy), []).append(i)
    return np.sort(np.array(keep, np.int64))


def detect(image, white: bool = False, threshold: float = 0.4, min_major: float = 4.0, max_major: float = 50.0,
           model: BlobModel | None = None) -> np.ndarray:
    """Detect blobs of one colour in one image.

    Parameters
    ----------
    image : array_like
        Grey uint8 (H, W); colour and 16-bit images are converted (see :func:`as_grey_u8`).
    white : bool
        White blobs (True) or black blobs (False).
    threshold : float
        Minimum classifier probability (0 finds almost everything, 1 almost nothing).
    min_major, max_major : float
        Limits on the full length of the ellipse's longest axis, pixels (the
        guide's Min/Max Radius: "the length of the longest axis").
    model : BlobModel, optional
        Classifier; the shipped one for the colour by default.

    Returns
    -------
    numpy.ndarray
        Detection records (:data:`~carapost.core.detections.DET_DTYPE`), sorted by y then x.
    """
    img = as_grey_u8(image)
    if model is None:
        model = default_model(bool(white))
    cand, bright = find_candidates(img, white, min_major, max_major)
    prob = model.predict(cand.feats)
    sel = prob >= max(float(threshold), 1e-6)
    x, y, major, minor, ang, ok = fit_candidates(bright, cand.x[sel], cand.y[sel], cand.level[sel])
    # The fit may wander to a neighbour: it must stay near the candidate.
    moved = np.hypot(x - cand.x[sel], y - cand.y[sel])
    lv = cand.level[sel]
    ok &= moved <= 1.0 * 2.0 ** lv + 1.0
    ok &= (major >= min_major) & (major <= max_major) & (minor > 0.5)
    # Blobs outside the image (window replicate padding) are not blobs.
    h, w = img.shape
    ok &= (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
    idx = np.flatnonzero(ok)
    score = prob[sel][idx]
    keep = idx[_dedupe(x[idx], y[idx], minor[idx], score)]
    rec = np.zeros(len(keep), DET_DTYPE)
    rec["x"], rec["y"] = x[keep], y[keep]
    rec["major"], rec["minor"], rec["angle"] = major[keep], minor[keep], ang[keep]
    rec["score"] = prob[sel][keep]
    rec["color"] = COLOR_WHITE if white else COLOR_BLACK
    order = np.lexsort((rec["x"], rec["y"]))
    return rec[order]
