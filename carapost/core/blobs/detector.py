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
from .model import FIT_FEATURE_NAMES, STAGE1_GATE, BlobModel, default_model


@dataclass
class Candidates:
    """Classifier inputs of one image (used by training and diagnostics)."""

    x: np.ndarray          #: full-resolution centre estimates
    y: np.ndarray
    level: np.ndarray      #: pyramid level each came from
    radius: np.ndarray     #: half-contrast radius estimate, full-resolution px
    noise: float           #: image noise estimate, grey levels
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
        ys, xs, dog, g, dmap = fe.candidates(padded, max(0.6, 0.5 * lnoise))
        if len(ys) == 0:
            continue
        f_all.append(fe.features(padded, g, ys, xs, dog, level, noise))
        ox, oy = fe.subpixel(dmap, ys, xs)
        scale = 2.0 ** level
        xs_all.append((xs + ox - b + 0.5) * scale - 0.5)
        ys_all.append((ys + oy - b + 0.5) * scale - 0.5)
        lv_all.append(np.full(len(xs), level, np.int8))
    if not f_all:
        z = np.zeros(0)
        return Candidates(z, z, z.astype(np.int8), z, noise, np.zeros((0, len(fe.FEATURE_NAMES)), np.float32)), bright
    F = np.concatenate(f_all)
    lv = np.concatenate(lv_all)
    return Candidates(np.concatenate(xs_all), np.concatenate(ys_all), lv,
                      fe.profile_radius(F) * 2.0 ** lv, noise, F), bright


#: Fit window half-sizes (pixels of the fit level); windows are grouped so each group is one batched fit.
_WINDOWS = (7, 10, 14)
#: Largest blob radius fitted at a level's full resolution; larger blobs go one octave down.
_MAX_FIT_RADIUS = 9.0
#: Radius big blobs are brought to (by pyramid levels) for fitting.
_COARSE_FIT_RADIUS = 6.0


def _plan(r0: np.ndarray):
    """Fit level and window half-size for blobs of initial radius ``r0`` (full-res px).

    Small blobs are fitted at full resolution (their centre accuracy matters
    most); larger ones an octave down per doubling, which keeps every window
    at 29x29 pixels or less while their long edges keep the centre accurate.
    """
    f = np.maximum(0, np.ceil(np.log2(np.maximum(r0, 1e-3) / _MAX_FIT_RADIUS))).astype(int)
    # Big blobs (rare, long edges) are fitted small at a coarser level: fewer, cheaper windows.
    f = np.where(f > 0, np.ceil(np.log2(np.maximum(r0, 1e-3) / _COARSE_FIT_RADIUS)).astype(int), f)
    rf = r0 / 2.0 ** f
    need = np.ceil(rf + 5.0)   # the fit's window reaches 4 px beyond the edge
    wins = np.asarray(_WINDOWS)
    k = np.minimum(np.searchsorted(wins, need), len(wins) - 1)
    return f, wins[k]


def _fit_group(imgs, x, y, r0, f, h):
    """One batched fit of blobs sharing fit level ``f`` and window ``h``."""
    sc = 2.0 ** f
    img = imgs[f]
    # Each level is padded once (by the largest window) and shared by all its groups.
    hp = _WINDOWS[-1]
    key = ("pad", f)
    if key not in imgs:
        imgs[key] = cv2.copyMakeBorder(img, hp, hp, hp, hp, cv2.BORDER_REPLICATE)
    pad = imgs[key]
    # Full-resolution pixel centre x maps to (x + 0.5) / sc - 0.5 on level f.
    fx, fy = (x + 0.5) / sc - 0.5, (y + 0.5) / sc - 0.5
    ix = np.clip(np.rint(fx).astype(np.int64), 0, img.shape[1] - 1)
    iy = np.clip(np.rint(fy).astype(np.int64), 0, img.shape[0] - 1)
    p, good, rms = fit_ellipses(extract(pad, ix + hp, iy + hp, h), r0 / sc)
    major, minor, ang = ellipse_axes(p)
    good &= np.isfinite(major) & (major < 2 * h + 1)
    # Edge width (Gaussian-equivalent sigma, full-res px) of the logistic edge: 1.6 R / k.
    r_geo = 0.25 * np.sqrt(np.maximum(major * minor, 1e-6)) * sc * 2
    edge = 1.596 * r_geo / np.maximum(p[:, 7], 1e-3)
    grad = np.hypot(p[:, 8], p[:, 9]) * r_geo / sc
    extra = np.stack([edge, p[:, 5], rms, grad, p[:, 7]], 1)
    return ((ix + p[:, 0] + 0.5) * sc - 0.5, (iy + p[:, 1] + 0.5) * sc - 0.5, major * sc, minor * sc, ang, good,
            extra)


