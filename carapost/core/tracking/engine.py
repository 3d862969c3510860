"""One frame of automatic tracking: the guide's four steps on arrays.

:class:`FrameTracker` holds the state carried from frame to frame (positions,
velocities, last 2D samples and blob sizes, neighbour offsets, cameras) and
:meth:`FrameTracker.step` tracks it into the next frame.  It reads the project
but never changes it; :mod:`.api` turns the per-frame results into a command.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..disc_image import disc_image_offsets
from ..points import SRC_DETECTION, SRC_NONE, SRC_PATCH, ST_NONE, ST_RECONSTRUCTED, ST_SINGLE
from . import elastic, missing_views, patch, reacquire, vote
from .new_points import NewPoints
from .nearest import SortedSweep
from .assign import candidates, mutual_best, size_changed
from .depth_kernel import fuse_points
from .finite import finite_rows
from .geometry import (RigState, depth_uncertainty, held_out_errors, information, refine_poses, reprojection,
                       round_views, triangulate)
from .params import TrackingParams

#: Pass 1 accepts a match when the next candidate is this many times farther (ratio test).
CONFIDENT_RATIO = 2.0
#: Brim observations farther than this (px) from the solved brim are dropped before the final solve.
BRIM_REJECT_PX = 3.0
#: Pose iterations for the brim solve and for the frame's camera refinement.
BRIM_ITERATIONS = 2
BUNDLE_ITERATIONS = 1
#: Frames a point may go on by patch tracking alone, without a blob in any view.
PATCH_ONLY_FRAMES = 5
#: Frames a view may go on by patch tracking since its last blob (the patch's template is that blob).
PATCH_VIEW_FRAMES = PATCH_ONLY_FRAMES
#: A patch view farther than this (px) from the point its blob views triangulate to is dropped...
PATCH_AGREE_PX = 1.5
#: ...and a point with fewer than two blob views loses its patch views when they put it farther
#: than this (mm) from its neighbours' prediction (a patch over a dot turned away finds skin or
#: the next dot at a high score, and two close cameras cannot tell the depth).
PATCH_3D_MM = 2.0
#: A patch track this close (px) to a blob another point holds on the same frame is rejected.
PATCH_ON_BLOB_PX = 3.0
#: A lost point no neighbour predicts may be this many Max Allowed 3D Point Errors from where it was last
#: seen (one per frame since, at most this many).
LAST_SEEN_FRAMES = 4
#: Depth error (mm per px of image error) above which a point's views are too close together to
#: fix its depth (two cameras on one side of the rig, ~10 degrees apart: ~2 mm/px; across: ~0.7).
NARROW_MM_PER_PX = 1.2
#: A point seen by one blob and one patch view is put at its neighbours' predicted depth only where the two
#: views fix its depth this poorly (mm per px, :meth:`FrameTracker._patch_depth`): a patch across the rig
#: gives a depth as good as the prediction (docs/tracking-history.md, "Session 19").
PATCH_DEPTH_MM_PER_PX = NARROW_MM_PER_PX
#: Such a point's depth may lie this far (mm) from its firmly seen neighbours' prediction: farther,
#: and it is brought back to this distance (grazing or half-hidden dots are detected 1-3 px off).
NARROW_DEPTH_MM = 1.0
#: ...unless it lies more than this many times Max Allowed 3D Point Error from it: then one blob is
#: another dot (a bias is a few mm), and the point is left to Remove Bad 3D Points.
NARROW_MISMATCH = 2.0
#: The brim dots' perspective offsets are computed again once a camera has moved this far (mm) or turned this
#: much (radians) since they were (:meth:`FrameTracker._brim_offsets`): they change ~1 % a mm or a degree.
BRIM_OFFSET_MM = 0.5
BRIM_OFFSET_RAD = 0.005
#: How much (mm) the bound on a held point's depth widens for each consecutive frame it has been held.
HELD_GROWTH_MM = 0.25
#: The only wide view of a close pair is dropped by the held-out test, below Max Allowed 2D Projection
#: Error, only where that brings the point this much (mm) nearer the neighbours' prediction.
WIDE_VIEW_MM = 0.5
#: A patch view's weight beside a blob view's in triangulation: the inverse of how many times farther
#: from the marker it lands (blob centres ~0.1-0.15 px RMS on rendered takes, patch tracks ~0.6 px: the
#: template's own blob is often a half-hidden dot's, and the dot's look changes under the patch).
PATCH_WEIGHT = 0.2
#: Held-out view errors above this many robust standard deviations of the frame's are mismatches...
HELD_OUT_SIGMAS = 8.0
#: ...but never below this (px), so that a frame of perfect data does not reject sub-pixel noise.
HELD_OUT_FLOOR_PX = 1.0
#: After the held-out test's first round a view is dropped only where that brings the point nearer its neighbours'
#: prediction, unless its held-out error is over this many times Max Allowed 2D Projection Error: a good wide
#: view held out against a close pair misses by the pair's depth error, about 3 px for each of its pixels, and
#: on the rendered takes such views missed by 5-9 px (the black 35-marker take: dropped at 1 times, its
#: `Eyelid_R_Lower` went 0.23 mm off and the take's RMS 0.033 -> 0.051 mm); a stray blob missed by 11.7.
FAR_HELD_OUT = 2.0
#: A two-blob point's view this many times farther from the projection of the neighbours' prediction
#: than its other view (and beyond Max Allowed 2D Projection Error) is another blob (`_far_pair_view`).
FAR_PAIR_RATIO = CONFIDENT_RATIO
#: It is dropped where the pair misses (both views beyond HELD_OUT_FLOOR_PX), or where it meets more than
#: this (mm) from the neighbours' prediction.
FAR_PAIR_MEET_MM = 2.0
#: A pass-1 anchor of two views farther than this (mm) from its neighbours' prediction (from the other
#: anchors), and than this plus its last motion from its own constant-velocity prediction, is not an
#: anchor (`_doubtful_pairs`).
ANCHOR_PAIR_MM = 2.0
#: Where no neighbour predicts a point, its own constant-velocity prediction decides which view the
#: held-out test drops, if the point moved at most this much (mm) on the previous frame: faster, as in
#: a jaw's turn, that prediction is millimetres off itself.
MOTION_JUDGE_MM = 1.0
#: A close pair's point whose depth lies more than this (mm) from its firm neighbours' prediction does
#: not vote in the prediction of points that have no firm neighbours (`_steady_depth`).
OFF_DEPTH_VOTE_MM = 2.0


def _median(a: np.ndarray) -> float:
    """``np.median`` of a 1-D array (NaN if it holds one), by a plain sort: ~3 us where numpy takes ~20."""
    v = np.sort(a)
    n = len(v)
    if n == 0 or np.isnan(v[-1]):
        return float("nan")
    return float(v[n // 2]) if n % 2 else float((v[n // 2 - 1] + v[n // 2]) / 2)


def held_out_limit(errors: np.ndarray, max_error: float) -> float:
    """The limit on a held-out view's error (px) on one frame.

    A stray blob within Max Allowed 2D Projection Error of a hidden marker's
    projection bends a 3-view point by millimetres while adding only a pixel or
    two of residual; the frame's own held-out errors (mostly good views) tell how
    far a good view lands, so a view far outside that spread is rejected even
    below the user's limit, which stays the upper bound.

    Parameters
    ----------
    errors : ndarray
        Held-out reprojection errors (px) of the worst view of each 3+-view point.
    max_error : float
        Max Allowed 2D Projection Error.
    """
    if len(errors) < 8:
        return float(max_error)
    sigma = 1.4826 * _median(errors)
    return float(min(max_error, max(HELD_OUT_FLOOR_PX, HELD_OUT_SIGMAS * sigma)))


#: How a blob's expected centre error grows as the classifier's score falls short of 1: by this many times
#: its error at a score of 0.999 for each decade of ``1 - score`` above 0.001 (rendered takes, black and
#: white: 0.08-0.12 px RMS at 0.999 and above, 0.16-0.21 at 0.995-0.999, 0.21-0.26 at 0.98-0.995,
#: 0.3-0.45 at 0.8-0.98: a low score is a dot seen at a grazing angle, half hidden or beside a shadow).
SCORE_ERROR_SLOPE = 1.8


def blob_weight(prob: np.ndarray) -> np.ndarray:
    """Triangulation weight of blob views of classifier score ``prob``: 1 at 0.999 and above (NaN: 1)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        decades = np.clip(3.0 + np.log10(np.clip(1.0 - prob, 1e-6, 1.0)), 0.0, 3.0)
    return np.where(np.isfinite(decades), 1.0 / (1.0 + SCORE_ERROR_SLOPE * decades), 1.0)


#: An oblique dot's centre is less sure along its major axis: blob views' equation along it is weighted
#: ``1 / (1 + ELONG_SLOPE max(0, ELONG_FROM - minor/major)^2)`` times the one across (docs/tracking.md).
ELONG_FROM = 0.7
ELONG_SLOPE = 8.0


def elongation(rec: np.ndarray) -> np.ndarray:
    """``(cos, sin, k)`` of detections ``rec`` (records, or their fields by name): their major axis' direction
    and its weight (:data:`ELONG_SLOPE`)."""
    ratio = rec["minor"].astype(float) / np.maximum(rec["major"].astype(float), 1e-6)
    a = np.radians(rec["angle"].astype(float))
    k = 1.0 / (1.0 + ELONG_SLOPE * np.maximum(ELONG_FROM - ratio, 0.0) ** 2)
    return np.column_stack([np.cos(a), np.sin(a), k])


#: A return from a loss on two views stands only if the next frame still sees it on a blob in both of its
#: cameras (docs/tracking-history.md, "Session 21").
RETURN_FOLLOWED = True


