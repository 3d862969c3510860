"""Stabilisation: per-frame rigid transforms that hold the head still (Process > Stabilize Data).

A head-mounted rig slips on the head, so the face moves in the rig's (the brim's)
frame although the actor's skull does not.  Stabilisation finds, for every frame
of a range, the rotation and translation that map that frame's stable points
(points the expression does not move: forehead, nose bridge, temples) onto the
same points on a *base frame*.  Applied to every point, they leave only the
expression.

Pure functions over arrays: positions are ``(F, P, 3)`` float64, NaN where a point
has no sample; a transform is a ``(3, 4)`` matrix ``[R | t]`` mapping raw to
stabilised positions, ``y = R x + t``.  The project keeps them beside the raw data
(:mod:`carapost.core.stabilize_ops`); nothing here changes a project.

Error figures follow the guide's glossary ("Stabilization error"): over the
*Stable Points Percent* most stable points of each frame (those nearest their
base-frame position once stabilised),

- base-frame error: RMS distance between those points and the same points on
  the base frame;
- inter-frame error: RMS distance between those points and the same points on
  the previous (stabilised) frame;
- stabilisation error: ``base_frame_weighting * base + inter_frame_weighting * inter``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import CaraError

__all__ = ["kabsch", "apply_transforms", "compose", "identity_transforms", "most_stable",
           "stabilization_errors", "solve_manual", "solve_assisted", "align_transform", "SolveResult",
           "Stabilization"]

#: Smallest number of points a rigid transform is solved from.
MIN_POINTS = 3


# ------------------------------------------------------------------ transforms
def identity_transforms(n: int) -> np.ndarray:
    """``(n, 3, 4)`` identity transforms."""
    t = np.zeros((n, 3, 4))
    t[:, :, :3] = np.eye(3)
    return t


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Weighted least-squares rigid transforms (Kabsch / Horn), batched.

    Parameters
    ----------
    src, dst : ndarray (..., N, 3)
        Corresponding points; NaN entries count as weight 0.
    weights : ndarray (..., N), optional
        Non-negative weights (default 1).

    Returns
    -------
    ndarray (..., 3, 4)
        ``[R | t]`` minimising ``sum w |R src + t - dst|^2`` with ``det R = +1``;
        NaN where fewer than three points have a positive weight.
    """
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    w = np.ones(src.shape[:-1]) if weights is None else np.broadcast_to(np.asarray(weights, np.float64),
                                                                         src.shape[:-1])
    ok_pt = _finite(src) & _finite(dst) & (w > 0)
    return _fit(np.where(ok_pt[..., None], src, 0.0), np.where(ok_pt[..., None], dst, 0.0),
                np.where(ok_pt, w, 0.0))