def fit_candidates(bright: np.ndarray, x: np.ndarray, y: np.ndarray, r0: np.ndarray):
    """Steps 3-4: fit ellipses; returns full-resolution (x, y, major, minor, angle, ok, extra).

    ``extra`` is ``(N, 5)``: edge width (px), contrast, RMS residual, background
    change across the blob, edge sharpness ``k`` — what stage 2 of the classifier sees.

    Blobs whose fitted size outgrows their window (the radius guess was low)
    are fitted again with a window planned from the first fit.
    """
    n = len(x)
    out = [np.zeros(n, np.float64) for _ in range(5)]
    ok = np.zeros(n, bool)
    extra = np.zeros((n, 5))
    if n == 0:
        return (*out, ok, extra)
    imgs = {0: bright}
    x0, y0 = x, y
    todo = np.arange(n)
    rr = r0.astype(np.float64)
    hmax = np.zeros(n)
    for _round in range(2):
        f, h = _plan(rr[todo])
        for key in sorted(set(zip(f.tolist(), h.tolist()))):
            sel = todo[(f == key[0]) & (h == key[1])]
            for lv in range(1, key[0] + 1):
                if lv not in imgs:
                    imgs[lv] = cv2.pyrDown(imgs[lv - 1])
            res = _fit_group(imgs, x[sel], y[sel], rr[sel], *key)
            for i in range(5):
                out[i][sel] = res[i]
            ok[sel] = res[5]
            extra[sel] = res[6]
            hmax[sel] = key[1] * 2.0 ** key[0]
        # Refit (a) blobs too big for their window (edge + 4 px must fit
        # inside it) and (b) blobs whose centre ended far from the window centre:
        # coarse-level candidates start up to 2 px off, and an off-centre window
        # lets the fit settle on a lopsided optimum.
        t = todo[ok[todo]]
        off = np.maximum(np.abs(out[0][t] - x[t]), np.abs(out[1][t] - y[t])) * 2.0 ** -_plan(rr[t])[0]
        again = t[(0.5 * out[2][t] + 5.0 > hmax[t] + 1) | (off > 1.0)]
        if len(again) == 0:
            break
        rr[again] = np.maximum(0.5 * out[2][again], 1.0)
        x, y = x.copy(), y.copy()
        x[again], y[again] = out[0][again], out[1][again]
        todo = again
    # Fits that diverged (usually a marker touching a brow, hair or another structure
    # that the window took in) get one more try in the smallest window, from the
    # candidate itself: less context, but the blob's own edge dominates.
    failed = np.flatnonzero(~ok & (r0 <= _MAX_FIT_RADIUS))
    if len(failed):
        res = _fit_group(imgs, x0[failed], y0[failed], np.minimum(r0[failed], 3.5), 0, _WINDOWS[0])
        good = res[5]
        idx = failed[good]
        for i in range(5):
            out[i][idx] = res[i][good]
        ok[idx] = True
        extra[idx] = res[6][good]
    return (*out, ok, extra)


def _greedy_nms(pts: np.ndarray, score: np.ndarray, clash) -> np.ndarray:
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


def _suppress(x, y, reach, score) -> np.ndarray:
    """Candidates kept when one blob was found on several octaves.

    Two distinct blobs are at least the sum of their radii apart; one blob seen
    on two octaves gives centres much closer than either radius.
    """
    def clash(i, j, d):
        return d < np.minimum(reach[i], reach[j]) + 1.0
    clash.reach = float(reach.max()) + 1.0 if len(reach) else 1.0
    return _greedy_nms(np.stack([x, y], 1), score, clash)


