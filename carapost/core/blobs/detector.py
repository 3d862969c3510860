"""Blob detection on one image: candidates, classification, fitting, filters.

The four steps of the guide's "Blob detection algorithm":

1. candidate centres — local maxima of a per-octave DoG on an image pyramid, and
   for black blobs of a narrower DoG on the finest octave (:mod:`.features`);
2. the classifier — probability that the candidate is a blob centre
   (:mod:`.model`); candidates below the threshold are dropped;
3. the boundary and centre — the half-contrast "inside" map of each candidate's
   window and its sub-pixel centre, closed form (:mod:`.centre`);
4. the ellipse — axes and angle from the second moments of that map; stage 2 of
   the classifier scores the result; then the size filter on the longest axis
   and removal of duplicates found on two octaves.

Our additions: the centre from the dot's painted edge (:mod:`.edges`, step 5),
faint thin black dots measured as lines (:mod:`.gauss_kernel`, step 6), elongated
dots placed along their axis by their profile (:mod:`.profile_kernel`, step 7),
black dots' centres taken back from the light's slope (:mod:`.light_kernel`, step 8), and
a learned correction of the centres on textured skin (:mod:`.centre_net`, step 9).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..detections import COLOR_BLACK, COLOR_WHITE, DET_DTYPE
from ..errors import CaraError
from ..heap import keep_freed_memory
from . import features as fe
from .candidate_kernel import LEVEL_SCALE, apart, engulfing, greedy_nms, profile_radius
from .centre import BORDER, MEASURE_NAMES, PASSES, WINDOWS, _constants
from .centre_net import corrected_centres
from .component_kernel import COMPONENT_COLUMNS, threshold_components, unexplained
from .measure_kernel import fit_features, fit_round, next_round
from .edges import TRUST, TRUST_TEXTURED, edge_ellipses, refine_centres
from .gauss_kernel import fit_gaussians
from .light_kernel import pull_back
from .profile_kernel import fit_profiles
from .model import (EDGE_FEATURE_NAMES, FIT_FEATURE_NAMES, ORPHAN_FEATURE_NAMES, STAGE1_GATE, BlobModel,
                    default_model)


@dataclass
class Candidates:
    """Classifier inputs of one image (used by training and diagnostics)."""

    x: np.ndarray          #: full-resolution centre estimates
    y: np.ndarray
    level: np.ndarray      #: pyramid level each came from
    radius: np.ndarray     #: half-contrast radius estimate, full-resolution px
    noise: float           #: image noise estimate, grey levels
    feats: np.ndarray      #: (N, F) features
    #: The "bright blob" image's pyramid, every level down to the coarsest searched (:func:`.features.pyramid`)
    pyramid: dict
    white: bool = False    #: white blobs (searched on the image) or black (on the inverted image)
    thin: np.ndarray | None = None  #: found by the finest level's narrower DoG only (:func:`.features.thin_candidates`)


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
    The C heap is told to keep freed memory first (:func:`~carapost.core.heap.keep_freed_memory`):
    each detection allocates and frees the same ~1 MB images.
    """
    keep_freed_memory()
    bright = img if white else cv2.bitwise_not(img)
    noise = fe.noise_sigma(img)
    levels = fe.levels_for(min_major, max_major)
    # Every level down to the coarsest searched: coarse candidates are measured first one octave finer (_fit_coarse).
    pyr = fe.pyramid(bright, max(levels))
    work = fe.workspace()
    xs_all, ys_all, lv_all, f_all, thin_all = [], [], [], [], []
    b = fe.PATCH_R + 1
    for level in levels:
        lvl = pyr[level]
        if min(lvl.shape) < 2 * b + 3:
            continue
        lnoise = noise / 2.0 ** level
        padded = fe.padded_level(lvl, b, work, level)
        floor = max(0.6, 0.5 * lnoise)
        ys, xs, dog, g, ox, oy = fe.candidates(padded, floor, work, level)
        thin = np.zeros(len(ys), bool)
        if not white and level == levels[0]:
            # Black dots under 1 level px across beside a dark outline (edge-on at the face's silhouette):
            # the narrower DoG's maxima that are not the ordinary ones' (docs/blobs-history.md, "Thin dots beside
            # dark outlines").  White dots are not looked for so: the face's outline is dark, unlike them,
            # and on the white frames of seeds 0-2 the pass found 1 more dot and 47 more false detections.
            ty, tx, tdog, tox, toy = fe.thin_candidates(padded, g, max(floor, fe.THIN_FLOOR * lnoise), work, level)
            new = apart(ty, tx, tox, toy, ys, xs, ox, oy, padded.shape[1], fe.THIN_APART)
            ys, xs, dog = np.concatenate([ys, ty[new]]), np.concatenate([xs, tx[new]]), np.concatenate([dog, tdog[new]])
            ox, oy = np.concatenate([ox, tox[new]]), np.concatenate([oy, toy[new]])
            thin = np.concatenate([thin, np.ones(int(new.sum()), bool)])
        if len(ys) == 0:
            continue
        thin_all.append(thin)
        f = fe.features(padded, g, ys, xs, dog, level, noise)
        # The narrower DoG sees half an octave finer than its level: so the classifier can tell its candidates.
        f[thin, fe.FEATURE_NAMES.index("level")] = (level - 0.5) / LEVEL_SCALE
        f_all.append(f)
        scale = 2.0 ** level
        # Not where cv2.pyrDown centres level pixel u (that is u * 2^L): these candidates sit (2^L - 1)/2 px
        # right of and below their blob.  The fit re-centres them; the classifier and the rescue's limits
        # were trained and tuned with them there, and placing them exactly (the classifier retrained)
        # made tracking worse (docs/blobs-history.md, "Candidates on the pyramid's grid").
        xs_all.append((xs + ox - b + 0.5) * scale - 0.5)
        ys_all.append((ys + oy - b + 0.5) * scale - 0.5)
        lv_all.append(np.full(len(xs), level, np.int8))
    if not f_all:
        z = np.zeros(0)
        return Candidates(z, z, z.astype(np.int8), z, noise, np.zeros((0, len(fe.FEATURE_NAMES)), np.float32), pyr,
                          bool(white), z.astype(bool)), bright
    F = np.concatenate(f_all)
    lv = np.concatenate(lv_all)
    # fe.profile_radius(F) * 2.0 ** lv, compiled (the same float32 and float64 arithmetic).
    radius = np.empty(len(F))
    profile_radius(F, lv, radius)
    return Candidates(np.concatenate(xs_all), np.concatenate(ys_all), lv, radius, noise, F, pyr, bool(white),
                      np.concatenate(thin_all)), bright


