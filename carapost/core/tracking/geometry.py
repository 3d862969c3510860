"""Fast per-frame geometry of the tracker, in corrected (undistorted) pixels.

The tracker must run 160 points x 4 cameras in a few milliseconds per frame.
Distorting projections (an iterative inverse) and the exact raw-pixel
triangulation of :mod:`carapost.core.camera` cost more than the whole budget,
so the tracker converts every detection to corrected pixels once (a cheap
closed form) and does all of its geometry there with plain projection matrices.
Lens distortion of a Cara camera changes pixel scale by a few percent at the
image corners, so distances and errors in corrected pixels are the raw-pixel
ones to within that.
"""
from __future__ import annotations

import numpy as np

from ..camera import Camera
from .geometry_kernel import dlt_depth_weighted, dlt_held_out, pixel_errors, pixels, rotation_matrices
from .depth_kernel import depth_spread, view_information
from .pose_kernel import refine_rig


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors ``w`` (..., 3)."""
    w = np.asarray(w, float)
    out = np.empty(w.shape[:-1] + (3, 3))
    rotation_matrices(np.ascontiguousarray(w.reshape(-1, 3)), out.reshape(-1, 3, 3))
    return out


class RigState:
    """Poses of the S cameras of one frame as arrays (R (S,3,3), C (S,3)) plus fixed intrinsics.

    Parameters
    ----------
    cameras : list of Camera
        Intrinsics and the initial poses.
    """

    def __init__(self, cameras: list[Camera]):
        self.cameras = list(cameras)
        self.K = np.stack([c.K for c in cameras])
        self.Kinv = np.linalg.inv(self.K)
        self.R = np.stack([np.asarray(c.rotation, float) for c in cameras])
        self.C = np.stack([np.asarray(c.position, float) for c in cameras])
        self._P_of = None
        # Each camera's (cx, cy, k1, k2, k3, aspect) where all have a radial model (:meth:`correct_all`).
        terms = [c.radial_terms() for c in cameras]
        self._radial = None if any(t is None for t in terms) else \
            np.array([(*t, c.aspect) for t, c in zip(terms, cameras)], float)

    def copy(self) -> "RigState":
        out = RigState.__new__(RigState)
        out.cameras, out.K, out.Kinv, out._radial = self.cameras, self.K, self.Kinv, self._radial
        out.R, out.C = self.R.copy(), self.C.copy()
        out._P_of = None
        return out

    @property
    def S(self) -> int:
        return len(self.cameras)

    def P(self) -> np.ndarray:
        """``(S, 3, 4)`` projection matrices to corrected pixels (read only).

        Kept until ``R`` or ``C`` is replaced (poses are only ever assigned whole, never
        edited in place): every projection and triangulation of a frame asks for them.
        """
        if self._P_of is None or self._P_of[0] is not self.R or self._P_of[1] is not self.C:
            Rt = np.concatenate([self.R, -np.einsum("sij,sj->si", self.R, self.C)[..., None]], axis=2)
            self._P_of = (self.R, self.C, self.K @ Rt)
        return self._P_of[2]

    def to_cameras(self) -> list[Camera]:
        return [c.with_pose(self.R[s], self.C[s]) for s, c in enumerate(self.cameras)]

    def project(self, X: np.ndarray) -> np.ndarray:
        """Corrected pixels ``(N, S, 2)`` of world points ``X`` (N, 3); NaN behind a camera."""
        P = self.P()
        out = np.empty((len(X), len(P), 2))
        pixels(np.ascontiguousarray(X, dtype=float)[None], P, out)
        return out

    def correct(self, s: int, raw_xy: np.ndarray) -> np.ndarray:
        """Raw pixels of sensor ``s`` to corrected pixels."""
        return self.cameras[s].correct(raw_xy) if len(raw_xy) else np.zeros((0, 2))

    def correct_all(self, sensor: np.ndarray, raw_xy: np.ndarray) -> np.ndarray:
        """Raw pixels ``raw_xy`` (G, 2) of sensors ``sensor`` (G,) to corrected pixels, every sensor at once.

        :meth:`.Camera.correct`'s arithmetic on the rows of all sensors together (one set of array
        operations a frame instead of one per sensor); cameras without a radial model go one by one.
        """
        if self._radial is None:
            out = np.empty((len(raw_xy), 2))
            for s in range(self.S):
                rows = sensor == s
                out[rows] = self.correct(s, raw_xy[rows])
            return out
        cx, cy, k1, k2, k3, a = self._radial[sensor].T
        dx = raw_xy[:, 0] - cx
        dy = a * (raw_xy[:, 1] - cy)
        r2 = dx * dx + dy * dy
        s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return np.stack([s * dx + cx, s * dy / a + cy], axis=-1)

    def rays(self, s: np.ndarray, uv_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Origins ``(N, 3)`` and unit directions ``(N, 3)`` of corrected pixels ``uv_c`` in sensors ``s``."""
        h = np.concatenate([uv_c, np.ones((len(uv_c), 1))], axis=1)
        d = np.einsum("nji,njk,nk->ni", self.R[s], self.Kinv[s], h)
        return self.C[s], d / np.linalg.norm(d, axis=1, keepdims=True)