def _fit(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`kabsch` on finite points whose unused entries have weight 0."""
    return _fit_weighted(a, b * w[..., None], w)


def _fit_weighted(a: np.ndarray, wb: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`_fit` given the weighted targets ``wb = w * b`` (what the assisted solve accumulates)."""
    ok = np.count_nonzero(w > 0, axis=-1) >= MIN_POINTS
    wsum = np.where(ok, w.sum(-1), 1.0)[..., None, None]
    ca = (w[..., None, :] @ a) / wsum                      # (..., 1, 3) weighted centroids
    cb = wb.sum(-2, keepdims=True) / wsum
    # sum w (a - ca)(b - cb)^T without centring copies of a and b
    h = np.swapaxes(a, -1, -2) @ wb - wsum * np.swapaxes(ca, -1, -2) @ cb
    u, _s, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    d = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    d = np.where(d == 0, 1.0, d)      # a degenerate (e.g. collinear) set: any proper rotation
    v[..., :, 2] *= d[..., None]
    r = v @ np.swapaxes(u, -1, -2)
    out = np.empty(a.shape[:-2] + (3, 4))
    out[..., :3] = r
    out[..., 3] = (cb - ca @ np.swapaxes(r, -1, -2))[..., 0, :]
    out[~ok] = np.nan
    return out


def apply_transforms(transforms: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(F, P, 3)`` points moved by their frame's ``(F, 3, 4)`` transform (one ``(3, 4)`` for all)."""
    t = np.asarray(transforms, np.float64)
    x = np.asarray(points, np.float64)
    if t.ndim == 2:
        return x @ t[:, :3].T + t[:, 3]
    return x @ np.swapaxes(t[:, :, :3], -1, -2) + t[:, None, :, 3]


def _finite(x: np.ndarray) -> np.ndarray:
    """``(...)`` bool: all three coordinates finite (one pass instead of ``isfinite().all(-1)``)."""
    return np.isfinite(x[..., 0] + x[..., 1] + x[..., 2])


def compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The transform ``outer(inner(x))``; ``outer`` is ``(3, 4)``, ``inner`` ``(..., 3, 4)``."""
    o = np.asarray(outer, np.float64)
    i = np.asarray(inner, np.float64)
    out = np.empty(np.broadcast_shapes(o.shape, i.shape))
    out[..., :3] = o[:3, :3] @ i[..., :3]
    out[..., 3] = np.einsum("ij,...j->...i", o[:3, :3], i[..., 3]) + o[:3, 3]
    return out


def align_transform(p0, p1, p2) -> np.ndarray:
    """Align Data: the rigid transform into the frame three points define.

    ``p0`` becomes the origin, ``p1`` lies on the +X axis, ``p2`` in the XY plane
    on the +Y side; Z completes a right-handed frame.

    Raises
    ------
    CaraError
        When two points coincide or the three are (nearly) on one line.
    """
    p0, p1, p2 = (np.asarray(p, np.float64).reshape(3) for p in (p0, p1, p2))
    if not (np.isfinite(p0).all() and np.isfinite(p1).all() and np.isfinite(p2).all()):
        raise CaraError("Align Data needs the three points to have 3D positions on the frame")
    x = p1 - p0
    lx = np.linalg.norm(x)
    if lx < 1e-6:
        raise CaraError("Align Data: the first and second points coincide")
    x /= lx
    z = np.cross(x, p2 - p0)
    lz = np.linalg.norm(z)
    if lz < 1e-3 * max(lx, np.linalg.norm(p2 - p0)):
        raise CaraError("Align Data: the three points are on one line; they cannot define a plane")
    z /= lz
    y = np.cross(z, x)
    r = np.vstack([x, y, z])
    return np.column_stack([r, -r @ p0])


# ---------------------------------------------------------------- stable sets
def most_stable(sq_residuals: np.ndarray, present: np.ndarray, fraction: float) -> np.ndarray:
    """Per frame, the ``fraction`` of present points with the smallest residuals.

    Parameters
    ----------
    sq_residuals : ndarray (F, P)
        Squared distance of each stabilised point to its base-frame position.
    present : ndarray (F, P) bool
    fraction : float
        Stable Points Percent (0-1); at least three points are kept per frame
        (fewer only where fewer are present).

    Returns
    -------
    ndarray (F, P) bool
    """
    n = np.count_nonzero(present, axis=1)
    k = np.clip(np.ceil(float(fraction) * n - 1e-9).astype(int), np.minimum(MIN_POINTS, n), n)
    r = np.where(present, sq_residuals, np.inf)
    # the k-th smallest residual of each frame is its threshold (ties are measure-zero with real data)
    kth = np.take_along_axis(np.sort(r, axis=1), np.maximum(k - 1, 0)[:, None], axis=1)
    return (r <= kth) & present & (k > 0)[:, None]


def _sq_norm(d: np.ndarray) -> np.ndarray:
    return d[..., 0] ** 2 + d[..., 1] ** 2 + d[..., 2] ** 2


def _sq_residuals(stabilised: np.ndarray, base_points: np.ndarray) -> np.ndarray:
    return _sq_norm(stabilised - base_points[None])


def stabilization_errors(transforms: np.ndarray, points: np.ndarray, base: int, stable_fraction: float,
                         base_weight: float = 1.0, inter_weight: float = 1.0,
                         stable: np.ndarray | None = None) -> dict:
    """The guide's three error figures of a stabilisation (mm).

    Parameters
    ----------
    transforms : ndarray (F, 3, 4)
        NaN on frames that were not stabilised (they are left out).
    points : ndarray (F, P, 3)
        Raw positions (NaN where absent) of the candidate points.
    base : int
        Index of the base frame in ``points``.
    stable_fraction : float
        Stable Points Percent: the figures are over that fraction of each
        frame's points, the most stable ones.
    base_weight, inter_weight : float
        Base and Inter Frame Weighting.
    stable : ndarray (F, P) bool, optional
        The stable sets to use instead of picking them.

    Returns
    -------
    dict
        ``base_frame``, ``inter_frame``, ``weighted`` (mm) and ``stable_points``
        (mean points per frame the figures are over).
    """
    y = apply_transforms(transforms, points)
    present = _finite(y) & _finite(points[base])[None]
    r2 = _sq_residuals(y, points[base])
    if stable is None:
        stable = most_stable(r2, present, stable_fraction)
    stable = stable & present
    n_base = np.count_nonzero(stable)
    base_rms = math.sqrt(float(r2[stable].sum()) / n_base) if n_base else float("nan")
    pair = stable[1:] & present[:-1]
    d = y[1:] - y[:-1]
    n_inter = np.count_nonzero(pair)
    inter_rms = math.sqrt(float(_sq_norm(d)[pair].sum()) / n_inter) if n_inter else 0.0
    frames = np.count_nonzero(stable.any(axis=1))
    return {"base_frame": base_rms, "inter_frame": inter_rms,
            "weighted": base_weight * base_rms + inter_weight * inter_rms,
            "stable_points": float(n_base / frames) if frames else 0.0}


# --------------------------------------------------------------------- solving
@dataclass
class SolveResult:
    """What a stabilisation solve found.

    Attributes
    ----------
    transforms : ndarray (F, 3, 4)
        Raw to stabilised, per frame; NaN where too few points were present.
    stable : ndarray (F, P) bool
        The points each frame was stabilised on.
    errors : dict
        :func:`stabilization_errors` of the result.
    iterations : int
        Optimisation iterations run (0 for a manual solve).
    converged : bool
        The stable sets and transforms stopped changing before Max Processing Iterations.
    """

    transforms: np.ndarray
    stable: np.ndarray
    errors: dict
    iterations: int = 0
    converged: bool = True


def _check_base(points: np.ndarray, base: int) -> None:
    if not 0 <= base < len(points):
        raise CaraError(f"base frame index {base} is outside the {len(points)} frames being stabilised")


def solve_manual(points: np.ndarray, base: int, columns, stable_fraction: float = 0.25,
                 base_weight: float = 1.0, inter_weight: float = 1.0) -> SolveResult:
    """Stabilize Data [Manual]: map the chosen points of every frame onto the base frame.

    Parameters
    ----------
    points : ndarray (F, P, 3)
        Raw positions, NaN where absent.
    base : int
        Base frame (index into ``points``); its transform is the identity.
    columns : sequence of int
        The points the user chose as stable (at least three).
    stable_fraction, base_weight, inter_weight : float
        Only for the error figures, which are measured as for an assisted solve
        so the two can be compared.

    Returns
    -------
    SolveResult
    """
    points = np.asarray(points, np.float64)
    _check_base(points, base)
    cols = np.asarray(list(columns), int)
    if len(cols) < MIN_POINTS:
        raise CaraError(f"stabilisation needs at least {MIN_POINTS} points (got {len(cols)})")
    sel = points[:, cols]
    t = kabsch(sel, np.broadcast_to(sel[base], sel.shape))
    t[base] = identity_transforms(1)[0]
    stable = np.zeros(points.shape[:2], bool)
    stable[:, cols] = _finite(sel)
    errors = stabilization_errors(t, points, base, stable_fraction, base_weight, inter_weight)
    return SolveResult(t, stable, errors)


def solve_assisted(points: np.ndarray, base: int, columns=None, *, stable_fraction: float = 0.25,
                   base_weight: float = 1.0, inter_weight: float = 1.0, max_iterations: int = 50,
                   tolerance_mm: float = 1e-5, progress=None) -> SolveResult:
    """Stabilize Data [Assisted]: find the stable points and the transforms together.

    Minimises, over the per-frame transforms ``T_f`` (``T_base`` = identity) and
    the per-frame stable sets ``S_f``::

        base_weight  * sum_f sum_{i in S_f} |T_f x_fi - x_base,i|^2
      + inter_weight * sum_f sum_{i in S_f} |T_f x_fi - T_f-1 x_f-1,i|^2

    where ``S_f`` holds the ``stable_fraction`` of frame ``f``'s points nearest
    their base-frame position (a frame whose set alternates between two choices
    keeps one of them from then on).  Each iteration re-picks the stable sets
    (the points with the largest residuals drop out) and then updates every
    frame's transform as a weighted Kabsch fit to the base frame and its
    stabilised neighbours, even frames then odd frames (twice), so each
    half-step solves its frames exactly given the others.  Stops when the
    stable sets no longer change and no point moves by more than
    ``tolerance_mm``, or after ``max_iterations``.

    Parameters
    ----------
    points : ndarray (F, P, 3)
        Raw positions of every candidate point, NaN where absent.  Points
        absent on the base frame cannot be compared with it and are ignored.
    base : int
        Base frame index.
    columns : sequence of int, optional
        The user's selection: the first estimate is the fit to these points
        (or, frame by frame, the fit to every point when that explains more of
        the frame's most stable points).  None: start from every point.
    stable_fraction : float
        Stable Points Percent.
    base_weight, inter_weight : float
        Base Frame Weighting, Inter Frame Weighting (>= 0, not both 0).
    max_iterations : int
        Max Processing Iterations.
    tolerance_mm : float
        Convergence threshold on the largest point displacement of an iteration.
    progress : Progress, optional
        One step per iteration; a cancel raises ``Cancelled``.

    Returns
    -------
    SolveResult
    """
    points = np.asarray(points, np.float64)
    _check_base(points, base)
    if base_weight < 0 or inter_weight < 0 or base_weight + inter_weight <= 0:
        raise CaraError("Base Frame Weighting and Inter Frame Weighting must be >= 0 and not both 0")
    n_f = len(points)
    xb = points[base]
    present = _finite(points) & _finite(xb)[None]
    x = np.where(present[..., None], points, 0.0)       # finite; absent points get weight 0
    xb0 = np.where(_finite(xb)[:, None], xb, 0.0)
    target_b = np.broadcast_to(xb0, x.shape)

    # First estimate: per frame, the better of the selection's fit and the fit to every point.
    t = _fit(x, target_b, present.astype(np.float64))
    if columns is not None and len(columns):
        cols = np.asarray(list(columns), int)
        t_sel = _fit(x[:, cols], target_b[:, cols], present[:, cols].astype(np.float64))
        t = _better(t_sel, t, x, xb0, present, stable_fraction)
    t[base] = identity_transforms(1)[0]
    solvable = np.isfinite(t[:, 0, 0])
    usable = present & solvable[:, None]
    t[~solvable] = identity_transforms(1)[0]            # placeholders, NaN again at the end

    stable_prev = stable_prev2 = None
    frozen = np.zeros(n_f, bool)
    iterations, converged = 0, False
    # Frame f is row f + 1 of the padded arrays: a frame's neighbours are plain strided slices.
    y_pad = np.zeros((n_f + 2,) + x.shape[1:])
    y = y_pad[1:-1]
    y[:] = apply_transforms(t, x)
    use_pad = np.zeros((n_f + 2, x.shape[1]), bool)
    use_pad[1:-1] = usable
    stable_pad = np.zeros_like(use_pad)
    update = solvable & (np.arange(n_f) != base)
    for it in range(int(max_iterations)):
        if progress is not None:
            progress.step(1, f"iteration {it + 1}")
        iterations = it + 1
        stable = most_stable(_sq_residuals(y, xb0), usable, stable_fraction)
        if stable_prev2 is not None:
            # A frame whose set flips back and forth between two near-equal choices keeps the last one:
            # otherwise one frame in thousands stops the whole take from converging.
            frozen |= (stable == stable_prev2).all(1) & (stable != stable_prev).any(1)
            stable[frozen] = stable_prev[frozen]
        stable_pad[1:-1] = stable
        y_old = y.copy()
        for q in (0, 1, 0, 1):      # even frames, odd frames, twice per re-selection: the sets settle sooner
            acc, w = _weighted_targets(q, n_f, y_pad, xb0, stable_pad, use_pad, base_weight, inter_weight)
            new = _fit_weighted(x[q::2], acc, w)
            keep = update[q::2] & np.isfinite(new[:, 0, 0])
            t[q::2] = np.where(keep[:, None, None], new, t[q::2])
            y[q::2] = apply_transforms(t[q::2], x[q::2])
        change = float(np.max(np.abs(y - y_old), where=usable[..., None], initial=0.0))
        if stable_prev is not None and np.array_equal(stable, stable_prev) and change <= tolerance_mm:
            converged = True
            break
        stable_prev2, stable_prev = stable_prev, stable
    stable = most_stable(_sq_residuals(y, xb0), usable, stable_fraction)
    t[~solvable] = np.nan
    errors = stabilization_errors(t, np.where(present[..., None], points, np.nan), base, stable_fraction,
                                  base_weight, inter_weight, stable=stable)
    return SolveResult(t, stable, errors, iterations, converged)


def _better(t_a, t_b, x, xb, present, fraction):
    """Per frame, whichever transform leaves the smaller trimmed residual."""
    def cost(t):
        ok = np.isfinite(t[:, 0, 0])
        r2 = _sq_residuals(apply_transforms(np.where(ok[:, None, None], t, 0.0), x), xb)
        keep = most_stable(r2, present, fraction)
        return np.where(ok, np.where(keep, r2, 0.0).sum(1), np.inf)

    use_a = cost(t_a) <= cost(t_b)
    return np.where(use_a[:, None, None], t_a, t_b)


def _weighted_targets(q, n_f, y_pad, xb, stable_pad, use_pad, wb, wi):
    """Weighted Kabsch targets of frames ``q, q+2, ...`` given their neighbours' stabilised points.

    ``sum_k w_k |T x - t_k|^2`` equals ``W |T x - tbar|^2`` plus a constant, with
    ``W = sum w_k`` and ``W tbar = sum w_k t_k``: one fit serves all three terms.
    Pair ``(f-1, f)`` counts the points stable on ``f``, pair ``(f, f+1)`` those
    stable on ``f+1`` (the glossary's inter-frame error).  Returns ``(W tbar, W)``.
    """
    here = slice(q + 1, n_f + 1, 2)          # padded rows of the frames, their predecessors, their successors
    prev = slice(q, n_f, 2)
    nxt = slice(q + 2, n_f + 2, 2)
    s = stable_pad[here]
    w_b = wb * s
    w_p = wi * (s & use_pad[prev])
    w_n = wi * (stable_pad[nxt] & use_pad[here])
    acc = w_b[..., None] * xb[None] + w_p[..., None] * y_pad[prev] + w_n[..., None] * y_pad[nxt]
    return acc, w_b + w_p + w_n


# ------------------------------------------------------------- project record
@dataclass(eq=False)
class Stabilization:
    """A project's stabilisation, kept beside the raw positions.

    Attributes
    ----------
    transforms : ndarray (F, 3, 4) float64
        Per take frame, raw to stabilised (and aligned) positions; NaN on frames
        that were not stabilised.
    method : str
        ``"manual"``, ``"assisted"`` or ``"none"`` (Align Data without a stabilisation).
    base_frame : int
        The take frame the others were mapped onto (-1 for ``"none"``).
    frame_range : tuple of int
        Inclusive range stabilised (the active range at the time).
    point_ids : ndarray (N,) int64
        Manual: the chosen points.  Assisted: every candidate point.
    usage : ndarray (N,) float32
        Fraction of the stabilised frames on which each of ``point_ids`` was
        among the stable points.
    errors : dict
        :func:`stabilization_errors` at the time of the solve (mm).
    parameters : dict
        The Stabilization Parameters used.
    alignment : ndarray (3, 4) or None
        Align Data's transform, applied after the stabilisation (already
        included in ``transforms``).
    """

    transforms: np.ndarray
    method: str = "manual"
    base_frame: int = -1
    frame_range: tuple[int, int] = (0, 0)
    point_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    usage: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    errors: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    alignment: np.ndarray | None = None

    def digest_items(self) -> tuple:
        """Everything it holds, for :meth:`Project.digest`."""
        return (np.asarray(self.transforms, np.float64), self.method, int(self.base_frame),
                tuple(self.frame_range), np.asarray(self.point_ids, np.int64),
                np.asarray(self.usage, np.float32), sorted(self.errors.items()), sorted(self.parameters.items()),
                None if self.alignment is None else np.asarray(self.alignment, np.float64))


def __getattr__(name: str):
    # Views may import the project-level reader from here too; it lives in stabilize_ops (which imports us).
    if name == "stabilized_positions":
        from .stabilize_ops import stabilized_positions
        return stabilized_positions
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