#: Rounds of measurement; each re-centres the window on the last answer and sizes it by the last major axis.
ROUNDS = 3
#: The weights' radius for the next round, over the measured semi-major axis (a margin: a taper
#: that cuts the edge measures the blob smaller than it is, and would keep doing so).
GROW = 1.15
#: The measurement's window half-sizes and constants, as the compiled round takes them.
_WINDOWS = np.asarray(WINDOWS, np.int64)
_CONSTANTS = _constants()
#: The next round's weights' radius clip(GROW * major / 2, 1, WINDOWS[-1] - BORDER), as the compiled test
#: of which blobs are measured again takes it (:func:`.measure_kernel.measured_again`).
_AGAIN = np.array([GROW * 0.5, 1.0, WINDOWS[-1] - BORDER])
_LAST = np.zeros(0)


def _measure_round(img, cx, cy, rr, todo, noise, passes, out, ok, extra, last=True):
    """Blobs ``todo`` measured in windows about ``(cx, cy)`` sized by ``rr`` (compiled: window_for, measure_at).

    Windows reaching past the image's edge replicate it (no padded copy of the frame).  Writes
    ``out[0:5]``, ``ok`` and ``extra`` at ``todo``; unless ``last``, ``extra`` is NaN for the blobs
    that another round measures again (or that are not ``ok`` after the first round's merge).
    """
    fit_round(img, cx, cy, rr, todo, float(noise), passes, _WINDOWS, BORDER, _CONSTANTS, out, ok, extra,
              _LAST if last else _AGAIN)


def fit_candidates(bright: np.ndarray, x: np.ndarray, y: np.ndarray, r0: np.ndarray, noise: float):
    """Steps 3-4: centre and ellipse of each candidate; returns full-resolution (x, y, major, minor, angle, ok, extra).

    ``extra`` is ``(N, len(MEASURE_NAMES))`` (:func:`.centre.measure`).  Up to
    :data:`ROUNDS` rounds: the first from the candidate (coarse-octave candidates
    start pixels off), each next one in a window re-centred on the last answer and
    sized by its major axis, for the blobs whose centre or size changed.  A large
    elongated blob is often two candidates (the ends of its major axis): after the
    first round, answers closer than half the larger minor axis are one blob, and
    only the one whose candidate was nearest its answer is measured on (the others
    are not ``ok``); a merged candidate that no kept fit ends within reach of after the
    last round (the one kept went elsewhere, or failed) is measured on its own
    (:func:`_unclaimed`).  Windows reaching past the image's edge replicate it.  A blob's
    stage-2 measurements are taken in its last round only: where the merge made it
    not ``ok`` after they were skipped, its ``extra`` row is NaN.
    """
    n = len(x)
    out = np.zeros((5, n), np.float64)
    ok = np.zeros(n, bool)
    extra = np.zeros((n, len(MEASURE_NAMES)))
    if n == 0:
        return (*out, ok, extra)
    cx, cy, rr = x.astype(np.float64), y.astype(np.float64), np.maximum(r0.astype(np.float64), 1.0)
    todo = np.arange(n)
    img = np.ascontiguousarray(bright)
    merged = np.zeros(0, np.int64)
    for rnd in range(ROUNDS):
        # The stage-2 measurements of a blob measured again are the next round's.
        _measure_round(img, cx, cy, rr, todo, noise, PASSES if rnd == 0 else 2, out, ok, extra, rnd == ROUNDS - 1)
        if rnd == 0:
            # A candidate outside the blob it led to belongs to something else (a neighbour's
            # measurement took it in): it must not win the merge below.
            moved = np.hypot(out[0] - x, out[1] - y)
            ok &= moved <= np.maximum(np.maximum(0.5 * out[2], r0), 2.0)
            good, kept = _keep_nearest(out, ok, moved)
            dropped = np.ones(len(good), bool)
            dropped[kept] = False
            merged = good[dropped]                  # good less the kept, in order (setdiff1d took 0.08 ms)
            first = out[0][merged], out[1][merged], np.maximum(2.0, 0.5 * out[3][merged])
        # The ok ones whose centre moved over half a pixel or whose weights' radius
        # clip(GROW * major / 2, 1, WINDOWS[-1] - BORDER) changed by over a tenth; (cx, cy, rr) updated.
        todo = next_round(todo, ok, out, cx, cy, rr, _AGAIN)
        if len(todo) == 0:
            break
    if len(merged):
        # A merged candidate whose blob no kept fit ended on: the one it was merged into went
        # elsewhere (a coarser candidate's window took in a neighbour) or failed.  Measured on its own.
        alone = _unclaimed(first, out[0][ok], out[1][ok])
        if alone.any():
            again = merged[alone]
            sub = fit_candidates(bright, x[again], y[again], r0[again], noise)
            for k in range(5):
                out[k][again] = sub[k]
            ok[again], extra[again] = sub[5], sub[6]
    return (*out, ok, extra)


#: Candidates of this pyramid level and coarser are measured apart from the finer ones: one round on the level one
#: octave finer than theirs, then one at full resolution about that answer (:func:`_fit_coarse`).  With the finer
#: candidates (:func:`fit_candidates`), a large dot's coarse candidate (a level pixel is 8-16 px) started pixels off
#: with a radius too small, crept towards the dot a few pixels a round and stopped short of it, or was merged into
#: a fit of a fragment of its rim or inside (docs/blobs-history.md, "Session 32").
LEVEL_FIRST = 3
#: Radial-symmetry solves of the full-resolution round after the level's.
LEVEL_FIRST_PASSES = 2
#: ... but a candidate whose radius is under this share of its level's smallest semi-major axis
#: (:func:`.features.level_band`, ``2^level`` px) is a small dot seen by a coarse DoG: it is measured with the finer
#: ones, as before (26 of the 61 coarse candidates of a black benchmark frame; the large-dot frames' detections
#: are the same without this rule).
COARSE_RADIUS = 0.75


def _fit_coarse(pyramid: dict, bright: np.ndarray, x, y, r0, level, noise: float):
    """Centre and ellipse of candidates of the coarse pyramid levels ``level`` (returns what :func:`fit_candidates`
    does).

    One round (:data:`~.centre.PASSES` solves) on the pyramid level one octave finer than each candidate's, where
    a pixel is ``sc = 2^(level-1)`` px and the window holds a quarter of the full-resolution one's pixels.  As in
    :func:`fit_candidates`' first round, an answer farther from its candidate than its semi-major axis (and the
    candidate's radius, and 2 level px) is not ``ok``, nor is one smaller than the sizes its level is for
    (:func:`.features.level_band`), and of answers closer than half the larger minor axis only the one whose
    candidate was nearest it (in level px) is.  Then one round (:data:`LEVEL_FIRST_PASSES` solves) at full
    resolution, in a window about each ``ok`` answer sized by its major axis, whose stage-2 measurements are the
    blob's.
    """
    n = len(x)
    sc = 2.0 ** (level - 1.0)
    out = np.zeros((5, n))
    ok = np.zeros(n, bool)
    extra = np.full((n, len(MEASURE_NAMES)), np.nan)
    # cv2.pyrDown centres level pixel u on full-resolution pixel u * sc.
    lx, ly, lr = x / sc, y / sc, np.maximum(r0 / sc, 1.0)
    for fine in np.unique(level - 1).tolist():
        img = bright if fine == 0 else pyramid[fine]
        at = np.flatnonzero(level - 1 == fine)
        _measure_round(np.ascontiguousarray(img), lx, ly, lr, at, noise / 2.0 ** fine, PASSES, out, ok, extra,
                       last=False)
    moved = np.hypot(out[0] - lx, out[1] - ly)
    ok &= moved <= np.maximum(np.maximum(0.5 * out[2], lr), 2.0)
    out[:4] *= sc
    # Smaller than its level is for (semi-major under features.level_band(level)[0] = 2^level px): a dot a finer
    # level's candidate leads to, which the coarse level's DoG sees too.
    ok &= 0.5 * out[2] >= 2.0 ** level
    _keep_nearest(out, ok, moved)
    todo = np.flatnonzero(ok)
    if len(todo):
        rr = np.clip(GROW * 0.5 * out[2], 1.0, WINDOWS[-1] - BORDER)
        _measure_round(np.ascontiguousarray(bright), out[0].copy(), out[1].copy(), rr, todo, noise, LEVEL_FIRST_PASSES,
                       out, ok, extra)
    return (*out, ok, extra)