def _depth_weights(P: np.ndarray, X: np.ndarray, v: np.ndarray) -> np.ndarray:
    depth = X @ P[:, 2, :3].T + P[:, 2, 3]
    return np.where(v, 1.0 / np.maximum(np.abs(depth), 1e-3), 0.0) * 100.0


def round_views(shape: tuple) -> np.ndarray:
    """``(*shape, 3)`` view elongation ``(cos, sin, k)`` of views all round (k = 1), as :func:`triangulate` takes it."""
    el = np.zeros((*shape, 3))
    el[..., 2] = 1.0
    return el


def _elongation(elong, shape) -> np.ndarray:
    """The kernels' ``(n, S, 3)`` view elongation: ``elong``, or all round."""
    return round_views(shape) if elong is None else np.ascontiguousarray(elong, dtype=float)


def triangulate(rig: RigState, uv_c: np.ndarray, valid: np.ndarray, weight: np.ndarray | None = None,
                elong: np.ndarray | None = None) -> np.ndarray:
    """Batched triangulation in corrected pixels.

    Linear least squares on the DLT equations, solved twice: the second solve
    weights each view by the inverse depth found by the first, which turns the
    algebraic error into the image-plane error (optimal to first order for
    cameras of equal focal length, as on a Cara rig).

    Parameters
    ----------
    uv_c : ndarray (N, S, 2)
    valid : ndarray (N, S) bool
    weight : ndarray (N, S), optional
        Each view's confidence, the inverse of its expected image error relative
        to a blob's (1: a blob; less for a patch track, which lands several times
        farther from the marker); None: all 1.
    elong : ndarray (N, S, 3), optional
        Each view's ``(cos, sin, k)``: its error along the image direction (cos, sin) is 1/k times
        its error across it (an oblique dot's centre is less sure along its major axis); None: round.

    Returns
    -------
    ndarray (N, 3)
        NaN rows for points with fewer than 2 valid views.
    """
    conf = np.ones(valid.shape) if weight is None else np.ascontiguousarray(weight, dtype=float)
    return dlt_depth_weighted(rig.P(), np.ascontiguousarray(uv_c, dtype=float), np.ascontiguousarray(valid), conf,
                              _elongation(elong, valid.shape))