def _dedupe(x, y, minor, score) -> np.ndarray:
    """Detections kept when one blob was fitted twice: closer than half the larger minor axis (>= 2 px)."""
    rad = np.maximum(2.0, 0.5 * minor)

    def clash(i, j, d):
        return d < np.maximum(rad[i], rad[j])
    clash.reach = float(rad.max()) if len(rad) else 1.0
    return _greedy_nms(np.stack([x, y], 1), score, clash)


@dataclass
class Fitted:
    """Candidates that passed stage 1, fitted (full-resolution geometry)."""

    x: np.ndarray
    y: np.ndarray
    major: np.ndarray
    minor: np.ndarray
    angle: np.ndarray
    ok: np.ndarray        #: the fit is a plausible blob near its candidate, inside the image
    prob1: np.ndarray     #: stage-1 probability
    feats: np.ndarray     #: stage-2 features (:data:`~.model.FIT_FEATURE_NAMES`)


def fit_stage(cand: Candidates, bright: np.ndarray, model: BlobModel) -> Fitted:
    """Stage-1 gate, suppression of duplicates, fitting, and the stage-2 features."""
    logit1 = model.stage1.logit(cand.feats)
    prob1 = 1.0 / (1.0 + np.exp(-np.clip(logit1, -30, 30)))
    sel = np.flatnonzero(prob1 >= STAGE1_GATE)
    # One blob is usually a candidate on two or three octaves: fit it once, from the
    # finest octave's candidate (closest to the centre; coarse ones start pixels off).
    sel = sel[_suppress(cand.x[sel], cand.y[sel], cand.radius[sel], prob1[sel] - cand.level[sel])]
    x, y, major, minor, ang, ok, extra = fit_candidates(bright, cand.x[sel], cand.y[sel], cand.radius[sel])
    # The fit may wander to a neighbour: it must stay near the candidate.
    moved = np.hypot(x - cand.x[sel], y - cand.y[sel])
    ok &= moved <= np.maximum(1.0 * cand.radius[sel], 2.0)
    ok &= minor > 0.5
    h, w = bright.shape
    ok &= (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
    edge, contrast, rms, grad, k = extra.T
    F = np.zeros((len(sel), len(FIT_FEATURE_NAMES)), np.float32)
    F[:, 0] = np.clip(logit1[sel], -30, 30)
    F[:, 1] = np.clip(edge, 0, 20)
    F[:, 2] = np.log(np.clip(major, 0.5, 500))
    F[:, 3] = np.clip(minor / np.maximum(major, 1e-6), 0, 1)
    F[:, 4] = np.log(np.clip(contrast, 1e-3, 1e4) / cand.noise)
    F[:, 5] = np.clip(rms / np.maximum(contrast, 1e-3), 0, 5)
    F[:, 6] = np.clip(grad / np.maximum(contrast, 1e-3), 0, 5)
    F[:, 7] = np.log(np.clip(k, 0.5, 60))
    return Fitted(x, y, major, minor, ang, ok, prob1[sel].astype(np.float32), F)


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
    fitted = fit_stage(cand, bright, model)
    if model.stage2 is not None:
        prob = model.stage2.predict(fitted.feats)
    else:
        prob = fitted.prob1
    ok = fitted.ok & (prob >= max(float(threshold), 1e-6))
    ok &= (fitted.major >= min_major) & (fitted.major <= max_major)
    idx = np.flatnonzero(ok)
    keep = idx[_dedupe(fitted.x[idx], fitted.y[idx], fitted.minor[idx], prob[idx])]
    rec = np.zeros(len(keep), DET_DTYPE)
    rec["x"], rec["y"] = fitted.x[keep], fitted.y[keep]
    rec["major"], rec["minor"], rec["angle"] = fitted.major[keep], fitted.minor[keep], fitted.angle[keep]
    rec["score"] = prob[keep]
    rec["color"] = COLOR_WHITE if white else COLOR_BLACK
    order = np.lexsort((rec["x"], rec["y"]))
    return rec[order]