def _one_per_blob(cand: Candidates, sel: np.ndarray, prob1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The candidates ``sel`` less those of a blob found on a finer octave (:func:`_suppress`), among the finer
    levels' and among the coarse levels' apart; and which of them are coarse (measured by :func:`_fit_coarse`:
    levels from :data:`LEVEL_FIRST` on, radius from :data:`COARSE_RADIUS` of the level's sizes).

    A large dot's coarse candidate lies inside it, and so do finer ones, off its centre, on fragments of its rim
    or of its inside: the coarse one is measured as well (docs/blobs-history.md, "Session 32").
    """
    lv = cand.level[sel]
    coarse = (lv >= LEVEL_FIRST) & (cand.radius[sel] >= COARSE_RADIUS * 2.0 ** lv)
    keep = [part[_suppress(cand.x[part], cand.y[part], cand.radius[part], prob1[part] - cand.level[part])]
            for part in (sel[~coarse], sel[coarse])]
    out = np.sort(np.concatenate(keep))
    return out, np.isin(out, keep[1])


def _fit_by_level(cand: Candidates, bright: np.ndarray, sel: np.ndarray, coarse: np.ndarray):
    """Steps 3-4 for candidates ``sel``: :func:`fit_candidates` for the finer ones, :func:`_fit_coarse` for those
    ``coarse`` (:func:`_one_per_blob`).  Returns what :func:`fit_candidates` does."""
    lv = cand.level[sel]
    if not coarse.any():
        return fit_candidates(bright, cand.x[sel], cand.y[sel], cand.radius[sel], cand.noise)
    n = len(sel)
    out = np.zeros((5, n))
    ok = np.zeros(n, bool)
    extra = np.zeros((n, len(MEASURE_NAMES)))
    at, s = np.flatnonzero(coarse), sel[coarse]
    parts = [(at, _fit_coarse(cand.pyramid, bright, cand.x[s], cand.y[s], cand.radius[s], lv[at].astype(np.int64),
                              cand.noise))]
    at, s = np.flatnonzero(~coarse), sel[~coarse]
    if len(at):
        parts.append((at, fit_candidates(bright, cand.x[s], cand.y[s], cand.radius[s], cand.noise)))
    for at, res in parts:
        out[:, at] = res[:5]
        ok[at], extra[at] = res[5], res[6]
    return (*out, ok, extra)


def _keep_nearest(out, ok, moved):
    """The first round's merge (in place): of ``ok`` answers closer than half the larger minor axis (one blob's),
    only the one whose candidate was nearest its answer (its window was the best centred) stays ``ok``.

    Returns ``(good, kept)``: the ``ok`` ones before, and which of them stay.
    """
    good = np.flatnonzero(ok)
    kept = _dedupe(out[0][good], out[1][good], out[3][good], -moved[good])
    ok[good] = False
    ok[good[kept]] = True
    return good, kept


def _unclaimed(first, kx, ky) -> np.ndarray:
    """Which of the first-round answers ``first = (x, y, reach)`` have no kept fit ``(kx, ky)`` within reach."""
    fx, fy, reach = first
    if len(kx) == 0:
        return np.ones(len(fx), bool)
    d2 = (fx[:, None] - kx[None]) ** 2 + (fy[:, None] - ky[None]) ** 2
    return d2.min(1) > reach ** 2


def _greedy_nms(x, y, rad, score, use_max: bool, extra: float) -> np.ndarray:
    """Indices kept by greedy suppression: the best score first, dropping the points that clash with a kept one.

    ``i`` and ``j`` clash when closer than ``max(rad_i, rad_j) + extra`` (``use_max``) or
    ``min(rad_i, rad_j) + extra`` (:func:`.candidate_kernel.greedy_nms`).
    """
    order = np.argsort(-np.asarray(score), kind="stable")
    alive = greedy_nms(np.asarray(x, np.float64), np.asarray(y, np.float64), np.asarray(rad, np.float64), order,
                       use_max, float(extra))
    return np.flatnonzero(alive)


def _suppress(x, y, reach, score) -> np.ndarray:
    """Candidates kept when one blob was found on several octaves.

    Two distinct blobs are at least the sum of their radii apart; one blob seen
    on two octaves gives centres much closer than either radius.
    """
    return _greedy_nms(x, y, reach, score, False, 1.0)


def _dedupe(x, y, minor, score) -> np.ndarray:
    """Detections kept when one blob was fitted twice: closer than half the larger minor axis (>= 2 px)."""
    return _greedy_nms(x, y, np.maximum(2.0, 0.5 * minor), score, True, 0.0)


#: A fit is suspected of having been drawn off its candidate's dot when it ended more than DRIFT
#: candidate radii (and 1.5 px) away, or measured more than :data:`GROWN` times the candidate's radius.
DRIFT = 1.0
#: Logit subtracted from the stage-2 score of an ellipse found from its candidate's edge.  On sample
#: frames of seeds 6-8 (not the benchmark's), stage 2 scored 43 such ellipses on markers 0.62-1.0
#: and 34 elsewhere (brow hair, lip creases, the dark outside the face) 0.40-1.0, most under 0.88;
#: 2.4 moves 0.88 to the default threshold 0.4: 38 of the 43 are kept and 6 of the 34.
RESCUE_LOGIT = 2.4
#: A fit that holds its candidate and that stage 2 scores this high is not looked at again: white dots
#: ``RESCUE_ABOVE``, black ``RESCUE_ABOVE_FLAT`` (0.9 for both until session 35: at 0.98 the black held-out frames'
#: centre RMS went 0.0952 -> 0.0907 px and the black 156-marker tracking runs' 0.0709 / 0.0701 -> 0.0667 / 0.0666 mm,
#: for no measurable CPU; white's benchmark frames gained a little, but its tracking runs lost, the 100-marker take's
#: forwards 0.0984 -> 0.1019 mm; docs/blobs-history.md, "Session 35").
RESCUE_ABOVE, RESCUE_ABOVE_FLAT = 0.9, 0.98
#: A grown fit that holds its candidate and has a clean edge of its own is a larger blob the candidate is part
#: of, unless stage 2 scores it under this (the guide's default threshold): then it is the dot measured with a
#: bright or dark region around it, and the candidate's own edge is looked for too (a saturated white nose-tip
#: dot on the nose's specular highlight, measured 19.5 x 13.5 px where it is 11.4 x 10.2; docs/blobs.md,
#: "Session 27").
HELD_BELOW = 0.4
#: A fit whose semi-major axis is this many times its candidate's radius was drawn off its dot (it took in what
#: the dot touches) when its own edge says so (1.5 until session 35: at 1.3 mouth-corner dots that took in a little
#: of the lips beside them are found from their own edge; recall on the four sets of benchmark frames +1 to +3
#: markers, the held-out black frames' centre RMS 0.0907 -> 0.0887 px; docs/blobs-history.md, "Session 35").
GROWN = 1.3


def _rescue_drifted(bright, cand: Candidates, sel, moved, x, y, major, minor, ang, ok, extra,
                    among=None, weak=None) -> np.ndarray:
    """Fits drawn off their candidate's dot are replaced by the dot's own edge ellipse (in place).

    The intensity measurement weighs every pixel of its window, so a small dot
    touching a larger dark region (the shadow under the nose, a brow, the edge
    of the hairline) is measured together with it, or the centre runs off into
    it: the fit lands pixels away from the candidate, or far larger than the
    candidate's radius.  Where that fit's own outline is not a clean ellipse
    and the candidate's is (:func:`.edges.edge_ellipses`), the candidate's
    edge ellipse is the blob; its stage-2 measurements are taken again in a
    window about it (one solve, whose centre is not used).  Only fits in ``among``
    (all by default) are looked at.  A fit in ``weak`` (stage 2 scores it under
    :data:`HELD_BELOW`) is not taken for a larger blob its candidate is part of,
    however clean its own edge.  Returns which fits were replaced and, for those, the edge stage's
    features (:func:`_edge_quality`; NaN for the others).
    """
    r0 = cand.radius[sel]
    grown = 0.5 * major > GROWN * r0
    drift = (moved > np.maximum(DRIFT * r0, 1.5)) | grown
    # Duplicate candidates of a blob already measured (not ok after the first round's merge) stay out.
    drift &= ok | (moved > np.maximum(np.maximum(0.5 * major, r0), 2.0))
    # Only the finest octave's candidates: a dot drawn off is small, and its candidate there sits inside
    # it (on sample frames of seeds 6-8, every rescued ellipse that became a hit came from that octave,
    # and coarser ones were ~40 % of the edge searches).
    if len(sel):
        drift &= cand.level[sel] == cand.level.min()
    if among is not None:
        drift &= among
    idx = np.flatnonzero(drift)
    rescued = np.zeros(len(x), bool)
    quality = np.full((len(x), len(EDGE_FEATURE_NAMES)), np.nan, np.float32)
    if len(idx) == 0:
        return rescued, quality
    sx, sy = cand.x[sel][idx], cand.y[sel][idx]
    # A fit that holds its candidate may be a larger blob the candidate is part of: its own clean
    # edge says so.  One that left its candidate behind says nothing about it.
    held = np.where(moved[idx] <= 0.5 * minor[idx], major[idx], 0.0)
    if weak is not None:
        held[weak[idx]] = 0.0
    # A dot measured with the hair it touches: that side of its own edge is spoilt too (its best arc).
    e = edge_ellipses(bright, sx, sy, r0[idx], (x[idx], y[idx], held, minor[idx], ang[idx]), grown[idx],
                      flat=not cand.white, quality=True)
    good = e[:, 5] > 0
    idx, e = idx[good], e[good]
    if len(idx) == 0:
        return rescued, quality
    m = len(idx)
    # One solve in a window about each edge ellipse (fit_candidates' round; its centre is not used).
    rr = np.clip(GROW * 0.5 * e[:, 2], 1.0, WINDOWS[-1] - BORDER)
    ok_e, extra_e = np.zeros(m, bool), np.zeros((m, len(MEASURE_NAMES)))
    _measure_round(np.ascontiguousarray(bright), np.ascontiguousarray(e[:, 0]), np.ascontiguousarray(e[:, 1]), rr,
                   np.arange(m), cand.noise, 1, np.zeros((5, m)), ok_e, extra_e)
    x[idx], y[idx], major[idx], minor[idx], ang[idx] = e[:, 0], e[:, 1], e[:, 2], e[:, 3], e[:, 4]
    ok[idx] = ok_e
    extra[idx] = extra_e
    rescued[idx] = True
    quality[idx] = _edge_quality(e[:, 6:10], extra_e, cand.noise)
    return rescued, quality


#: A detection whose major axis is this many times another's, with that one's centre within ENGULF_INSIDE of
#: its minor semi-axis, is the other's dot measured together with what it touches.  The white nose tip's blob
#: with the nose's highlight holds the dot at 0.67 of its minor semi-axis; a large dot's rim holds fragments of
#: itself found from level-1 candidates at 0.9-1.1 (6 white and 4 black large dots of the benchmark were dropped
#: for one at 1.0; docs/blobs-history.md, "Session 32").
ENGULF, ENGULF_INSIDE = 2.0, 0.8


def _engulfing(x, y, major, minor) -> np.ndarray:
    """Which detections hold a much smaller detection near their centre (:data:`ENGULF`).

    The duplicate removal keeps one of two detections closer than half the
    larger minor axis by score: right for one blob fitted twice, wrong for a dot
    and a region twice its size that contains it (a white nose tip measured with
    the nose's specular highlight), where the larger's score may be the higher.
    """
    out = np.zeros(len(x), bool)
    # Of every pair closer than half the largest minor axis (swept in x order, compiled).
    engulfing(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
              np.ascontiguousarray(major, np.float64), np.ascontiguousarray(minor, np.float64), float(ENGULF),
              float(ENGULF_INSIDE), out)
    return out


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
    start: tuple = ()     #: the candidates' ``(x, y, radius)`` (full resolution)
    from_edge: np.ndarray | None = None  #: the ellipse is the candidate's own edge (:func:`_rescue_drifted`)
    #: (N, len(EDGE_FEATURE_NAMES)) how that edge looked (:func:`_edge_quality`; NaN for the other fits)
    edge_feats: np.ndarray | None = None
    #: the fit is the orphan search's (:func:`_with_orphans`; scored by :meth:`~.model.BlobModel.orphan_scores`)
    orphan: np.ndarray | None = None


def _fit_features(cand: Candidates, sel, logit1, x, y, major, minor, extra, rescued) -> np.ndarray:
    """Stage 2's inputs (:data:`~.model.FIT_FEATURE_NAMES`) of the fits of candidates ``sel``.

    Compiled (:func:`.measure_kernel.fit_features`): the log of the contrast over the image's
    noise, of the major axis and of the edge's sharpness; the axis ratio; the lines' scatter over
    the radius; the ring's residual over the contrast; the background's slope; the fill; the
    edge's share; how far the fit moved from its candidate, in candidate radii; the depth (the
    contrast over the skin's light: the background on the image for white blobs, 255 less it on
    the inverted image for black ones); the core's uniformity; whether the ellipse came from the
    candidate's own edge.  Each clipped to a sane range.
    """
    F = np.empty((len(sel), len(FIT_FEATURE_NAMES)), np.float32)
    if len(sel):
        fit_features(logit1[sel], cand.x[sel], cand.y[sel], cand.radius[sel], x, y, major, minor,
                     np.ascontiguousarray(extra, np.float64), np.asarray(rescued, bool), float(cand.noise),
                     bool(cand.white), F)
    return F


def fit_stage(cand: Candidates, bright: np.ndarray, model: BlobModel, orphans: bool | None = None) -> Fitted:
    """Stage-1 gate, suppression of duplicates, fitting, and the stage-2 features; then the dots found about
    the candidates no believed fit explains (:func:`_with_orphans`; ``orphans``: :data:`ORPHANS` by default)."""
    logit1 = model.stage1.logit(cand.feats)
    prob1 = 1.0 / (1.0 + np.exp(-np.clip(logit1, -30, 30)))
    sel = np.flatnonzero(prob1 >= STAGE1_GATE)
    # One blob is usually a candidate on two or three octaves: fit it once, from the
    # finest octave's candidate (closest to the centre; coarse ones start pixels off).
    sel, coarse = _one_per_blob(cand, sel, prob1)
    x, y, major, minor, ang, ok, extra = _fit_by_level(cand, bright, sel, coarse)
    moved = np.hypot(x - cand.x[sel], y - cand.y[sel])
    among = weak = None
    if model.stage2 is not None:
        # Fits stage 2 already believes, holding their candidate, are not looked at again (the edge
        # search costs ~50 us a candidate; most drifted candidates are coarse octaves' of a clean blob).
        p0 = model.stage2.predict(_fit_features(cand, sel, logit1, x, y, major, minor, extra, np.zeros(len(sel))))
        above = RESCUE_ABOVE if cand.white else RESCUE_ABOVE_FLAT
        among = ~(ok & (p0 >= above) & (moved <= np.maximum(DRIFT * cand.radius[sel], 1.5)))
        weak = p0 < HELD_BELOW
    rescued, quality = _rescue_drifted(bright, cand, sel, moved, x, y, major, minor, ang, ok, extra, among, weak)
    # The centre may wander to a neighbour: the candidate must stay inside the blob found.
    moved = np.hypot(x - cand.x[sel], y - cand.y[sel])
    ok &= moved <= np.maximum(np.maximum(0.5 * major, cand.radius[sel]), 2.0)
    ok &= minor > 0.5
    h, w = bright.shape
    ok &= (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
    F = _fit_features(cand, sel, logit1, x, y, major, minor, extra, rescued)
    fitted = Fitted(x, y, major, minor, ang, ok, prob1[sel].astype(np.float32), F,
                    (cand.x[sel], cand.y[sel], cand.radius[sel]), rescued, quality)
    if (ORPHANS if orphans is None else orphans) and model.stage2 is not None:
        fitted = _with_orphans(fitted, cand, bright, model, logit1, prob1)
    return fitted


#: Look for dots about the candidates no believed fit explains (:func:`_with_orphans`).
ORPHANS = True
#: ... among the finest octave's candidates of stage-1 probability this or more (under STAGE1_GATE: the dots
#: this finds are mostly ones stage 1 doubts, 0.02-0.3);
ORPHAN_GATE = 0.01
#: ... with no fit stage 2 scores this or more (the default threshold) within max(ORPHAN_NEAR px, their radius),
#: or holding them;
ORPHAN_BELIEVED, ORPHAN_NEAR = 0.4, 1.5
#: ... whose threshold component (:mod:`.component_kernel`: window half-size, threshold step in grey levels, area
#: growth that means it merged) has ORPHAN_MIN_AREA px or more and a semi-major axis of ORPHAN_MAX_A px or less;
ORPHAN_REACH, ORPHAN_STEP, ORPHAN_JUMP = 12, 2, 2.0
ORPHAN_MIN_AREA, ORPHAN_MAX_AREA, ORPHAN_MAX_A = 3, 120, 12.0
#: ... and whose edge, searched from that component's ellipse, is a clean ellipse no wider (full minor axis) than
#: ORPHAN_MAX_MINOR px and no longer than ORPHAN_MAX_MAJOR px: the dots drawn off are thin ones
#: (docs/blobs-history.md, "Session 44").
ORPHAN_MAX_MINOR, ORPHAN_MAX_MAJOR = 3.5, 14.0


def orphan_components(fitted: Fitted, cand: Candidates, bright: np.ndarray, model: BlobModel, prob1):
    """The finest octave's candidates that no believed fit explains, and their threshold components.

    Returns the candidates' indices and their rows of
    :func:`.component_kernel.threshold_components` (:data:`.component_kernel.COMPONENT_COLUMNS`), one
    a region (several candidates of one dot find the same), only regions of plausible size.
    """
    fin = np.flatnonzero((cand.level == cand.level.min()) & (prob1 >= ORPHAN_GATE)) if len(cand.x) else np.zeros(0, int)
    if len(fin) == 0:
        return np.zeros(0, np.int64), np.zeros((0, len(COMPONENT_COLUMNS)))
    believed = np.flatnonzero(fitted.ok)
    believed = believed[model.score(fitted.feats[believed], fitted.from_edge[believed], RESCUE_LOGIT,
                                    fitted.edge_feats[believed]) >= ORPHAN_BELIEVED]
    free = np.zeros(len(fin), bool)
    unexplained(_f64(cand.x[fin]), _f64(cand.y[fin]), _f64(cand.radius[fin]), _f64(fitted.x[believed]),
                _f64(fitted.y[believed]), _f64(0.5 * fitted.major[believed]), _f64(0.5 * fitted.minor[believed]),
                _f64(fitted.angle[believed]), float(ORPHAN_NEAR), free)
    fin = fin[free]
    comp = np.zeros((len(fin), len(COMPONENT_COLUMNS)))
    threshold_components(bright, _f64(cand.x[fin]), _f64(cand.y[fin]), ORPHAN_REACH, ORPHAN_STEP, ORPHAN_JUMP,
                         ORPHAN_MAX_AREA, comp)
    use = (comp[:, 7] > 0) & (comp[:, 2] >= ORPHAN_MIN_AREA) & (comp[:, 3] <= ORPHAN_MAX_A)
    fin, comp = fin[use], comp[use]
    # Several candidates of one dot find the same region (the same centroid to the bit).
    _, first = np.unique(comp[:, 0] * 4096.0 + comp[:, 1], return_index=True)
    first.sort()
    return fin[first], comp[first]


def orphan_features(cand: Candidates, fin, comp, logit1) -> np.ndarray:
    """The orphan gate's inputs (:data:`~.model.ORPHAN_FEATURE_NAMES`) of components ``comp`` of candidates ``fin``."""
    n = len(fin)
    X = np.empty((n, len(ORPHAN_FEATURE_NAMES)), np.float32)
    if n:
        X[:, 0] = np.log(comp[:, 2])
        X[:, 1], X[:, 2] = comp[:, 3], comp[:, 4]
        X[:, 3] = comp[:, 4] / comp[:, 3]
        X[:, 4] = comp[:, 6]
        X[:, 5] = (comp[:, 8] - comp[:, 9]) / cand.noise
        X[:, 6] = comp[:, 8] / 255.0
        X[:, 7] = np.log(max(float(cand.noise), 1e-3))
        X[:, 8] = logit1[fin]
        X[:, 9] = cand.radius[fin]
        X[:, 10] = cand.thin[fin] if cand.thin is not None else 0.0
        X[:, 11:] = cand.feats[fin]
    return X


def orphan_fits(cand: Candidates, bright: np.ndarray, fin, comp, logit1):
    """Step 5's edge about each component's ellipse, and the fits of those that are clean and thin.

    Returns which rows gave a fit, and for those the edge ellipses (:func:`.edges.edge_ellipses`' columns),
    ``ok``, the stage-2 features and the edge stage's features.
    """
    e = edge_ellipses(bright, comp[:, 0], comp[:, 1], comp[:, 3], flat=not cand.white, quality=True,
                      start=(comp[:, 4], np.radians(comp[:, 5])))
    good = (e[:, 5] > 0) & (e[:, 3] <= ORPHAN_MAX_MINOR) & (e[:, 2] <= ORPHAN_MAX_MAJOR)
    fin, e = fin[good], e[good]
    m = len(fin)
    rr = np.clip(GROW * 0.5 * e[:, 2], 1.0, WINDOWS[-1] - BORDER)
    ok, extra = np.zeros(m, bool), np.zeros((m, len(MEASURE_NAMES)))
    if m:
        _measure_round(np.ascontiguousarray(bright), _f64(e[:, 0]), _f64(e[:, 1]), rr, np.arange(m), cand.noise, 1,
                       np.zeros((5, m)), ok, extra)
    h, w = bright.shape
    ok &= (e[:, 3] > 0.5) & (e[:, 0] >= -0.5) & (e[:, 0] <= w - 0.5) & (e[:, 1] >= -0.5) & (e[:, 1] <= h - 0.5)
    F = _fit_features(cand, fin, logit1, e[:, 0], e[:, 1], e[:, 2], e[:, 3], extra, np.ones(m))
    return good, e, ok, F, _edge_quality(e[:, 6:10], extra, cand.noise)


def _with_orphans(fitted: Fitted, cand: Candidates, bright: np.ndarray, model: BlobModel, logit1, prob1) -> Fitted:
    """``fitted`` and the dots found about the candidates no believed fit explains.

    A small dot touching a larger dark region can lose its candidates to stage 1's gate
    (its neighbourhood looks like that region's rim), to a neighbour's in the suppression, or
    to a fit drawn into the region that the from-edge search (:func:`_rescue_drifted`) does not
    set right from the candidate's circle.  About each finest-octave candidate that no fit
    stage 2 believes explains, the region thresholded from the candidate's peak down to just
    before it merges with what it touches (:func:`.component_kernel.threshold_components`) is
    the dot; the orphan gate (:attr:`~.model.BlobModel.orphan`) picks the regions worth a look
    (of ~130 an image, ~1 ends as a detection), and where step 5's rays from a region's ellipse find a
    clean, thin edge, the edge's ellipse is one more fit, found from its edge as the rescued ones are
    (scored by the edge stage, :meth:`~.model.BlobModel.score`).  The suppression of duplicates in
    :func:`detect` keeps one detection a dot.
    """
    fin, comp = orphan_components(fitted, cand, bright, model, prob1)
    if model.orphan is not None and len(fin):
        look = model.orphan.logit(orphan_features(cand, fin, comp, logit1)) >= 0.0
        fin, comp = fin[look], comp[look]
    if len(fin) == 0:
        return fitted
    good, e, ok, F, Q = orphan_fits(cand, bright, fin, comp, logit1)
    fin = fin[good]
    if len(fin) == 0:
        return fitted
    add = lambda a, b: np.concatenate([a, np.asarray(b, a.dtype)])  # noqa: E731
    return Fitted(add(fitted.x, e[:, 0]), add(fitted.y, e[:, 1]), add(fitted.major, e[:, 2]),
                  add(fitted.minor, e[:, 3]), add(fitted.angle, e[:, 4]), add(fitted.ok, ok),
                  add(fitted.prob1, prob1[fin]), add(fitted.feats, F),
                  tuple(add(a, b) for a, b in zip(fitted.start, (cand.x[fin], cand.y[fin], cand.radius[fin]))),
                  add(fitted.from_edge, np.ones(len(fin), bool)), add(fitted.edge_feats, Q),
                  np.concatenate([np.zeros(len(fitted.x), bool), np.ones(len(fin), bool)]))


def _f64(v) -> np.ndarray:
    return np.ascontiguousarray(v, np.float64)


#: A blob whose surround (step 3's ring of background) varies more than this many times the image's noise
#: lies on textured or shaded skin: its edge is trusted sooner than its intensity centre
#: (:data:`.edges.TRUST_TEXTURED`).  Isolated discs on flat backgrounds read 0.7-1.2, face dots 1.1-8 (median
#: 1.7).
TEXTURED = 1.5
#: ... and so is a dot longer than LARGE px (major axis) whose gradient lines miss each other by more than
#: LINES_APART of its semi-major axis (stage 2's ``line_rms``): step 3's window about a large dot weighs a wide
#: patch of skin, whose shading pulls the intensity centre though the ring about it fits its plane.  On the
#: large-dot frames the centre RMS fell 0.1080 -> 0.1013 px (black) and 0.1057 -> 0.0983 (white); isolated discs of
#: radius 4-12 px, whose lines meet within 0.087 of the radius at signal-to-noise 15, keep the full trust, and their
#: centres do not change (docs/blobs-history.md, "Session 36").
LARGE, LINES_APART = 12.0, 0.1


_BORDER, _CNR = FIT_FEATURE_NAMES.index("border_std"), FIT_FEATURE_NAMES.index("log_cnr")
_MAJOR, _LINES = FIT_FEATURE_NAMES.index("log_major"), FIT_FEATURE_NAMES.index("line_rms")


def _edge_quality(q: np.ndarray, extra: np.ndarray, noise: float) -> np.ndarray:
    """The edge stage's own inputs (:data:`~.model.EDGE_FEATURE_NAMES`) from :func:`.edges.edge_ellipses`' quality
    columns ``q`` and the fits' measurements ``extra``: the edge's scatter, the share of rays that found it,
    its median gradient over the noise and over the blob's contrast, its weakest over its median."""
    contrast = np.maximum(extra[:, 0], 1e-3)
    med = np.maximum(q[:, 2], 1e-3)
    return np.column_stack([np.clip(q[:, 0], 0, 5), q[:, 1], np.log(med / max(noise, 0.1)),
                            np.clip(med / contrast, 0, 5), np.clip(q[:, 3] / med, 0, 1)]).astype(np.float32)


def _trust(feats: np.ndarray) -> np.ndarray:
    """Step 5's trust in the first centre (:data:`.edges.TRUST`) of fits with stage-2 features ``feats``."""
    # border_std / contrast times contrast / noise: the ring's residual over the image's noise.
    texture = feats[:, _BORDER].astype(np.float64) * np.exp(feats[:, _CNR].astype(np.float64))
    large = (feats[:, _MAJOR] > np.log(LARGE)) & (feats[:, _LINES] > LINES_APART)
    return np.where((texture > TEXTURED) | large, TRUST_TEXTURED, TRUST)


#: An ellipse found from its candidate's edge moves to step 5's centre (measured along its own normals) when
#: that is at most EDGE_MOVE px away and step 5 run again from there moves it less than EDGE_CONVERGE times as
#: far (docs/blobs-history.md, "Session 19: step 5 on the ellipses found from a candidate's edge").  EDGE_MOVE was
#: 1.0 until session 35: the white saturated nose-tip dot's ellipse sits 1.0-1.3 px off on the nose's highlight (the
#: white benchmark's centre RMS 0.1191 -> 0.1163 px; the white 100-marker tracking take's 0.0983 / 0.0993 -> 0.0968 /
#: 0.0972 mm).
EDGE_MOVE, EDGE_CONVERGE = 1.3, 0.5


def _refine_edge_ellipses(bright, x, y, major, minor, angle, flat: bool):
    """Step 5 for ellipses found from their candidate's edge (:func:`_rescue_drifted`): their new centres.

    The rays from a candidate's circle cut an elongated or off-centre dot's edge obliquely and reach
    its ends only in part; along the found ellipse's own normals the edge is sampled whole.  Such an
    ellipse is itself an edge fit, so the edge is trusted as on textured skin.  A move is taken only
    when short and when a second pass from the new centre confirms it: a move onto the edge of what
    the dot touches (brow hair, a lip band) does not settle there.
    """
    trust = np.full(len(x), TRUST_TEXTURED)
    nx, ny, used = refine_centres(bright, x, y, major, minor, angle, flat=flat, trust=trust)
    move = np.hypot(nx - x, ny - y)
    take = used & (move <= EDGE_MOVE)
    if take.any():
        mx, my, again = refine_centres(bright, nx[take], ny[take], major[take], minor[take], angle[take], flat=flat,
                                       trust=np.zeros(int(take.sum())))
        take[take] = again & (np.hypot(mx - nx[take], my - ny[take]) < EDGE_CONVERGE * move[take])
    return np.where(take, nx, x), np.where(take, ny, y)


#: Faint thin black dots (docs/blobs.md, step 6): a kept detection whose moment ellipse fills under this share of
#: itself (stage 2's ``fill``: the half-contrast map took in a patch of shade) and that is not measured thin
#: already (minor axis at least ``THIN_ROUND`` of its major) is fitted as an elliptical Gaussian on a plane ...
THIN_FILL, THIN_ROUND = 0.5, 0.45
#: ... and takes the Gaussian's centre and ellipse where the Gaussian is a line (its minor standard deviation
#: under ``THIN_SIGMA`` px), the measured minor axis is over ``THIN_ROUNDER`` times the Gaussian's (both as
#: full axes of a uniform ellipse of the same second moments, 4 sigma) and the centre moves under
#: ``THIN_MOVE`` px.
THIN_SIGMA, THIN_ROUNDER, THIN_MOVE = 1.0, 1.65, 3.0
#: The fit's window: half-size 0.6 major + 3 px, at least 7 and at most ``THIN_HALF`` (a faint thin dot is 6-10 px
#: long; a large low-filled blob is no line, and its window would cost as many times more as it has pixels).
THIN_HALF = 12
_FILL = FIT_FEATURE_NAMES.index("fill")


def _thin_lines(bright: np.ndarray, rec: np.ndarray, fill: np.ndarray, min_major: float,
                max_major: float) -> np.ndarray:
    """Measure again, in place, the detections of faint thin dots that step 3 measured round.

    A dot seen edge-on in the shade is a line a few grey levels deep: where the shade
    curves more than step 3's plane follows, the half-contrast map takes in a patch of
    it, and the blob is measured round, several px across and up to 1.4 px off.

    Parameters
    ----------
    bright : ndarray (H, W) uint8
        The search image (blobs bright).
    rec : ndarray of DET_DTYPE
        The detections, changed in place.
    fill : ndarray (len(rec),)
        Their stage-2 ``fill``.
    min_major, max_major : float
        The size filter, applied again to the ellipses measured here.

    Returns
    -------
    ndarray of bool
        The detections to keep (False: a line outside the size filter).
    """
    keep = np.ones(len(rec), bool)
    idx = np.flatnonzero((fill < THIN_FILL) & (rec["minor"] >= THIN_ROUND * rec["major"]))
    if not len(idx):
        return keep
    x, y = rec["x"][idx].astype(np.float64), rec["y"][idx].astype(np.float64)
    half = np.ceil(np.clip(0.6 * rec["major"][idx].astype(np.float64), 4.0, THIN_HALF - 3.0) + 3.0).astype(np.int64)
    out = np.empty((len(idx), 8))
    fit_gaussians(bright, x, y, half, out)
    mxx, myy, mxy = out[:, 2], out[:, 3], out[:, 4]
    mid, rad = 0.5 * (mxx + myy), np.hypot(0.5 * (mxx - myy), mxy)
    small = np.maximum(mid - rad, 0.0)
    take = (out[:, 7] > 0) & (small > 0) & (small < THIN_SIGMA ** 2)
    take &= rec["minor"][idx] > THIN_ROUNDER * 4.0 * np.sqrt(small)
    take &= np.hypot(out[:, 0] - x, out[:, 1] - y) < THIN_MOVE
    t = idx[take]
    major = 4.0 * np.sqrt(mid + rad)[take]
    rec["x"][t], rec["y"][t] = out[take, 0], out[take, 1]
    rec["major"][t], rec["minor"][t] = major, 4.0 * np.sqrt(small[take])
    rec["angle"][t] = 0.5 * np.degrees(np.arctan2(2.0 * mxy, mxx - myy))[take]
    keep[t] = (major >= min_major) & (major <= max_major)
    return keep


#: Elongated dots (docs/blobs.md, step 7): a detection whose minor axis is under ``ALONG_UPTO`` of its major is placed
#: along its major axis by its profile (:mod:`.profile_kernel`), wholly at ``ALONG_FULL`` and under, in between in
#: proportion (a blend of the two centres).
ALONG_FULL, ALONG_UPTO = 0.35, 0.60


def _along_profiles(bright: np.ndarray, rec: np.ndarray) -> None:
    """Move, in place, elongated detections along their major axis to the middle of their profile's segment."""
    ratio = rec["minor"].astype(np.float64) / np.maximum(rec["major"].astype(np.float64), 1e-6)
    idx = np.flatnonzero(ratio < ALONG_UPTO)
    if not len(idx):
        return
    a = rec["angle"][idx].astype(np.float64)
    out = np.empty((len(idx), 6))
    fit_profiles(bright, rec["x"][idx].astype(np.float64), rec["y"][idx].astype(np.float64), a,
                 rec["major"][idx].astype(np.float64), rec["minor"][idx].astype(np.float64), out)
    w = np.clip((ALONG_UPTO - ratio[idx]) / (ALONG_UPTO - ALONG_FULL), 0.0, 1.0)
    shift = np.where(out[:, 5] > 0, w * 0.5 * (out[:, 0] + out[:, 1]), 0.0)
    rad = np.radians(a)
    rec["x"][idx] += shift * np.cos(rad)
    rec["y"][idx] += shift * np.sin(rad)


#: Black dots (docs/blobs.md, step 8): the centre moves by ``-ε s² / 4`` along each axis of the ellipse, ``ε`` the light's
#: relative slope along it (:func:`.light_kernel.light_slopes`) and ``s`` the semi-axis, at most ``LIGHT_UPTO`` px: step 3's
#: centre is pulled towards the light by that much, but a larger dot is placed by its edge (step 5), which the light pulls
#: less: a blurred edge's gradient peak moves ~2 ε σ² (σ the blur; a 6 x 5 px dot blurred 0.8 px under 3 %/px light: 0.042
#: px, 2 ε σ² = 0.038), so the cap's 2.25 ε is that pull for σ ~1 px.  On the black benchmark frames the final centres'
#: pull along the axis was 2.2 ε for semi-axes of 3.5-5 px and 1.4 ε over 5 px, where ε a² / 4 is 4.5 and 12.  A cap of
#: 2.5, 3 or 3.5 px took the centre RMS 0.0834 to 0.0783, 0.0784 and 0.0798 px (held out 0.0881 to 0.0827, 0.0827, 0.0839;
#: clutter frames 0.0823 to 0.0769, 0.0757, 0.0750).
LIGHT_UPTO = 3.0
#: ... and a slope over ``LIGHT_MAX`` a px is taken as that much: steeper than the light falls, it is something beside the
#: dot (the face's outline, a brow) that the plane took in.
LIGHT_MAX = 0.1


def _light_corrected(img: np.ndarray, rec: np.ndarray) -> None:
    """Move, in place, black detections ``rec`` against the light's slope across them (step 8)."""
    x, y = rec["x"].astype(np.float64), rec["y"].astype(np.float64)
    pull_back(img, x, y, rec["major"].astype(np.float64), rec["minor"].astype(np.float64),
              rec["angle"].astype(np.float64), float(LIGHT_UPTO), float(LIGHT_MAX))
    rec["x"], rec["y"] = x, y


#: Step 9 (:mod:`.centre_net`) when :func:`detect` is not told (the Blob Parameter ``blob.learned_centres`` tells
#: it).  The tests of steps 1-8 turn it off to see their own step's centres.
LEARNED_CENTRES = True


def detect(image, white: bool = False, threshold: float = 0.4, min_major: float = 4.0, max_major: float = 50.0,
           model: BlobModel | None = None, learned_centres: bool | None = None) -> np.ndarray:
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
    learned_centres : bool, optional
        Step 9: correct the centres by the model's centre stage (:mod:`.centre_net`), where it has one
        (default :data:`LEARNED_CENTRES`).

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
        # An ellipse from a candidate's own edge is a second guess: stage 2 less RESCUE_LOGIT, or the edge
        # stage's score where that is higher (:meth:`~.model.BlobModel.score`).
        prob = model.score(fitted.feats, fitted.from_edge, RESCUE_LOGIT, fitted.edge_feats)
        if fitted.orphan is not None and fitted.orphan.any():
            prob[fitted.orphan] = model.orphan_scores(fitted.feats[fitted.orphan], fitted.edge_feats[fitted.orphan],
                                                       RESCUE_LOGIT)
    else:
        prob = fitted.prob1
    ok = fitted.ok & (prob >= max(float(threshold), 1e-6))
    ok &= (fitted.major >= min_major) & (fitted.major <= max_major)
    idx = np.flatnonzero(ok)
    idx = idx[~_engulfing(fitted.x[idx], fitted.y[idx], fitted.major[idx], fitted.minor[idx])]
    keep = idx[_dedupe(fitted.x[idx], fitted.y[idx], fitted.minor[idx], prob[idx])]
    rec = np.zeros(len(keep), DET_DTYPE)
    rec["x"], rec["y"] = fitted.x[keep], fitted.y[keep]
    # An ellipse found from its candidate's edge already has the edge's centre.
    again = keep if fitted.from_edge is None else keep[~fitted.from_edge[keep]]
    at = np.searchsorted(keep, again)
    rec["x"][at], rec["y"][at], _ = refine_centres(bright, fitted.x[again], fitted.y[again], fitted.major[again],
                                                   fitted.minor[again], fitted.angle[again],
                                                   tuple(v[again] for v in fitted.start), flat=not white,
                                                   trust=_trust(fitted.feats[again]), along=True)
    if fitted.from_edge is not None and fitted.from_edge[keep].any():
        edge = keep[fitted.from_edge[keep]]
        at = np.searchsorted(keep, edge)
        rec["x"][at], rec["y"][at] = _refine_edge_ellipses(bright, fitted.x[edge], fitted.y[edge], fitted.major[edge],
                                                           fitted.minor[edge], fitted.angle[edge], not white)
    rec["major"], rec["minor"], rec["angle"] = fitted.major[keep], fitted.minor[keep], fitted.angle[keep]
    rec["score"] = prob[keep]
    rec["color"] = COLOR_WHITE if white else COLOR_BLACK
    if not white:
        # White paint is shaded, not flat: on the white benchmark frames this took 7 detections and moved the
        # centre RMS from 0.1385 to 0.1387 px (docs/blobs-history.md, "Session 33").
        rec = rec[_thin_lines(bright, rec, fitted.feats[keep, _FILL], min_major, max_major)]
    _along_profiles(bright, rec)
    if not white and len(rec):
        # White paint takes the light as skin does but its bright core clips and shines: its centres show no such
        # pull (docs/blobs-history.md, "Session 37").
        _light_corrected(img, rec)
    # Step 5 may bring two fits of one dot to its centre (an elongated dot's two ends, each measured as a round
    # blob, both refined from the dot's whole edge): one detection.
    rec = rec[_dedupe(rec["x"], rec["y"], rec["minor"], rec["score"])]
    if learned_centres is None:
        learned_centres = LEARNED_CENTRES
    if learned_centres and model.centre is not None and len(rec):
        rec["x"], rec["y"] = corrected_centres(bright, rec, cand.noise, model.centre)
    order = np.lexsort((rec["x"], rec["y"]))
    return rec[order]