def held_out_errors(rig: RigState, uv_c: np.ndarray, valid: np.ndarray,
                    X: np.ndarray | None = None, weight: np.ndarray | None = None,
                    elong: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each view's error against the point triangulated from the other views.

    Parameters
    ----------
    uv_c : ndarray (N, S, 2)
    valid : ndarray (N, S) bool
        Rows need 3+ valid views.
    X : ndarray (N, 3), optional
        The points triangulated from all their views (with ``weight``), when already known.
    weight : ndarray (N, S), optional
        The views' confidence, as for :func:`triangulate`.
    elong : ndarray (N, S, 3), optional
        The views' elongation, as for :func:`triangulate`.

    Returns
    -------
    err : ndarray (N, S)
        Distance (px) from each valid view's sample to the projection of the
        point the other views give; -1 where not valid.
    X : ndarray (N, S, 3)
        Those leave-one-out points.
    """
    P = rig.P()
    if X is None:
        X = triangulate(rig, uv_c, valid, weight, elong)
    w = _depth_weights(P, X, valid) * (1.0 if weight is None else weight)
    Xs = dlt_held_out(P, np.ascontiguousarray(uv_c, dtype=float), w, _elongation(elong, valid.shape),
                      np.ascontiguousarray(valid))                     # (S, N, 3) without view s
    # Each leave-one-out point projected into the camera it left out, all cameras in one kernel call.
    proj = np.empty(valid.shape + (2,))
    pixels(Xs, P, proj)
    Xs = Xs.transpose(1, 0, 2)
    err = np.empty(valid.shape)
    pixel_errors(proj, uv_c, valid, -1.0, err)
    return np.where(np.isnan(err), -1.0, err), Xs


def reprojection(rig: RigState, X: np.ndarray, uv_c: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Corrected-pixel errors ``(N, S)`` of points ``X`` against ``uv_c``; NaN where not valid."""
    out = np.empty(valid.shape)
    pixel_errors(rig.project(X), uv_c, valid, np.nan, out)
    return out


def refine_poses(rig: RigState, X: np.ndarray, uv_c: np.ndarray, valid: np.ndarray, iterations: int = 3,
                 huber: float = 1.0, min_obs: int = 6) -> RigState:
    """Gauss-Newton refinement of every camera's pose on fixed 3D points (vectorised over cameras).

    Parameters
    ----------
    X : ndarray (N, 3)
        Points held fixed (brim markers, and this frame's triangulated face points).
    uv_c, valid : (N, S, 2), (N, S)
        Corrected observations.
    huber : float
        Huber threshold (px): a mismatched detection cannot drag a camera.
    min_obs : int
        Cameras with fewer observations keep their pose.

    Returns
    -------
    RigState
        A new state (the input is not changed).
    """
    out = rig.copy()
    good = (valid & np.all(np.isfinite(X), axis=1)[:, None]).T                 # (S, N)
    active = good.sum(axis=1) >= min_obs
    if not np.any(active):
        return out
    Xf = np.where(np.isfinite(X), X, 0.0)
    obs = np.ascontiguousarray(np.where(good[..., None], uv_c.transpose(1, 0, 2), 0.0))   # (S, N, 2)
    R, C = np.ascontiguousarray(out.R), np.ascontiguousarray(out.C)
    refine_rig(out.K, R, C, Xf, obs, np.ascontiguousarray(good), active, int(iterations), float(huber))
    out.R, out.C = R, C
    return out


def depth_uncertainty(rig: RigState, X: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How poorly a point's views fix its depth: viewing direction and mm of depth per px of error.

    Two cameras on the same side of a rig see a point from directions ~10 degrees
    apart: a pixel of error along their epipolar line moves the triangulated point
    by mm along the viewing direction while leaving every residual small.

    Parameters
    ----------
    X : ndarray (N, 3)
        Triangulated points.
    valid : ndarray (N, S) bool
        Their views.

    Returns
    -------
    u : ndarray (N, 3)
        Unit mean viewing direction (NaN without views).
    mm_per_px : ndarray (N,)
        Depth error along ``u`` per pixel of image error: distance over focal
        length divided by the sine of the widest angle between two views
        (inf with fewer than two views).
    """
    u = np.empty((len(X), 3))
    mm = np.empty(len(X))
    depth_spread(np.ascontiguousarray(X, dtype=float), rig.C, rig.K[:, 0, 0].copy(), np.ascontiguousarray(valid), u, mm)
    return u, mm


def information(rig: RigState, X: np.ndarray, valid: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """(N, 3, 3) how well each point's views fix it: the inverse of its position's covariance, per px².

    Each view adds ``(f / d)² (I - r rᵀ)``, ``r`` the unit ray from the camera to the point,
    ``d`` its length and ``f`` the focal length in px: a pixel of image error moves the point
    ``d / f`` mm across the ray and nothing along it.  Two close cameras leave the depth
    loose; cameras on both sides fix it.  ``weight`` (N, S): each view's confidence as in
    :func:`triangulate` (its information scales with the square).
    """
    out = np.empty((len(X), 3, 3))
    w = np.ones(valid.shape) if weight is None else np.ascontiguousarray(weight, dtype=float)
    view_information(np.ascontiguousarray(X, dtype=float), rig.C, rig.K[:, 0, 0].copy(), np.ascontiguousarray(valid),
                     w, out)
    return out