#: A return from a loss on one blob (a single-sensor sample of a point lost on the frame before) stands only if
#: the next frame measures the point too: on the white 35-marker process take of seed 2 a lower lip lost with the
#: jaw open came back for one frame, twice, on a highlight of the teeth 3.9 mm off (docs/tracking-history.md,
#: "Session 30").
SINGLE_RETURN_FOLLOWED = True


#: A lost point comes back on two or more blob views: the patches of a point that has one are left out
#: (their templates are from before the loss; docs/tracking-history.md, "Session 20").
RETURN_ON_BLOBS = True


def confidence(src: np.ndarray, prob: np.ndarray | None = None, blob: np.ndarray | None = None) -> np.ndarray:
    """Triangulation weight of each view of ``src`` (N, S): :func:`blob_weight` of its detection's
    score ``prob`` (N, S) for a blob (1 without), ``PATCH_WEIGHT`` for a patch.  ``blob``: those blob
    weights already worked out (``prob`` is then not used)."""
    if blob is None:
        blob = 1.0 if prob is None else blob_weight(prob)
    return np.where(src == SRC_PATCH, PATCH_WEIGHT, blob)


def on_ray(rig: RigState, uv_c: np.ndarray, views: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points on the ray of each row's one view in ``views`` (n, S), nearest ``pred`` (n, 3).

    Returns the points (n, 3) and their distances along the rays from the camera centres (n,).
    """
    s = np.argmax(views, axis=1)
    o, d = rig.rays(s, uv_c[np.arange(len(s)), s])
    t = np.einsum("ni,ni->n", pred - o, d)
    return o + t[:, None] * d, t


@dataclass
class FrameResult:
    """What tracking found on one frame (rows: face points, then brim markers)."""

    frame: int
    R: np.ndarray            #: (S, 3, 3) camera rotations
    C: np.ndarray            #: (S, 3) camera centres
    X: np.ndarray            #: (N, 3) face positions (NaN lost)
    status: np.ndarray       #: (N,) ST_*
    residual: np.ndarray     #: (N,) RMS px
    src: np.ndarray          #: (N, S) SRC_*
    det: np.ndarray          #: (N, S)
    uv: np.ndarray           #: (N, S, 2) raw px
    score: np.ndarray        #: (N, S)
    brim_det: np.ndarray     #: (B, S)
    brim_uv: np.ndarray      #: (B, S, 2) raw px
    brim_score: np.ndarray   #: (B, S)
    brim_err: np.ndarray     #: (B, S) px
    #: (N,) points whose sample on the frame before this one was a return from a loss on two views that this
    #: frame did not confirm (:attr:`FrameTracker.tentative`), or on one blob that this frame did not measure
    #: (:data:`SINGLE_RETURN_FOLLOWED`): the caller takes that sample back.
    retract: np.ndarray | None = None
    #: Rows at the end that are new points (markers no point followed), made on this frame.
    new: int = 0
    #: Per sensor, the dots Search Missing Views found and appended to the frame's detections (``det`` counts
    #: them after the frame's own records), or None.
    found: list | None = None

    def take_back(self, rows: np.ndarray) -> None:
        """Clear the face samples of ``rows`` (N,) bool on this frame (a return that was not confirmed)."""
        self.X[rows] = np.nan
        self.status[rows] = ST_NONE
        self.residual[rows] = np.nan
        self.src[rows] = SRC_NONE
        self.det[rows] = -1
        self.uv[rows] = np.nan
        self.score[rows] = np.nan


#: The detection fields the tracker reads.
_FIELDS = ("x", "y", "major", "minor", "score", "angle")


class FrameData:
    """One frame's detections in corrected pixels, indexed globally over sensors.

    All sensors share one index: sensor ``s`` sits at x + ``s * SENSOR_GAP``
    so that one query serves every camera (4 queries cost 4 times the Python overhead).
    The index is a :class:`.nearest.SortedSweep`, which answers as a ``cKDTree`` of the
    same points would, bit for bit, at a fraction of its cost at this size.
    """

    SENSOR_GAP = 1.0e6

    def __init__(self, rig: RigState, recs: list[np.ndarray]):
        counts = [len(r) for r in recs]
        self.offsets = np.cumsum([0] + counts)
        G = int(self.offsets[-1])
        self.sensor = np.repeat(np.arange(len(recs)), counts)
        self.local = np.arange(G) - self.offsets[self.sensor]
        # Field by field: concatenating the records themselves costs several times more.
        field = {n: np.concatenate([r[n] for r in recs]) if recs else np.zeros(0) for n in _FIELDS}
        self.raw_all = np.column_stack([field["x"], field["y"]]).astype(float)
        self.size_all = np.column_stack([field["major"], field["minor"]]).astype(float)
        self.prob_all = field["score"].astype(float)
        self.el_all = elongation(field)
        self.xy_all = rig.correct_all(self.sensor, self.raw_all)
        cut = self.offsets
        # Each sensor's rows of the arrays above (views, not copies).
        self.raw = [self.raw_all[cut[s]:cut[s + 1]] for s in range(len(recs))]
        self.xy = [self.xy_all[cut[s]:cut[s + 1]] for s in range(len(recs))]
        self.free = np.ones(G, bool)
        self._tree = None

    def tree(self):
        if self._tree is None and self.offsets[-1]:
            shifted = self.xy_all.copy()
            shifted[:, 0] += self.sensor * self.SENSOR_GAP
            self._tree = SortedSweep(shifted)
        return self._tree

    def attached(self, det: np.ndarray, mask: np.ndarray | None = None):
        """Rows, sensors and global detection indices of the views of ``det`` (N, S) in ``mask`` (default
        ``det >= 0``): one gather over all sensors instead of one per sensor."""
        r, s = np.nonzero(det >= 0 if mask is None else mask)
        return r, s, self.offsets[s] + det[r, s]

    def shift(self, uv: np.ndarray, sensors: np.ndarray) -> np.ndarray:
        """Predicted corrected pixels moved into their sensor's slot of the shared tree."""
        out = uv.copy()
        out[:, 0] += sensors * self.SENSOR_GAP
        return out


#: Image error (px) of a blob centre of top score (weight 1 in :func:`confidence`), and error (mm) of the
#: neighbours' prediction per mm of a point's mean distance to its nearest neighbours: the weights
#: :func:`fuse_depth` gives the two.  Chosen on the rendered takes (session 13; docs/tracking.md): the
#: blobs of score 0.999 and above land 0.08-0.12 px from their dots; a smaller DEPTH_PX (a weaker pull
#: towards the prediction) left more of the close pairs' depth error, a larger one let the prediction,
#: whose offsets are refreshed from the averaged points, hold the points too firmly (156-marker black take:
#: 0.2 px gave 0.15 mm RMS where 0.08 px gives 0.095 mm).
DEPTH_PX = 0.08
PRED_MM_PER_MM = 0.025
#: A measurement farther than this many standard deviations (per axis) from the prediction is not averaged
#: with it: a wrong or biased blob, for the clamp and Remove Bad 3D Points to judge.
FUSE_GATE = 3.0
#: The neighbours' prediction of a point averaged on the frame before is as certain as that average was, plus
#: this fraction of ``PRED_MM_PER_MM`` x spacing for a frame's change (never less certain than that product
#: alone, nor more than the neighbours' spread allows): the average becomes a filter over frames
#: (docs/tracking-history.md, "Session 22: the prediction's certainty carried from frame to frame").  0: off.
CARRIED_Q = 0.6
#: The neighbours' votes that a frame's measured points are averaged with are turned by their neighbourhood's
#: rotation since their offsets were refreshed (:func:`.elastic.turned_offsets`; docs/tracking-history.md,
#: "Session 25").
TURNED_VOTES = True


def fuse_depth(X: np.ndarray, info: np.ndarray, pred: np.ndarray, pred_sd, rows: np.ndarray,
               post: np.ndarray | None = None) -> np.ndarray:
    """``X`` with each of ``rows`` averaged with the neighbours' prediction, each weighted by its certainty.

    The measured point is certain to ``info / DEPTH_PX²`` (:func:`.geometry.information`):
    across the rays, to a fraction of a millimetre; along them, for two close cameras,
    to millimetres.  The prediction is certain to ``pred_sd`` mm in every direction.  The
    weighted mean moves a point mostly along its poorly seen depth and hardly across
    it.  Where the two disagree by more than :data:`FUSE_GATE` standard deviations the
    point is left as measured.

    Parameters
    ----------
    X, pred : ndarray (N, 3)
    info : ndarray (N, 3, 3)
        Information of each point's views per px² of image error.
    pred_sd : float or ndarray (N,)
        Standard deviation (mm) of each prediction.
    rows : ndarray (N,) bool
        Points to average (measured, by two or more views).
    post : ndarray (N,), optional
        Filled with each average's variance (mm², inf where a point is left as measured).
    """
    out = np.empty_like(X)
    var = np.ascontiguousarray(np.broadcast_to(np.asarray(pred_sd, float) ** 2, (len(X),)))
    if post is None:
        post = np.empty(len(X))
    fuse_points(np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(info, dtype=float),
                np.ascontiguousarray(pred, dtype=float), var, np.ascontiguousarray(rows), 1.0 / DEPTH_PX ** 2,
                3.0 * FUSE_GATE ** 2, out, post)
    return out


class FrameTracker(NewPoints):
    """Tracks a set of face points (and the brim) from frame to frame.

    Parameters
    ----------
    rig : RigState
        Cameras of the start frame.
    X0 : ndarray (N, 3)
        Face points on the start frame.
    uv0 : ndarray (N, S, 2)
        Their raw 2D samples on the start frame (NaN none).
    size0 : ndarray (N, S, 2)
        Blob (major, minor) of those samples (NaN unknown).
    brim : ndarray (B, 3)
        Brim markers (world = brim frame); may be empty.
    params : TrackingParams
    images : callable, optional
        ``images(sensor, frame) -> (H, W) uint8`` for patch matching; None disables it.
    pool : PatchPool, optional
    start_frame : int, optional
        The frame of ``uv0``: its blob samples (``size0`` known) are the first patch templates.
    learned_centres : bool
        Whether the dots Search Missing Views finds get the detector's step 9 (Blob Parameters > Learned Centre
        Correction), as the frame's own detections did.
    """

    def __init__(self, rig: RigState, X0, uv0, size0, brim, params: TrackingParams, images=None, pool=None,
                 start_frame: int | None = None, brim_radius=None, learned_centres: bool = True):
        self.rig = rig
        self.p = params
        self.learned_centres = learned_centres       # Search Missing Views' dots: the Blob Parameter's step 9
        self.images = images
        self.pool = pool or patch.PatchPool(1)
        self.S = rig.S
        self.X = np.array(X0, float)
        self.N = len(self.X)
        self.V = np.full_like(self.X, np.nan)            # velocity per frame
        self.uv_prev = np.array(uv0, float)              # raw px of the previous frame's samples
        self.size = np.array(size0, float)
        self.brim = np.asarray(brim, float).reshape(-1, 3)
        # The brim dots' radii (mm): their images' perspective offsets come off the detections (:meth:`_solve_brim`).
        r = np.zeros(len(self.brim)) if brim_radius is None else np.asarray(brim_radius, float).ravel()
        self.brim_radius = r if np.any(r > 0) else None
        self._boff = None                                # (R, C, offsets) of :meth:`_brim_offsets`
        self.prev_frame = None
        self.nb = elastic.neighbours(self.X, mutual=elastic.MUTUAL)
        self.off = np.full(self.nb.shape + (3,), np.nan)
        self.motion = np.zeros(self.nb.shape + (2,))     # how each neighbour offset has changed
        self.w = elastic.weights(self.motion)
        meas = finite_rows(self.X)
        elastic.update_offsets(self.off, self.nb, self.X, meas)
        self.X_last = self.X.copy()
        self.unseen = np.where(meas, 0, LAST_SEEN_FRAMES)  # frames since each point last had a position
        self.held = np.zeros(self.N, np.int64)           # consecutive frames each point's depth was held
        self.patch_run = np.zeros(self.N, int)           # frames in a row without a blob in any view
        # Points back from a loss on two views on the last frame: kept only if this frame finds them too.
        self.tentative = np.zeros(self.N, bool)
        self.tentative_views = np.zeros((self.N, self.S), bool)   # ... and the cameras they came back in
        self.single_return = np.zeros(self.N, bool)      # points back from a loss on one blob on the last frame
        self._blob_w = np.ones((self.N, self.S))           # this frame's blob views' weights (:func:`blob_weight`)
        self._el = round_views((self.N, self.S))            # and their elongation (:func:`elongation`)
        # How far each prediction can be off: its neighbours' distance scales the face's deformation between them.
        self.pred_sd = self._prediction_sd(elastic.spacing(self.X))
        # The variance (mm²) of each point's average with its prediction on the last frame (inf: none; see
        # CARRIED_Q), and this frame's (:meth:`_steady_depth`), until the frame's end decides who carries it on.
        self.post_var = np.full(self.N, np.inf)
        self._post_new = np.full(self.N, np.inf)
        # Each view's last blob sample (frame, raw px): patches are matched against the marker's
        # look there, not against the previous frame's patch, so that they cannot drift step by step.
        blob0 = finite_rows(self.size) & finite_rows(self.uv_prev)
        self.blob_frame = np.where(blob0 & (start_frame is not None), -1 if start_frame is None else start_frame, -1)
        self.blob_uv = np.where(blob0[..., None], self.uv_prev, np.nan)
        self.seen = blob0.copy()                         # views that had a blob on some frame (Search Missing Views)
        self._img_cache: OrderedDict = OrderedDict()
        # Matches for markers no point follows found on the last frame (:meth:`_add_new_markers`).
        self._pending = None

    # ------------------------------------------------------------------ helpers
    def _image(self, s, f):
        key = (s, f)
        if key in self._img_cache:
            self._img_cache.move_to_end(key)
        else:
            if len(self._img_cache) >= 6 * self.S:
                self._img_cache.popitem(last=False)
            self._img_cache[key] = self.images(s, f)
        return self._img_cache[key]

    def _solve_brim(self, fd: FrameData):
        """Match the brim with the Brim Point Tracking Distance and solve the cameras from it."""
        B, S = len(self.brim), self.S
        det = np.full((B, S), -1)
        uv_c = np.full((B, S, 2), np.nan)
        if B == 0:
            return self.rig.copy(), det, uv_c, np.full((B, S), np.nan)
        pred = self.rig.project(self.brim)
        rows, sens = np.nonzero(finite_rows(pred))
        r = np.full(len(rows), float(self.p.brim_point_tracking_distance))
        idx, dist = candidates(fd.tree(), fd.free, fd.shift(pred[rows, sens], sens), r, k=2)
        ok = (idx[:, 0] >= 0) & (dist[:, 1] >= CONFIDENT_RATIO * dist[:, 0])
        j = np.flatnonzero(ok)
        acc = mutual_best(rows[j] * S + sens[j], idx[j, 0], dist[j, 0], B * S, int(fd.offsets[-1]))
        j = j[acc]
        g = idx[j, 0]
        det[rows[j], sens[j]] = fd.local[g]
        r, s, g = fd.attached(det)
        uv_c[r, s] = fd.xy_all[g]
        if self.brim_radius is not None and len(r):
            uv_c[r, s] -= self._brim_offsets()[r, s]
        valid = det >= 0
        rig = refine_poses(self.rig, self.brim, uv_c, valid, iterations=BRIM_ITERATIONS)
        err = reprojection(rig, self.brim, uv_c, valid)
        bad = valid & (err > BRIM_REJECT_PX)
        if np.any(bad):
            det[bad] = -1
            uv_c[bad] = np.nan
            valid &= ~bad
            rig = refine_poses(rig, self.brim, uv_c, valid, iterations=BRIM_ITERATIONS)
            err = reprojection(rig, self.brim, uv_c, valid)
        fd.free[fd.attached(det, valid)[2]] = False
        return rig, det, uv_c, err

    def _brim_offsets(self) -> np.ndarray:
        """The brim dots' perspective offsets (B, S, 2) under the previous frame's cameras.

        A dot's image is centred off its centre's projection; the offset under the previous frame's
        cameras is this frame's to well within the detections' noise, and it changes by about 1 % for a
        millimetre or a degree of camera motion: computed again (0.9 ms) only once a camera has moved
        :data:`BRIM_OFFSET_MM` or :data:`BRIM_OFFSET_RAD` since.
        """
        rig = self.rig
        if self._boff is not None:
            R0, C0, off = self._boff
            turned = np.arccos(np.clip((np.einsum("sij,sij->s", R0, rig.R) - 1.0) / 2.0, -1.0, 1.0))
            if np.all(np.linalg.norm(rig.C - C0, axis=1) <= BRIM_OFFSET_MM) and np.all(turned <= BRIM_OFFSET_RAD):
                return off
        off = disc_image_offsets(rig.project, self.brim, self.brim_radius)
        self._boff = (rig.R.copy(), rig.C.copy(), off)
        return off

    def _search(self, fd, rig, Xpred, radius, slots, taken, k=3, nudge=None, uv=None, found=None):
        """Candidates of ``slots`` (N, S) bool: pair arrays (point, sensor, local det, distance), nearest first.

        ``taken`` (G,) bool marks detections already attached this frame; ``nudge`` (N, S, 2) moves the
        projections of ``Xpred`` (:mod:`.vote`); ``uv``: those projections, when already known.
        ``found``: a dict shared by searches of one frame with the same ``radius``, ``slots``, ``taken``
        and ``k``; each leaves its queries there, and a later one searches again only those it moved.
        """
        if uv is None:
            uv = rig.project(Xpred)
        if nudge is not None:
            uv = uv + nudge
        rows, sens = np.nonzero(slots & finite_rows(uv))
        e = np.zeros(0, int)
        if len(rows) == 0:
            return e, e, e, np.zeros(0), uv
        q = fd.shift(uv[rows, sens], sens)
        known = None
        if found and np.array_equal(found["slots"], rows * self.S + sens):
            known = found["queries"]
        idx, dist = candidates(fd.tree(), fd.free & ~taken, q, radius[rows], k=k, known=known)
        if found is not None:
            found["slots"], found["queries"] = rows * self.S + sens, (q, idx, dist)
        has = idx >= 0
        if np.any(has):
            # Blob Size Difference Threshold: a blob whose width or height changed too much is not the marker.
            drop = size_changed(self.size[rows, sens], fd.size_all, idx, self.p.blob_size_difference_threshold)
            if np.any(drop):
                dist = np.where(drop, np.inf, dist)
                order = np.argsort(dist, axis=1, kind="stable")
                dist = np.take_along_axis(dist, order, 1)
                idx = np.take_along_axis(np.where(drop, -1, idx), order, 1)
        P = np.repeat(rows, k)
        Ss = np.repeat(sens, k)
        D = idx.ravel()
        Dist = dist.ravel()
        keep = D >= 0
        return P[keep], Ss[keep], fd.local[np.maximum(D[keep], 0)], Dist[keep], uv

    # --------------------------------------------------------------------- step
    def step(self, frame: int, recs: list[np.ndarray]) -> FrameResult:
        """Track into ``frame`` whose detections per sensor are ``recs``."""
        p, S, N = self.p, self.S, self.N
        fd = FrameData(self.rig, recs)
        offsets = fd.offsets
        # 1. Cameras from the brim (the previous frame's cameras when the brim is not seen).
        rig, bdet, buv_c, berr = self._solve_brim(fd)
        # 2. Predict: constant velocity for points tracked on the previous frame,
        #    elastic prediction from the neighbours' predictions for lost points.
        tracked = finite_rows(self.X)
        Xp = np.where(np.isfinite(self.V), self.X + self.V, self.X)
        speed = np.linalg.norm(np.where(np.isnan(self.V), 0.0, self.V), axis=1)    # mm on the previous frame
        lost = ~tracked
        if np.any(lost):
            el = self._predict(Xp, tracked, lost)
            Xp[lost] = np.where(np.isfinite(el), el, self.X_last[lost])
        det = np.full((N, S), -1)
        src = np.zeros((N, S), np.uint8)
        uv_c = np.full((N, S, 2), np.nan)
        uv_raw = np.full((N, S, 2), np.nan)
        score = np.full((N, S), np.nan)
        taken = np.zeros(int(offsets[-1]), bool)
        # 3. Pass 1: unambiguous matches within the Face Point Tracking Distance.
        radius = np.full(N, float(p.face_point_tracking_distance))
        have = finite_rows(Xp)
        # Only views that go on from the previous frame: a view coming back (the marker was hidden in
        # that camera) waits for pass 2, so that it cannot take, by a nearer prediction, the blob of a
        # neighbour the camera kept seeing (a jaw dot turning out of view projects onto the next one).
        slots = have[:, None] & finite_rows(self.uv_prev)
        found = {}
        Pi, Si, Di, Dd, uv1 = self._search(fd, rig, Xp, radius, slots, taken, k=2, found=found)
        fj, d1, second = self._first_two(Pi, Si, Dd)
        # A region that changed speed at once (a jaw jerk) moves its predictions together first:
        # the views whose nearest blob is off their prediction, with another in reach, go to the vote.
        ask = np.zeros((N, S), bool)
        ask[Pi[fj], Si[fj]] = (d1 > vote.ASK_PX) & np.isfinite(second)
        if np.any(ask):
            nudge = vote.nudges(uv1, slots, ask, fd, float(p.face_point_tracking_distance), self.nb, self.w)
            if np.any(nudge):
                Pi, Si, Di, Dd, _ = self._search(fd, rig, Xp, radius, slots, taken, k=2, nudge=nudge, uv=uv1,
                                                   found=found)
                fj, d1, second = self._first_two(Pi, Si, Dd)
        if len(Pi):
            key = Pi * S + Si
            conf = second >= CONFIDENT_RATIO * d1
            fi = fj[conf]
            gid = offsets[Si[fi]] + Di[fi]
            acc = mutual_best(key[fi], gid, Dd[fi], N * S, int(offsets[-1]))
            fi = fi[acc]
            det[Pi[fi], Si[fi]] = Di[fi]
            score[Pi[fi], Si[fi]] = 1.0 - Dd[fi] / radius[Pi[fi]]
        # Anchors: points whose confident matches agree in 3D.
        valid = det >= 0
        r, s, g = fd.attached(det)
        uv_c[r, s] = fd.xy_all[g]
        Xa = triangulate(rig, uv_c, valid)
        err = reprojection(rig, Xa, uv_c, valid)
        anchor = (valid.sum(1) >= 2) & ~np.any(err > p.max_allowed_2d_projection_error, axis=1)     # NaN: no view
        doubtful, el = self._doubtful_pairs(Xa, anchor, valid, Xp, speed)
        anchor &= ~doubtful
        # Everything else starts again in pass 2 with better predictions.
        det[~anchor] = -1
        score[~anchor] = np.nan
        uv_c[~anchor] = np.nan
        taken[fd.attached(det)[2]] = True
        # 4. Pass 2: elastic prediction from the anchors (``el``), within the Max Elastic Prediction Distance.
        X2 = np.where(anchor[:, None], Xa, np.where(np.isfinite(el), el, Xp))
        # 4a. Search Missing Views: points that fewer than two cameras detect near this prediction, looked for
        # again in the images (:mod:`.missing_views`).  After the anchors, not before: at a jaw's jerk their
        # elastic prediction is where the dots are, a point's own motion is not.
        extra = None
        if p.search_missing_views and self.images is not None:
            extra = missing_views.look_again(rig, lambda s: self._image(s, frame), X2, recs, fd.xy, self.seen,
                                             self.learned_centres)
            if extra is not None:
                # Appended after each sensor's own records: the brim's and the anchors' matches keep their indices.
                recs = missing_views.appended(recs, extra)
                fd = FrameData(self.rig, recs)
                fd.free[fd.attached(bdet)[2]] = False
                offsets = fd.offsets
                taken = np.zeros(int(offsets[-1]), bool)
                taken[fd.attached(det)[2]] = True
        use_el = anchor | finite_rows(el)
        r2 = np.where(use_el, float(p.face_point_max_elastic_prediction_distance),
                      float(p.face_point_tracking_distance))
        # An anchored point's projection is known to a pixel: its further views must fit it as
        # closely as any view must (Max Allowed 2D Projection Error), which keeps stray blobs off.
        r2 = np.where(anchor, np.minimum(r2, float(p.max_allowed_2d_projection_error)), r2)
        slots = (det < 0) & finite_rows(X2)[:, None]
        Pi, Si, Di, Dd, uv2 = self._search(fd, rig, X2, r2, slots, taken, k=3)
        cost = Dd / r2[Pi]
        ncc = np.full(len(Pi), np.nan)
        if self.images is not None and self.prev_frame is not None and len(Pi):
            key = Pi * S + Si
            cnt = np.bincount(key, minlength=N * S)
            prev = self.uv_prev[Pi, Si]
            # Appearance only where position alone is ambiguous (cost of patches).
            need = np.flatnonzero((cnt[key] > 1) & finite_rows(prev))
            if len(need):
                jobs = [(self._image(int(Si[j]), self.prev_frame), prev[j], self._image(int(Si[j]), frame),
                         fd.raw[int(Si[j])][Di[j]], int(p.patch_match_size)) for j in need]
                ncc[need] = self.pool.map(patch.compare, jobs)
                bad = need[ncc[need] < p.patch_match_threshold]
                cost[bad] = np.inf
                cost[need] += 0.5 * (1.0 - np.clip(ncc[need], -1, 1))
        ok = np.isfinite(cost)
        Pi, Si, Di, Dd, cost, ncc = Pi[ok], Si[ok], Di[ok], Dd[ok], cost[ok], ncc[ok]
        if len(Pi):
            acc = mutual_best(Pi * S + Si, offsets[Si] + Di, cost, N * S, int(offsets[-1]))
            Pi, Si, Di, Dd, ncc = Pi[acc], Si[acc], Di[acc], Dd[acc], ncc[acc]
            det[Pi, Si] = Di
            score[Pi, Si] = np.where(np.isfinite(ncc), ncc, 1.0 - Dd / r2[Pi])
        # 4b. Lost points whose marker is back but far from the prediction: detections whose rays meet.
        reacquired = np.zeros(N, bool)
        if np.any(lost):
            limit = held_out_limit(err[anchor][valid[anchor]], p.max_allowed_2d_projection_error)
            reacquired = self._reacquire(fd, rig, X2, lost & ((det >= 0).sum(1) < 2), det, taken, limit)
        valid = det >= 0
        src[valid] = SRC_DETECTION
        r, s, g = fd.attached(det)
        uv_c[r, s] = fd.xy_all[g]
        uv_raw[r, s] = fd.raw_all[g]
        # Worked out once: the triangulations ask for them several times a frame (_view_weights).
        self._blob_w = np.ones((N, S))
        self._blob_w[r, s] = blob_weight(fd.prob_all[g])
        self._el = round_views((N, S))
        self._el[r, s] = fd.el_all[g]
        # 5. Patch tracking where no blob matched.
        if self.images is not None and self.prev_frame is not None:
            # A lost point comes back on blobs: its patches' templates are from before the loss and lag a
            # marker that moved meanwhile.  With one blob it is put on that blob's ray (single-sensor tracking).
            returning = lost & (valid.sum(1) < 2) if RETURN_ON_BLOBS else np.zeros(N, bool)
            self._patch_track(frame, fd, rig, X2, r2, uv2, valid | returning[:, None], src, uv_c, uv_raw, score, det)
        # Patches bridge short blob dropouts (blur, a lash over the dot); a point with no blob in any
        # view for longer is no longer seen (a chin turned away): its patches drift over bare skin.
        no_blob = ~np.any(src == SRC_DETECTION, axis=1)
        self.patch_run = np.where(no_blob, self.patch_run + 1, 0)
        stale = no_blob & (self.patch_run > PATCH_ONLY_FRAMES)
        if np.any(stale):
            src[stale] = SRC_NONE
            uv_c[stale] = np.nan
            uv_raw[stale] = np.nan
        valid = src != SRC_NONE
        # 6. Triangulate, remove bad 2D projections, refine the cameras (brim fixed), triangulate again.
        # Where the neighbours cannot predict a point (most of them lost, as on a grazing chin), its own
        # motion is the check: a point tracked on the previous frame does not jump millimetres.
        motion = np.where(tracked[:, None], Xp, np.nan)
        # So too for which view the held-out test drops, where the point moved slowly: a close pair with one
        # biased blob makes a good wide view look the worst, and nothing else tells them apart.
        judge = np.where(np.isfinite(el), el, np.where((speed <= MOTION_JUDGE_MM)[:, None], motion, np.nan))
        X, err = self._triangulate_clean(rig, uv_c, valid, src, det, judge)
        self._far_pair_view(rig, X, err, uv_c, src, np.where(np.isfinite(el), el, motion))
        self._check_patches(rig, X, err, uv_c, src, motion)
        valid = src != SRC_NONE
        multi = valid.sum(1) >= 2
        if np.count_nonzero(multi) >= 3:
            Xall = np.concatenate([self.brim, X[multi]])
            uvall = np.concatenate([buv_c, uv_c[multi]])
            vall = np.concatenate([bdet >= 0, valid[multi]])
            rig = refine_poses(rig, Xall, uvall, vall, iterations=BUNDLE_ITERATIONS)
            X = triangulate(rig, uv_c, valid, *self._view_weights(src))
        # 7. Remove bad 3D points: inconsistent with the neighbours' prediction.
        measured = finite_rows(X)
        X, pred, clamped = self._steady_depth(rig, X, valid, measured, self._view_weights(src)[0])
        measured &= finite_rows(X)
        X = self._patch_depth(rig, X, uv_c, src, measured, motion)
        if p.remove_bad_3d_points and np.any(measured):
            # Three or more agreeing blob views outweigh a prediction: a jaw speeding up from 3.6 to 9 mm a
            # frame put four views of a lower-lip dot 0.02 mm from the truth and 5.1 mm from the prediction.
            back = reacquired | (lost & (valid.sum(1) >= 3)) | ((src == SRC_DETECTION).sum(1) >= 3)
            # (Two views of a wide pair meet whatever the blobs when one lies near the other's epipolar
            # line: a chin dot's view took the next chin dot's blob, 20 px away, and passed 20 mm off.)
            pred = np.where(np.isfinite(pred), pred, motion)
            # A point back after a loss that no neighbour can predict (most of a grazing chin lost) is
            # held to where it was last seen, within the limit per frame since: a chin dot's patch slid
            # onto the next dot's place, met a wide pair's blob and put it 21 mm off, unchecked.
            alone = lost & ~finite_rows(pred)
            pred[alone] = Xp[alone]
            reach = np.where(alone, np.minimum(self.unseen + 1, LAST_SEEN_FRAMES), 1)
            X, measured = self._remove_bad_3d(rig, X, uv_c, valid, src, det, measured, back, pred, reach)
            valid = src != SRC_NONE
        # 8. Single-sensor tracking of points seen by one sensor only.
        status = np.where(measured, ST_RECONSTRUCTED, ST_NONE).astype(np.uint8)
        one = ~measured & (valid.sum(1) == 1)
        if np.any(one):
            Xs = self._single_sensor(rig, X, measured, uv_c, valid, one) if p.allow_single_sensor_tracking \
                else np.full((N, 3), np.nan)
            okk = one & finite_rows(Xs)
            X[okk] = Xs[okk]
            status[okk] = ST_SINGLE
            drop = one & ~okk
            src[drop] = SRC_NONE
        # A return from a loss on two views is the weakest evidence there is: a wide pair meets wherever one
        # blob lies near the other's epipolar line, and a lower lip lost with the jaw open came back on two
        # stray blobs 10 px off its dot, 3.5 mm off.  Such a return stands once the next frame measures the
        # point again from two blob views (one view on the ray near the return confirms nothing, and nor do
        # patches: their templates are the return's own blobs, so they follow whatever it took).  Until
        # then its offsets are not refreshed from it; a return taken back leaves no patch templates, and a
        # point that only such patches see is not measured on this frame either.
        blobs = (src == SRC_DETECTION).sum(1)
        retract = self.tentative & ((status != ST_RECONSTRUCTED) | (blobs < 2))
        if RETURN_FOLLOWED:
            # Confirmed by other cameras is not enough: each camera the return was seen in must still see the
            # point on a blob (a lower lip came back on its own blob and, in another camera, on the blob of the
            # dot beside it, 3.1 mm off; the next frame measured it from three other blobs).
            retract |= self.tentative & np.any(self.tentative_views & (src != SRC_DETECTION), axis=1)
        status[retract & (blobs == 0)] = ST_NONE
        if SINGLE_RETURN_FOLLOWED:
            retract |= self.single_return & (status == ST_NONE)
        self.blob_frame[retract] = -1
        nothing = status == ST_NONE
        src[nothing] = SRC_NONE
        valid = src != SRC_NONE
        det[src != SRC_DETECTION] = -1
        uv_raw[~valid] = np.nan
        uv_c[~valid] = np.nan
        score[~valid] = np.nan
        err = reprojection(rig, X, uv_c, valid)
        nv = valid.sum(1)
        residual = np.sqrt(np.where(valid, err, 0.0) ** 2 @ np.ones(S) / np.maximum(nv, 1))
        residual = np.where(nv > 0, residual, np.nan)
        X[nothing] = np.nan
        tentative = lost & (status == ST_RECONSTRUCTED) & (valid.sum(1) == 2)
        self.tentative_views = tentative[:, None] & (src == SRC_DETECTION)
        # 9. Carry the state to the next frame.
        have = ~nothing
        self.V = np.where(have[:, None] & tracked[:, None], X - self.X, np.nan)
        self.X = X.copy()
        self.X_last[have] = X[have]
        self.unseen = np.where(have, 0, self.unseen + 1)
        self.held = np.where(clamped, self.held + 1, np.where(status == ST_RECONSTRUCTED, 0, self.held))
        # A clamped depth is the prediction's, not a measurement: refreshing the offsets with it would
        # let a biased pair walk the point away by the clamp distance every frame.
        elastic.update_offsets(self.off, self.nb, X, (status == ST_RECONSTRUCTED) & ~clamped & ~tentative,
                               self.motion)
        self.tentative = tentative
        self.single_return = lost & (status == ST_SINGLE)
        # Carried on only by points measured on both frames, not clamped and not a tentative return.
        self.post_var = np.where((status == ST_RECONSTRUCTED) & ~clamped & ~tentative & tracked, self._post_new,
                                 np.inf)
        self.w = elastic.weights(self.motion)
        self.uv_prev = uv_raw.copy()
        blob = src == SRC_DETECTION
        self.blob_frame[blob] = frame
        self.blob_uv[blob] = uv_raw[blob]
        self.seen |= blob
        r, s, g = fd.attached(det, blob)
        self.size[r, s] = fd.size_all[g]
        self.rig = rig
        self.prev_frame = frame
        buv_raw = np.full(buv_c.shape, np.nan)
        bscore = np.full(bdet.shape, np.nan)
        r, s, g = fd.attached(bdet)
        buv_raw[r, s] = fd.raw_all[g]
        bscore[r, s] = 1.0
        berr = reprojection(rig, self.brim, buv_c, bdet >= 0)
        res = FrameResult(frame, rig.R.copy(), rig.C.copy(), X, status, residual, src, det, uv_raw, score,
                          bdet, buv_raw, bscore, berr, retract if np.any(retract) else None, found=extra)
        # 10. Points for markers no point follows (rows added after the frame's own: they carry no state yet).
        if p.add_points_for_new_markers:
            known = np.where(have[:, None], X, np.where(finite_rows(Xp)[:, None], Xp, self.X_last))
            self._add_new_markers(frame, fd, rig, res, known)
        return res

    # --------------------------------------------------------------- sub-steps
    @staticmethod
    def _prediction_sd(spacing):
        """How far (mm) a point's neighbours' prediction can be off, from its spacing (:data:`PRED_MM_PER_MM`)."""
        return PRED_MM_PER_MM * spacing

    def _view_weights(self, src, rows=slice(None)):
        """This frame's triangulation weights of the views ``src[rows]``: (:func:`confidence`, elongation)."""
        return confidence(src[rows], blob=self._blob_w[rows]), self._el[rows]

    def _doubtful_pairs(self, Xa, anchor, valid, own, speed):
        """Pass-1 anchors of two views that neither their neighbours nor their own motion put there.

        Returns the (N,) mask of those pairs and the elastic prediction (N, 3) of every point from the
        anchors left (``anchor`` less the mask), which pass 2 searches from.

        Two views meet wherever one blob lies near the other's epipolar line: a chin dot undetected in one
        camera took a blob 5.4 px from it there, and the pair met 4.6 mm off.  As an anchor it then
        predicts its neighbours (the next chin dot's prediction went 3.8 mm off, and it lost its one good
        wide view to the held-out test).  A two-view anchor farther than ``ANCHOR_PAIR_MM`` from the other
        anchors' elastic prediction and than ``ANCHOR_PAIR_MM`` plus its last frame's motion from its own
        constant-velocity prediction (``own``; ``speed``, each point's motion on the previous frame, mm)
        waits for pass 2 instead.  Three or more agreeing views stay anchors whatever the predictions say
        (a jaw jerk moves them all).
        """
        bad = np.zeros(self.N, bool)
        pair = anchor & (valid.sum(1) == 2)
        firm = anchor.copy()
        el, _ = elastic.predict(Xa, firm, self.nb, self.off, weight=self.w)
        if not np.any(pair):
            return bad, el
        # A constant-velocity prediction is off by about the change of velocity: more, the faster the point.
        far_own = ~(np.linalg.norm(Xa - own, axis=1) <= ANCHOR_PAIR_MM + speed)     # NaN (no motion): far
        for _ in range(2):      # once more without the pairs found: one may have swayed another's prediction
            new = pair & firm & far_own & (np.linalg.norm(Xa - el, axis=1) > ANCHOR_PAIR_MM)
            if not np.any(new):
                break
            bad |= new
            firm &= ~new
            el, _ = elastic.predict(Xa, firm, self.nb, self.off, weight=self.w)
        return bad, el

    def _first_two(self, Pi, Si, Dd):
        """Of :meth:`_search`'s rows (k=2): each slot's first row, its distance and the second's (inf none)."""
        if len(Pi) == 0:
            return np.zeros(0, int), np.zeros(0), np.zeros(0)
        key = Pi * self.S + Si
        # Rows come in (slot, nearest first) order: a slot's second candidate follows its first.
        first = np.r_[True, key[1:] != key[:-1]]
        fj = np.flatnonzero(first)
        has2 = (fj + 1 < len(key)) & ~np.r_[first[1:], True][fj]
        second = np.where(has2, Dd[np.minimum(fj + 1, len(key) - 1)], np.inf)
        return fj, Dd[fj], second

    def _predict(self, X, available, rows):
        """Elastic prediction of ``rows`` only (``X``, ``available``: every point)."""
        return elastic.predict(X, available, self.nb[rows], self.off[rows], weight=self.w[rows],
                               rigid=self.unseen[rows] > 0)[0]      # offsets from before a loss

    def _patch_track(self, frame, fd, rig, X2, r2, uv2, skip, src, uv_c, uv_raw, score, det):
        """Patch views (in place) for the recently blob-seen views not in ``skip`` (N, S)."""
        p = self.p
        recent = (self.blob_frame >= 0) & (np.abs(frame - self.blob_frame) <= PATCH_VIEW_FRAMES)
        rows, sens = np.nonzero(~skip & recent & finite_rows(uv2))
        if len(rows) == 0:
            return
        jobs, keep = [], []
        for i, s in zip(rows.tolist(), sens.tolist()):
            pred_raw = rig.cameras[s].distort(uv2[i, s])
            w, h = rig.cameras[s].sensor_size
            if not (np.all(np.isfinite(pred_raw)) and 0 <= pred_raw[0] < w and 0 <= pred_raw[1] < h):
                continue
            jobs.append((self._image(s, int(self.blob_frame[i, s])), self.blob_uv[i, s], self._image(s, frame), pred_raw,
                         float(r2[i]), int(p.patch_match_size)))
            keep.append((i, s))
        # Another point's blob: every dot looks alike, so a patch that slid onto a dot another point
        # holds this frame (an upper lid closing over the lower lid's marker) is that marker, not this one.
        # (A merged blob nobody holds is where patches are meant to work: the guide's remedy.)
        held = [fd.raw[s][det[det[:, s] >= 0, s]] for s in range(self.S)]
        for (i, s), (xy, sc) in zip(keep, self.pool.map(patch.track_patch, jobs)):
            if len(held[s]) and np.min(np.hypot(*(held[s] - xy).T)) < PATCH_ON_BLOB_PX:
                continue
            if sc >= p.patch_match_threshold:
                src[i, s] = SRC_PATCH
                uv_raw[i, s] = xy
                uv_c[i, s] = rig.cameras[s].correct(xy)
                score[i, s] = sc

    def _reacquire(self, fd, rig, Xpred, rows, det, taken, limit):
        """Attach to lost points (``rows``) the free detections of 3+ cameras whose rays agree near their prediction.

        Searches the Face Point Tracking Distance around the prediction; fills
        ``det`` in place and returns the (N,) mask of points picked up.
        """
        N, S = self.N, self.S
        out = np.zeros(N, bool)
        rows = rows & finite_rows(Xpred)
        if not np.any(rows):
            return out
        used = taken.copy()
        used[fd.attached(det)[2]] = True
        radius = np.full(N, float(self.p.face_point_tracking_distance))
        slots = np.repeat(rows[:, None], S, axis=1)
        Pi, Si, Di, _, _ = self._search(fd, rig, Xpred, radius, slots, used, k=6)
        for i in np.unique(Pi).tolist():
            m = Pi == i
            keep = ~used[fd.offsets[Si[m]] + Di[m]]
            ss, dd = Si[m][keep], Di[m][keep]
            found = reacquire.best_views(rig, [fd.xy[s][dd[ss == s]] for s in range(S)], limit)
            if found is None:
                continue
            choice = found[0]
            det[i] = -1
            for s in np.flatnonzero(choice >= 0).tolist():
                d = int(dd[ss == s][choice[s]])
                det[i, s] = d
                used[fd.offsets[s] + d] = True
            out[i] = True
        return out

    def _triangulate_clean(self, rig, uv_c, valid, src, det, pred):
        """Triangulate; with Remove Bad 2D Projections drop the worst view above the limit until all fit.

        ``pred`` (N, 3): the neighbours' prediction (NaN none), which decides between views above the
        held-out limit.  The held-out test runs again on a point that still has 3+ views after losing
        one, as long as each further drop brings it nearer that prediction.
        """
        X = triangulate(rig, uv_c, valid, *self._view_weights(src))
        err = reprojection(rig, X, uv_c, valid)
        if not self.p.remove_bad_2d_projections:
            return X, err
        for _ in range(self.S):
            e = np.where(valid, err, -1.0)
            worst = np.argmax(e, axis=1)
            bad = np.flatnonzero(e[np.arange(len(e)), worst] > self.p.max_allowed_2d_projection_error)
            if len(bad) == 0:
                break
            s = worst[bad]
            valid[bad, s] = False
            src[bad, s] = SRC_NONE
            uv_c[bad, s] = np.nan
            X[bad] = triangulate(rig, uv_c[bad], valid[bad], *self._view_weights(src, bad))
            err[bad] = reprojection(rig, X[bad], uv_c[bad], valid[bad])
        # A wrong view of a 3+-view point shares its error with the others; held out, it shows in full.
        rows = np.flatnonzero(valid.sum(1) >= 3)
        limit, again = None, False
        while len(rows):
            # Hold out each view in turn: the wrong one is the view the others agree least with
            # (not the one with the largest residual, which a wrong view may push onto a good one).
            # Unweighted: a patch's word on which view is wrong counts as a blob's (a weak patch beside a
            # close pair would leave the pair to judge a good third blob by its poor depth).
            held, Xs = held_out_errors(rig, uv_c[rows], valid[rows], X[rows])
            worst = most = np.argmax(held, axis=1)
            e = held[np.arange(len(rows)), most]
            if limit is None:
                limit = held_out_limit(e, self.p.max_allowed_2d_projection_error)
            # Two close cameras left alone fix the depth badly (mm per pixel of a biased detection), so
            # the good third view can look the worst; of the views above the limit, drop the one whose
            # removal leaves the point nearest the neighbours' prediction.
            near = np.linalg.norm(Xs - pred[rows][:, None, :], axis=2)
            near = np.where((held > limit) & np.isfinite(near), near, np.inf)
            judged = np.isfinite(near).any(1)
            worst = np.where(judged, np.argmin(near, axis=1), worst)
            # Not a blob where a patch above the limit can go and leave the other views agreeing: a patch
            # follows its template over a marker gone from view, and its error shows in the good views' too.
            first = self._patch_first(rig, uv_c[rows], valid[rows], src[rows], held, limit,
                                      src[rows, worst] == SRC_DETECTION)
            judged &= first < 0
            worst = np.where(first >= 0, first, worst)
            bad = e > limit
            if not again and np.any(bad):
                # The only wide view of a close pair shows the pair's depth error in its held-out error
                # (~3 px of it per pixel of the pair's): within Max Allowed 2D Projection Error it is
                # dropped only where that brings the point clearly nearer the neighbours' prediction.
                # (Jaw_L_11, 156-marker take: a good grazing view 3.9 px held out, limit 1.1 px; dropped,
                # the pair put the point 4.0 mm off, kept 0.6 mm; the prediction, 2.3 mm off, was 1.7 mm
                # from both.)
                r = np.flatnonzero(bad)
                left = valid[rows[r]].copy()
                left[np.arange(len(r)), worst[r]] = False
                _, mm = depth_uncertainty(rig, Xs[r, worst[r]], left)
                here = np.linalg.norm(X[rows[r]] - pred[rows[r]], axis=1)
                keep = ((mm > NARROW_MM_PER_PX) & (e[r] <= self.p.max_allowed_2d_projection_error) & np.isfinite(here)
                        & ~(near[r, worst[r]] < here - WIDE_VIEW_MM))
                bad[r[keep]] = False
            if again:
                # Another round only where it brings the point nearer its neighbours: two close cameras
                # left alone agree with each other at any depth, and a good pair must not lose its mate --
                # unless the view held out worst misses the others' point by more than FAR_HELD_OUT times Max
                # Allowed 2D Projection Error: then it is no view of this marker, whatever the prediction says,
                # and it goes (the white 35-marker take of seed 2, frame 69, the jaw opening 4 mm a frame: a
                # stray blob 10 px from Lip_Lower_L in camera 0, 11.7 px held out, stayed beside a good blob and
                # patch because the neighbours' prediction, 2.4 mm off, was as far from either answer; the
                # point went 4.6 mm off).
                nearer = near[np.arange(len(rows)), worst] < np.linalg.norm(X[rows] - pred[rows], axis=1)
                far = e > FAR_HELD_OUT * self.p.max_allowed_2d_projection_error
                worst = np.where(far, most, worst)
                bad &= (judged & nearer) | far
            if not np.any(bad):
                break
            b, s = rows[bad], worst[bad]
            valid[b, s] = False
            src[b, s] = SRC_NONE
            uv_c[b, s] = np.nan
            X[b] = triangulate(rig, uv_c[b], valid[b], *self._view_weights(src, b))
            err[b] = reprojection(rig, X[b], uv_c[b], valid[b])
            # A point may hold two wrong views (a drifting patch and another marker's blob): the views
            # left are judged again, against the same limit (the frame's spread of good views).
            rows = b[valid[b].sum(1) >= 3]
            again = True
        return X, err

    def _patch_first(self, rig, uv_c, valid, src, held, limit, ask) -> np.ndarray:
        """For each point where ``ask`` (the held-out test would drop a blob), the patch view to drop instead
        (-1: none).

        That is the patch of largest held-out error above ``limit`` where the other views, three or more,
        all agree within ``limit`` without it.  A grazing chin dot of the 156-marker black take (Chin_R_11,
        frame 77 forwards), hidden in cameras 0 and 2: their patches 0.8 and 4 px off made the good blob of
        camera 3 the worst view held out (4.7 px, the 4 px patch 4.1), and a neighbours' prediction 2.4 mm
        off lay nearest the point without it: the point passed 3.1 mm off.  Where the others do not agree
        (a false blob 9 px off beside a patch 1 px off: the white 35-marker take's Lip_Lower_L with the jaw
        open), the usual choice stands.  (With four cameras it acts in the held-out loop's first round only: a
        later round has three views.)
        """
        out = np.full(len(held), -1)
        cand = np.where((held > limit) & (src == SRC_PATCH), held, -np.inf)
        k = np.argmax(cand, axis=1)
        rows = np.flatnonzero(ask & np.isfinite(cand[np.arange(len(held)), k]) & (valid.sum(1) >= 4))
        if len(rows) == 0:
            return out
        left = valid[rows].copy()
        left[np.arange(len(rows)), k[rows]] = False
        h, _ = held_out_errors(rig, uv_c[rows], left)
        agree = np.all(~left | (h <= limit), axis=1)
        out[rows[agree]] = k[rows[agree]]
        return out

    def _far_pair_view(self, rig, X, err, uv_c, src, pred):
        """Drop the far view of a two-blob point whose views disagree and one lies far from the prediction.

        Two views always triangulate, and Remove Bad 2D Projections cannot tell which of two is
        wrong: each takes half the error.  A white lower lip coming back with the jaw open
        (``carapost sample --white``, 35 markers, seed 1, frames 107 forwards and 93 backwards)
        took, in one camera, a false detection beside the teeth 8-11 px from its dot, with one
        good view of the other side: its prediction projected 2.5-4.7 px from the good blob and
        9-13 px from the false one, the pair missed by 3-4 px per view, and the point passed
        3.6-5.4 mm off, within Max Allowed 3D Point Error of the prediction.  So where the pair
        does not meet (both views above ``HELD_OUT_FLOOR_PX``) and one view lies beyond Max
        Allowed 2D Projection Error from the prediction's projection and ``FAR_PAIR_RATIO`` times
        farther than the other view (at least ``HELD_OUT_FLOOR_PX``), that view goes; the point is
        left to single-sensor tracking on the near one.  (A good pair whose prediction is off
        along one camera's ray lies far in the other camera too, but its views meet.)  On the
        black and white rendered takes, all 16 such views before this rule were 5.6-27 px from their
        marker.  Where no neighbour predicts the point, ``pred`` is its own motion (constant velocity
        from the previous frame): a chin dot of the 156-marker take (frame 100 forwards) whose chin
        neighbours were all lost took, in one camera, the next dot's blob 9.7 px away with one good
        view; the pair missed by 4.3 px per view and passed 5 mm off.  A pair that meets is judged
        so too where it stands more than ``FAR_PAIR_MEET_MM`` from ``pred``: the white 100-marker
        take's Chin_R_6 (frame 129 forwards), its dot undetected in camera 3, took a blob 5.4 px away
        there that lay along the epipolar line of its good view, and passed 3.3 mm off.  Part of
        Remove Bad 2D Projections (off: nothing is dropped).  Updates ``X``, ``err``, ``uv_c`` and
        ``src`` in place.
        """
        if not self.p.remove_bad_2d_projections:
            return
        valid = src != SRC_NONE
        rows = np.flatnonzero((valid.sum(1) == 2) & ((src == SRC_DETECTION).sum(1) == 2)
                              & finite_rows(pred) & finite_rows(X))
        if len(rows) == 0:
            return
        v = valid[rows]
        d = np.where(v, np.linalg.norm(rig.project(pred[rows]) - uv_c[rows], axis=2), np.nan)
        far = np.nanargmax(np.nan_to_num(d, nan=-1.0), axis=1)
        near_d = np.nanmin(d, axis=1)
        far_d = d[np.arange(len(rows)), far]
        e = np.nanmin(np.where(v, err[rows], np.nan), axis=1)
        off = np.linalg.norm(X[rows] - pred[rows], axis=1)
        meets_far = (FAR_PAIR_MEET_MM > 0) & (off > FAR_PAIR_MEET_MM)
        bad = (((e > HELD_OUT_FLOOR_PX) | meets_far) & (far_d > float(self.p.max_allowed_2d_projection_error))
               & (far_d >= FAR_PAIR_RATIO * np.maximum(near_d, HELD_OUT_FLOOR_PX)))
        if not np.any(bad):
            return
        b, s = rows[bad], far[bad]
        src[b, s] = SRC_NONE
        uv_c[b, s] = np.nan
        X[b] = np.nan
        err[b] = np.nan

    def _check_patches(self, rig, X, err, uv_c, src, motion=None):
        """Drop patch views that disagree with the point's blob views or, lacking two, its neighbours.

        Patches are the weaker evidence: blob views decide where the point is, and
        a patch may only add to it.  ``motion`` (N, 3): the points' constant-velocity
        prediction (NaN for points not tracked on the previous frame; None: none), the
        check where the neighbours cannot predict; with neither, a point's patch views go.
        Updates ``X``, ``err``, ``uv_c`` and ``src`` in place.
        """
        patch = src == SRC_PATCH
        rows = np.flatnonzero(patch.any(1))
        if len(rows) == 0:
            return
        blob = src[rows] == SRC_DETECTION
        drop = np.zeros((len(rows), self.S), bool)
        two = blob.sum(1) >= 2
        if np.any(two):
            r = rows[two]
            Xb = triangulate(rig, uv_c[r], blob[two])
            e = reprojection(rig, Xb, uv_c[r], patch[r])
            drop[two] = patch[r] & (np.nan_to_num(e, nan=np.inf) > PATCH_AGREE_PX)
        measured = finite_rows(X)
        few = ~two & measured[rows]
        if np.any(few):
            r = rows[few]
            ref = self._predict(X, measured & ~patch.any(1), r)
            if motion is not None:
                ref = np.where(np.isfinite(ref), ref, motion[r])
            dev = np.linalg.norm(X[r] - ref, axis=1)
            # Patches with nothing to check them against (neither neighbours nor the point's own motion)
            # are not evidence enough: two patches over skin near a turned-away chin dot meet anywhere
            # along their rays, and one patch beside one blob is as free (a chin patch slid 20 px onto
            # the next dot, which lay near the blob's epipolar line).
            unchecked = np.isnan(dev)
            drop[few] = patch[r] & ((np.nan_to_num(dev, nan=0.0) > PATCH_3D_MM) | unchecked)[:, None]
        if not np.any(drop):
            return
        b, s = np.nonzero(drop)
        b = rows[b]
        src[b, s] = SRC_NONE
        uv_c[b, s] = np.nan
        r = np.unique(b)
        v = src[r] != SRC_NONE
        X[r] = triangulate(rig, uv_c[r], v, *self._view_weights(src, r))
        err[r] = reprojection(rig, X[r], uv_c[r], v)

    def _patch_depth(self, rig, X, uv_c, src, measured, motion):
        """Points seen by one blob and one patch view of a close pair: on the blob's ray, at the predicted depth.

        A patch track lands ~0.6 px from its marker (five times a blob's error: its template is
        often a half-hidden dot's last blob, and the dot's look changes under it), and beside one
        blob its error along the epipolar line is all the depth the point has: 0.9 mm RMS on the
        156-marker take, against 0.7 mm for the neighbours' prediction.  The patch keeps the point
        tracked (it passed :meth:`_check_patches`); the blob's ray keeps what the blob measures.
        The prediction comes from neighbours with 2+ blob views, else the point's own motion
        (``motion``, NaN where unknown); without either the point stays where it was triangulated.
        Two or more patch views fix the depth from as many directions: such points keep what
        :meth:`_steady_depth` made of them, where a prediction off along the blob's ray does not
        take them with it (docs/tracking.md, session 16); so does one patch view in a camera across
        the rig from the blob's, whose depth error is under :data:`PATCH_DEPTH_MM_PER_PX` mm per px
        (session 19).
        """
        blob = src == SRC_DETECTION
        rows = np.flatnonzero(measured & (blob.sum(1) == 1) & ((src == SRC_PATCH).sum(1) == 1))
        if len(rows) == 0:
            return X
        # A patch in a camera across the rig fixes the depth to ~0.7 mm per px: step 7's average with the
        # prediction (by certainty) does better with it than the prediction alone.
        _u, mm = depth_uncertainty(rig, X[rows], (blob | (src == SRC_PATCH))[rows])
        rows = rows[mm > PATCH_DEPTH_MM_PER_PX]
        if len(rows) == 0:
            return X
        pred = self._predict(X, measured & (blob.sum(1) >= 2), rows)
        if motion is not None:
            pred = np.where(np.isfinite(pred), pred, motion[rows])
        ok = finite_rows(pred)
        rows, pred = rows[ok], pred[ok]
        if len(rows) == 0:
            return X
        X = X.copy()
        X[rows] = on_ray(rig, uv_c[rows], blob[rows], pred)[0]
        return X

    def _steady_depth(self, rig, X, valid, measured, weight=None):
        """Average each point with its neighbours' prediction; bound the depth of points seen only by close cameras.

        ``weight`` (N, S): each view's triangulation weight (:func:`confidence`), which
        scales its information in the average.

        A narrow pair's depth is off by mm per pixel of detection error, which its
        residuals do not show; the neighbours seen from both sides place it better.
        Such a point whose depth lies more than ``NARROW_DEPTH_MM`` from the prediction
        of its firmly seen neighbours is moved along its viewing direction to that
        distance (its image positions hardly change).  Points without firm neighbours
        (a cheek seen from one side only) keep their own depth: predictions from other
        narrow points would only pass the same error around.  Where the neighbours'
        votes disagree along the viewing direction by more than ``NARROW_DEPTH_MM``,
        their spread is the bound instead (:meth:`_vote_spread`); a point beyond
        ``NARROW_MISMATCH`` x Max Allowed 3D Point Error is a mismatch and is left
        as it is for Remove Bad 3D Points.

        Returns
        -------
        X : ndarray (N, 3)
        pred : ndarray (N, 3)
            The neighbours' prediction of every point (from the firm points where
            they suffice, else from all ``measured``).
        clamped : ndarray (N,) bool
            Points whose measured depth was beyond the bound (their offsets are not refreshed).

        Each average's variance (mm², inf where not averaged) goes to ``self._post_new``: the next frame's
        prediction carries it (:data:`CARRIED_Q`).

        A narrow point that no neighbour predicts, though it has neighbours (they are all lost), is not
        measured (its row of ``X`` is NaN).

        Every measured point's position is first averaged with the prediction, each weighted by
        its certainty (:func:`fuse_depth`); the bound applies to the average.  A narrow point more
        than ``OFF_DEPTH_VOTE_MM`` deep of its firm neighbours' prediction does not vote in the
        prediction of points without firm neighbours.
        """
        u, mm = depth_uncertainty(rig, X, valid & measured[:, None])
        narrow = measured & (mm > NARROW_MM_PER_PX)
        turn = np.ones(len(X), bool) if TURNED_VOTES else None
        pred, _ = elastic.predict(X, measured, self.nb, self.off, weight=self.w, rotate=turn)
        clamped = np.zeros(len(X), bool)
        has_firm = np.zeros(len(X), bool)
        firm = measured
        voting = measured
        if np.any(narrow):
            # Firm: seen from both sides and where its own neighbours put it.  A wide pair can triangulate
            # a wrong correspondence consistently (Remove Bad 3D Points drops it later), and one such
            # neighbour with a heavy weight would otherwise drag every narrow point near it.
            dev = np.linalg.norm(X - pred, axis=1)
            firm = measured & ~narrow & ~(dev > float(self.p.max_allowed_3d_point_error))
            firm_pred, _ = elastic.predict(X, firm, self.nb, self.off, weight=self.w, rotate=turn)
            has_firm = finite_rows(firm_pred)
            # A narrow point whose depth its firm neighbours put millimetres away (to be held near them below)
            # does not vote for the points without firm neighbours: a close pair 5.5 mm deep pulled a chin dot
            # beside it, well measured by a wide pair, 2.4 mm towards its own error.
            along = np.abs(np.einsum("ni,ni->n", np.nan_to_num(X - firm_pred), u))
            off_depth = narrow & has_firm & (along > OFF_DEPTH_VOTE_MM)
            if np.any(off_depth):
                voting = measured & ~off_depth
                pred, _ = elastic.predict(X, voting, self.nb, self.off, weight=self.w, rotate=turn)
            pred[has_firm] = firm_pred[has_firm]
        # How far each prediction can be off: the face's deformation over its neighbours' distance, or, where
        # they disagree about the depth (a jaw point between the still cheek and the moving chin), their spread.
        rows = np.flatnonzero(measured & finite_rows(pred))
        spread = np.zeros(len(X))
        if len(rows):
            spread[rows] = self._vote_spread(X, has_firm[rows], firm, voting, rows, pred[rows], u[rows])
        Xm = X
        sd = np.maximum(self.pred_sd, spread)
        if CARRIED_Q > 0:
            carried = np.sqrt(self.post_var + (CARRIED_Q * self.pred_sd) ** 2)
            sd = np.maximum(spread, np.minimum(self.pred_sd, carried))
        X = fuse_depth(X, information(rig, X, valid & measured[:, None], weight), pred, sd, measured,
                       self._post_new)
        # A close pair's depth with no neighbour to bound it is a guess within millimetres: not a measurement
        # (a chin dot with the jaw open, every neighbour lost, met 4.6 mm deep on cameras 0 and 1 at 4.3 mm a px;
        # its own motion was 3.4 mm off too).  Where the neighbours come back, so does the point.  A point
        # tracked with too few others to have neighbours (one or two selected points) has nothing to wait for.
        predicted = finite_rows(pred)
        unbounded = narrow & ~predicted
        if np.any(unbounded):
            X[unbounded & ((self.nb >= 0).sum(axis=1) >= elastic.MIN_NEIGHBOURS)] = np.nan
        rows = np.flatnonzero(narrow & predicted)
        if len(rows) == 0:
            return X, pred, clamped
        along = np.einsum("ni,ni->n", X[rows] - pred[rows], u[rows])
        measured_along = np.einsum("ni,ni->n", Xm[rows] - pred[rows], u[rows])
        # A point held frame after frame is held to offsets that age with it: the face deforms under them.
        bound = np.maximum(NARROW_DEPTH_MM + HELD_GROWTH_MM * self.held[rows], spread[rows])
        excess = along - np.clip(along, -bound, bound)
        # Held: the measured depth itself beyond the bound.  Its offsets are not refreshed even where the
        # average with the prediction came within the bound: a pair biased frame after frame would
        # otherwise walk the prediction after it, a fraction of the bias a frame.
        held = np.abs(measured_along) > bound
        if self.p.remove_bad_3d_points:
            # Farther than any grazing bias: a wrong blob, not a biased one.  Moved to the bound it
            # would pass as a point millimetres off; left where it is, Remove Bad 3D Points drops it.
            lim = NARROW_MISMATCH * float(self.p.max_allowed_3d_point_error)
            mismatch = np.abs(measured_along) > np.maximum(bound, lim)
            excess = np.where(mismatch, 0.0, excess)
            held &= ~mismatch
        X = X.copy()
        X[rows] -= excess[:, None] * u[rows]
        clamped[rows] = held
        return X, pred, clamped

    def _vote_spread(self, X, use_firm, firm, voting, rows, pred, u):
        """Weighted robust spread (mm) along ``u`` of the neighbour votes behind ``pred`` for ``rows``.

        Each row's prediction was made from the points ``firm`` (N,) where ``use_firm`` (n,), else ``voting`` (N,).
        Where the neighbours a point moves with disagree about its depth (a jaw point
        between the still cheek and the moving chin), their prediction is no firmer
        than two close cameras, and the depth is held only within this spread of it.
        """
        out = np.empty(len(rows))
        elastic.along_spread(X, self.nb, self.off, self.w, np.ascontiguousarray(pred),
                             np.ascontiguousarray(u), rows, use_firm, firm, voting, out)
        return out

    def _remove_bad_3d(self, rig, X, uv_c, valid, src, det, measured, back, pred, reach=1):
        """Detach views that put a point farther than Max Allowed 3D Point Error from its neighbours' prediction.

        ``back`` rows (lost on the previous frame, now seen by 3+ agreeing cameras, or seen in 3+
        blob views) get twice the limit: their neighbour offsets date from before they were lost, or
        the views agree more closely than the prediction can, so the prediction is what is stale,
        not the point.  ``pred`` is the neighbours' prediction of every point; ``reach`` (per
        point) multiplies the limit where ``pred`` is where the point was last seen, frames ago.
        """
        lim = np.where(back, 2.0, 1.0) * reach * float(self.p.max_allowed_3d_point_error)
        dev = np.linalg.norm(X - pred, axis=1)
        bad = np.flatnonzero(measured & np.isfinite(dev) & (dev > lim))
        for i in bad.tolist():
            views = np.flatnonzero(valid[i])
            best, best_d = None, np.inf
            if len(views) >= 3:
                # Leave one view out: a single mismatched detection is the usual cause.
                for s in views:
                    v = valid[i].copy()
                    v[s] = False
                    Xi = triangulate(rig, uv_c[i:i + 1], v[None], *self._view_weights(src, slice(i, i + 1)))[0]
                    e = reprojection(rig, Xi[None], uv_c[i:i + 1], v[None])[0]
                    d = np.linalg.norm(Xi - pred[i])
                    if d <= lim[i] and np.nanmax(e) <= self.p.max_allowed_2d_projection_error and d < best_d:
                        best, best_d = (s, Xi), d
            if best is not None:
                s, Xi = best
                valid[i, s] = False
                src[i, s] = SRC_NONE
                uv_c[i, s] = np.nan
                X[i] = Xi
            else:
                valid[i] = False
                src[i] = SRC_NONE
                uv_c[i] = np.nan
                X[i] = np.nan
                measured[i] = False
        return X, measured

    def _single_sensor(self, rig, X, measured, uv_c, valid, one):
        """Points on the ray of their one sample, at the depth nearest the neighbours' prediction."""
        N = len(X)
        out = np.full((N, 3), np.nan)
        rows = np.flatnonzero(one)
        pred = self._predict(X, measured, rows)
        keep = finite_rows(pred)
        rows, pred = rows[keep], pred[keep]
        if len(rows) == 0:
            return out
        Xr, t = on_ray(rig, uv_c[rows], valid[rows], pred)
        dist = np.linalg.norm(Xr - pred, axis=1)
        ok = (t > 0) & (dist <= self.p.single_sensor_tracking_threshold)
        out[rows[ok]] = Xr[ok]
        return out
