"""Camera model of a Vicon calibration (XCP): radial correction, projection, triangulation.

Conventions (those of the XCP files written by Vicon systems):

* Pixels: ``(x, y)`` with x to the right and y down, origin at the first pixel.
  *Raw* pixels are where a blob is seen in the image; *corrected* pixels are raw
  pixels with the radial distortion removed.  The projection matrix ``P`` maps
  world points to corrected pixels.
* ``rotation`` rotates world to camera coordinates; ``position`` is the camera
  centre in world millimetres, so ``X_cam = R (X - t)``.  The camera looks down
  its +z axis (a point in front has positive depth).
* Quaternions are ``(x, y, z, w)``, real part last.

The radial models (raw ``(xr, yr)`` to corrected ``(xc, yc)``, ``a`` the pixel
aspect ratio, ``c`` the distortion centre)::

    dp = (xr - cx, a (yr - cy)),  r = |dp|
    VICON_RADIAL  (w0 w1):            s = 1 + w0 r^2 + w1 r^4,           c = principal point
    VICON_RADIAL2 (cx cy k1 k2 k3):   s = 1 + k1 r^2 + k2 r^4 + k3 r^6,  c = (cx, cy)
    xc = s dp_x + cx,  yc = s dp_y / a + cy

Pure numpy/scipy: no Qt here, so the solvers and the command line can use it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Sequence

import numpy as np

__all__ = [
    "Camera", "DISTORTION_MODELS", "quaternion_to_matrix", "matrix_to_quaternion",
    "triangulate", "triangulate_many", "reprojection_errors", "fundamental_matrix",
    "epipolar_line", "symmetric_epipolar_distance", "centroid",
]

DISTORTION_MODELS = ("none", "VICON_RADIAL", "VICON_RADIAL2")
_DISTORTION_SIZE = {"none": 0, "VICON_RADIAL": 2, "VICON_RADIAL2": 5}

# Newton inversion of the radial correction: stop when the radius moves less than
# this (pixels); the result is then checked against _INVERSE_TOL.
_NEWTON_STEP_TOL = 1e-11
_NEWTON_MAX_ITER = 60
_INVERSE_TOL = 1e-6
# Triangulation refinement stops when no point moved more than this (mm) in the
# last step; convergence is quadratic, so the error left is orders smaller.
_GN_STEP_TOL_MM = 1e-5


# --------------------------------------------------------------------------- quaternions

def quaternion_to_matrix(q_xyzw) -> np.ndarray:
    """Rotation matrix of a quaternion.

    Parameters
    ----------
    q_xyzw : array_like, shape (4,) or (..., 4)
        Quaternion ``(x, y, z, w)``, real part last.  It is normalised first, so
        the 15-digit quaternions of XCP files give orthonormal matrices.

    Returns
    -------
    ndarray, shape (3, 3) or (..., 3, 3)
        The matrix rotating vectors as the quaternion does (``v' = R v``).

    Raises
    ------
    ValueError
        If the quaternion is not 4 finite numbers or has zero length.
    """
    q = np.asarray(q_xyzw, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"a quaternion has 4 components, got shape {q.shape}")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(n < 1e-12):
        raise ValueError("quaternion must be finite and non-zero")
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R = np.stack([
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ], axis=-1)
    return R.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quaternion(R) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0``.

    Parameters
    ----------
    R : array_like, shape (3, 3) or (..., 3, 3)
        Rotation matrix (a slightly non-orthonormal one gives the quaternion of
        the nearest rotation).

    Returns
    -------
    ndarray, shape (4,) or (..., 4)
        Unit quaternion, real part last, sign chosen so that ``w >= 0`` (``q`` and
        ``-q`` are the same rotation; one canonical sign keeps files stable).
    """
    from scipy.spatial.transform import Rotation

    M = np.asarray(R, dtype=np.float64)
    if M.shape[-2:] != (3, 3):
        raise ValueError(f"a rotation matrix is 3x3, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("rotation matrix must be finite")
    q = Rotation.from_matrix(M.reshape(-1, 3, 3)).as_quat()
    q = np.where(q[:, 3:4] < 0, -q, q)
    return q.reshape(M.shape[:-2] + (4,))


# --------------------------------------------------------------------------- camera

def _as_uv(uv) -> np.ndarray:
    a = np.asarray(uv, dtype=np.float64)
    if a.shape[-1:] != (2,):
        raise ValueError(f"pixel coordinates have 2 components, got shape {a.shape}")
    return a


def _as_xyz(X) -> np.ndarray:
    a = np.asarray(X, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"3D points have 3 components, got shape {a.shape}")
    return a


@dataclass(eq=False)
class Camera:
    """One calibrated camera: intrinsics, radial distortion and pose.

    Attributes
    ----------
    name, device_id : str
        ``NAME`` and ``DEVICEID`` of the XCP camera.
    sensor_size : tuple of int
        ``(width, height)`` in pixels.
    focal_length : float
        Focal length in pixels.
    principal_point : ndarray, shape (2,)
        In pixels; defaults to the sensor centre.
    aspect : float
        Pixel aspect ratio ``a`` (``K[1, 1] = f / a``).
    skew : float
        ``K[0, 1]``.
    distortion_model : {"none", "VICON_RADIAL", "VICON_RADIAL2"}
    distortion : ndarray
        ``(w0, w1)`` for VICON_RADIAL, ``(cx, cy, k1, k2, k3)`` for VICON_RADIAL2,
        empty for none.
    rotation : ndarray, shape (3, 3)
        World to camera.
    position : ndarray, shape (3,)
        Camera centre in world millimetres.

    Notes
    -----
    Arrays are copied on construction (so ``dataclasses.replace(cam)`` is a deep
    copy).  Equality is exact equality of every field.
    """

    name: str = ""
    device_id: str = ""
    sensor_size: tuple[int, int] = (1280, 720)
    focal_length: float = 1000.0
    principal_point: np.ndarray = None  # type: ignore[assignment]  # None -> sensor centre
    aspect: float = 1.0
    skew: float = 0.0
    distortion_model: str = "none"
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        self.name = str(self.name)
        self.device_id = str(self.device_id)
        w, h = (int(v) for v in self.sensor_size)
        self.sensor_size = (w, h)
        self.focal_length = float(self.focal_length)
        self.aspect = float(self.aspect)
        self.skew = float(self.skew)
        if self.principal_point is None:
            self.principal_point = np.array([w / 2.0, h / 2.0])
        self.principal_point = np.array(self.principal_point, dtype=np.float64).reshape(-1)
        self.rotation = np.array(self.rotation, dtype=np.float64)
        self.position = np.array(self.position, dtype=np.float64).reshape(-1)
        if self.distortion_model is None or self.distortion_model == "":
            self.distortion_model = "none"
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"unknown distortion model {self.distortion_model!r} "
                             f"(expected one of {', '.join(DISTORTION_MODELS)})")
        self.distortion = np.array(self.distortion if self.distortion is not None else [],
                                   dtype=np.float64).reshape(-1)
        n = _DISTORTION_SIZE[self.distortion_model]
        if self.distortion.size != n:
            raise ValueError(f"{self.distortion_model} distortion has {n} values, "
                             f"got {self.distortion.size}")
        if self.principal_point.shape != (2,):
            raise ValueError("principal_point has 2 values")
        if self.position.shape != (3,):
            raise ValueError("position has 3 values")
        if self.rotation.shape != (3, 3):
            raise ValueError("rotation is a 3x3 matrix")
        if not (np.isfinite(self.focal_length) and self.focal_length > 0):
            raise ValueError(f"focal length must be positive, got {self.focal_length}")
        if not (np.isfinite(self.aspect) and self.aspect > 0):
            raise ValueError(f"pixel aspect ratio must be positive, got {self.aspect}")
        for nm in ("principal_point", "rotation", "position", "distortion"):
            if not np.all(np.isfinite(getattr(self, nm))):
                raise ValueError(f"{nm} must be finite")
        if not np.isfinite(self.skew):
            raise ValueError("skew must be finite")

    # ------------------------------------------------------------------ basics

    def __eq__(self, other) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # mutable, compared by value

    @classmethod
    def from_quaternion(cls, q_xyzw, position, **kw) -> "Camera":
        """Camera with the pose of quaternion ``q_xyzw`` (world to camera) and centre ``position``."""
        return cls(rotation=quaternion_to_matrix(q_xyzw), position=position, **kw)

    def quaternion(self) -> np.ndarray:
        """``(x, y, z, w)`` of ``rotation``, with ``w >= 0``."""
        return matrix_to_quaternion(self.rotation)

    def copy(self) -> "Camera":
        """A deep copy."""
        return replace(self)

    def with_pose(self, rotation, position) -> "Camera":
        """A copy with another pose (``rotation`` world to camera, ``position`` the centre)."""
        return replace(self, rotation=rotation, position=position)

    @property
    def label(self) -> str:
        """``name``, else ``device_id`` (Nexus files leave NAME empty)."""
        return self.name or self.device_id

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix ``[[f, k, xpp], [0, f/a, ypp], [0, 0, 1]]``."""
        f = self.focal_length
        return np.array([[f, self.skew, self.principal_point[0]],
                         [0.0, f / self.aspect, self.principal_point[1]],
                         [0.0, 0.0, 1.0]])

    @property
    def P(self) -> np.ndarray:
        """Projection matrix ``K [R | -R t]`` (world mm to corrected pixels)."""
        return self.K @ np.hstack([self.rotation, (-self.rotation @ self.position)[:, None]])

    # ------------------------------------------------------------------ distortion

    def radial_terms(self):
        """``(cx, cy, k1, k2, k3)`` of the radial model, or None without distortion."""
        d = self.distortion
        if self.distortion_model == "VICON_RADIAL":
            return self.principal_point[0], self.principal_point[1], d[0], d[1], 0.0
        if self.distortion_model == "VICON_RADIAL2":
            return d[0], d[1], d[2], d[3], d[4]
        return None

    def correct(self, raw_uv) -> np.ndarray:
        """Remove the radial distortion: raw pixels to corrected pixels.

        Parameters
        ----------
        raw_uv : array_like, shape (..., 2)
            Raw (image) pixel coordinates, e.g. ``(N, 2)`` or ``(2,)``.

        Returns
        -------
        ndarray, same shape
            Corrected pixel coordinates (NaN in, NaN out).
        """
        uv = _as_uv(raw_uv)
        rad = self.radial_terms()
        if rad is None:
            return uv.copy()
        cx, cy, k1, k2, k3 = rad
        a = self.aspect
        dx = uv[..., 0] - cx
        dy = a * (uv[..., 1] - cy)
        r2 = dx * dx + dy * dy
        s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return np.stack([s * dx + cx, s * dy / a + cy], axis=-1)

    def correct_jacobian(self, raw_uv) -> np.ndarray:
        """Derivative of :meth:`correct` at raw pixels.

        Parameters
        ----------
        raw_uv : array_like, shape (..., 2)

        Returns
        -------
        ndarray, shape (..., 2, 2)
            ``J[..., i, j] = d corrected_i / d raw_j``.
        """
        uv = _as_uv(raw_uv)
        J = np.zeros(uv.shape[:-1] + (2, 2))
        rad = self.radial_terms()
        if rad is None:
            J[..., 0, 0] = J[..., 1, 1] = 1.0
            return J
        cx, cy, k1, k2, k3 = rad
        a = self.aspect
        px = uv[..., 0] - cx
        py = a * (uv[..., 1] - cy)
        r2 = px * px + py * py
        s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        ds = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # ds / d(r^2)
        # In aspect-scaled coordinates p the correction is q = s(|p|^2) p, so
        # dq/dp = s I + 2 s' p p^T; the aspect scaling of y is undone around it.
        J[..., 0, 0] = s + 2.0 * ds * px * px
        J[..., 0, 1] = 2.0 * ds * px * py * a
        J[..., 1, 0] = 2.0 * ds * px * py / a
        J[..., 1, 1] = s + 2.0 * ds * py * py
        return J

    def distort(self, corrected_uv) -> np.ndarray:
        """Add the radial distortion back: corrected pixels to raw pixels (inverse of :meth:`correct`).

        The correction scales the aspect-scaled offset from the distortion centre
        by ``s(r)``, keeping its direction, so the inverse is a 1-D problem in the
        raw radius ``rho``: solve ``rho s(rho) = |corrected offset|`` by Newton's
        method (converged to ~1e-11 px).

        Parameters
        ----------
        corrected_uv : array_like, shape (..., 2)

        Returns
        -------
        ndarray, same shape
            Raw pixels.  NaN where no raw pixel maps there: beyond the radius where
            the polynomial folds back (``d(rho s)/d rho <= 0``), which a real lens
            never images.
        """
        uv = _as_uv(corrected_uv)
        rad = self.radial_terms()
        if rad is None:
            return uv.copy()
        cx, cy, k1, k2, k3 = rad
        a = self.aspect
        ex = uv[..., 0] - cx
        ey = a * (uv[..., 1] - cy)
        re = np.hypot(ex, ey)
        with np.errstate(invalid="ignore", over="ignore"):
            # Start from one fixed-point step (rho = re / s(re)): Newton then needs
            # only a few iterations for realistic lenses.
            r2 = re * re
            s0 = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            rho = np.where(s0 > 0.0, re / np.where(s0 > 0.0, s0, 1.0), re)
            for _ in range(_NEWTON_MAX_ITER):
                r2 = rho * rho
                f = rho * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) - re
                fp = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
                step = f / fp
                new = rho - step
                # A Newton step past zero (strong barrel terms far out) is halved instead.
                rho = np.where(new < 0.0, 0.5 * rho, new)
                if not np.any(np.abs(step) > _NEWTON_STEP_TOL):  # NaN steps do not keep us looping
                    break
            r2 = rho * rho
            s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            fp = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3))
            bad = ~(np.abs(rho * s - re) <= _INVERSE_TOL) | ~(fp > 0.0)
            scale = np.where(re > 0.0, rho / np.where(re > 0.0, re, 1.0), 1.0)
        scale = np.where(bad, np.nan, scale)  # also NaN in (comparisons with NaN fail)
        return np.stack([ex * scale + cx, ey * scale / a + cy], axis=-1)

    # ------------------------------------------------------------------ projection

    def to_camera(self, X) -> np.ndarray:
        """Camera-frame coordinates ``R (X - t)`` of world points ``X`` (..., 3)."""
        X = _as_xyz(X)
        return (X - self.position) @ self.rotation.T

    def depth(self, X) -> np.ndarray:
        """Depth (camera z, mm) of world points ``X`` (..., 3); positive in front of the camera."""
        X = _as_xyz(X)
        return (X - self.position) @ self.rotation[2]

    def _corrected_from_camera(self, Xc: np.ndarray) -> np.ndarray:
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = Xc[..., 0] / z
            y = Xc[..., 1] / z
        f = self.focal_length
        return np.stack([f * x + self.skew * y + self.principal_point[0],
                         (f / self.aspect) * y + self.principal_point[1]], axis=-1)

    def project_corrected(self, X) -> np.ndarray:
        """Corrected pixels of world points ``X`` (..., 3) through ``P``.

        Points not in front of the camera (depth <= 0) give NaN: they are not
        imaged, and their mirrored projection would mislead.
        """
        Xc = self.to_camera(X)
        uv = self._corrected_from_camera(Xc)
        uv[~(Xc[..., 2] > 0)] = np.nan
        return uv

    def project(self, X) -> np.ndarray:
        """Raw (image) pixels of world points ``X`` (..., 3): ``P`` then :meth:`distort`.

        NaN for points behind the camera or beyond the valid range of the distortion.
        """
        return self.distort(self.project_corrected(X))

    def ray(self, raw_uv):
        """Viewing rays of raw pixels.

        Parameters
        ----------
        raw_uv : array_like, shape (..., 2)

        Returns
        -------
        origin : ndarray, shape (3,)
            The camera centre.
        directions : ndarray, shape (..., 3)
            Unit world directions (towards the scene, i.e. increasing depth).
        """
        c = self.correct(raw_uv)
        f, a, k = self.focal_length, self.aspect, self.skew
        xpp, ypp = self.principal_point
        # K^-1 [u, v, 1] in closed form (upper-triangular K).
        y = (c[..., 1] - ypp) * a / f
        x = (c[..., 0] - xpp - k * y) / f
        d = np.stack([x, y, np.ones_like(x)], axis=-1) @ self.rotation  # R^T d
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return self.position.copy(), d


# --------------------------------------------------------------------------- triangulation

def _stack_cameras(cameras: Sequence[Camera]):
    """Per-view arrays used by the vectorised solvers."""
    R = np.stack([c.rotation for c in cameras])                      # (V,3,3)
    t = np.stack([c.position for c in cameras])                      # (V,3)
    P = np.stack([c.P for c in cameras])                             # (V,3,4)
    intr = np.array([[c.focal_length, c.focal_length / c.aspect, c.skew,
                      c.principal_point[0], c.principal_point[1]] for c in cameras])  # (V,5)
    return R, t, P, intr


def _dlt(P: np.ndarray, centres: np.ndarray, uv: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Batched linear triangulation.

    P (V,3,4), centres (V,3), uv (N,V,2) corrected pixels (finite where valid),
    valid (N,V).  Returns (N,3), NaN where the system is degenerate.

    The DLT rows ``u P3 - P1``, ``v P3 - P2`` are solved with the homogeneous
    coordinate fixed to 1 (normal equations of a 3x3 system per point) rather
    than by a batched SVD, which costs ~1 ms for 160 points by itself; a point
    at infinity is impossible for cameras around a face.
    """
    # Condition the system: world coordinates relative to the cameras' centroid
    # in units of their spread (mm offsets of ~1e3 would otherwise dwarf the
    # rotation part of P), and every row scaled to unit length.
    m = centres.mean(axis=0)
    sc = float(np.mean(np.linalg.norm(centres - m, axis=1)))
    if not sc > 0:
        sc = 1.0
    T = np.eye(4)
    T[:3, :3] *= sc
    T[:3, 3] = m
    Pn = P @ T                                                       # (V,3,4)
    rows_u = uv[..., 0:1] * Pn[None, :, 2, :] - Pn[None, :, 0, :]    # (N,V,4)
    rows_v = uv[..., 1:2] * Pn[None, :, 2, :] - Pn[None, :, 1, :]
    A = np.concatenate([rows_u, rows_v], axis=1)                     # (N,2V,4)
    w = np.concatenate([valid, valid], axis=1)
    nrm = np.linalg.norm(A, axis=-1)
    A = A * (w / np.where(nrm > 0, nrm, 1.0))[..., None]
    At = A[..., :3].transpose(0, 2, 1)
    H = At @ A[..., :3]
    g = -(At @ A[..., 3:])
    det = np.linalg.det(H)
    bad = ~(np.abs(det) > 1e-14)
    H[bad] = np.eye(3)
    Y = np.linalg.solve(H, g)[..., 0]
    Y[bad] = np.nan
    return Y * sc + m


def _gauss_newton(R, t, intr, uv_c, W, valid, X, iterations=8):
    """Batched Levenberg-Marquardt on whitened corrected-pixel residuals.

    Residual of view v: ``W_v (pi_v(X) - uv_c_v)`` where ``W_v`` is the inverse
    Jacobian of the correction at the observed raw pixel, so that the cost is,
    to first order, the squared *raw*-pixel reprojection error (what the
    detector measured) without inverting the distortion every iteration.

    Written with explicit per-component arithmetic on (N, V) arrays: with 160
    points the run time is the number of numpy calls, and small einsums,
    broadcast matmuls of 2x3 blocks and batched LAPACK calls cost more than
    the arithmetic itself.
    """
    N, V = valid.shape
    f, fa, k, xpp, ypp = (intr[:, i] for i in range(5))
    Rt = np.einsum("vij,vj->vi", R, t)
    Rflat = R.reshape(V * 3, 3).T
    vm = valid.astype(np.float64)
    w00, w01, w10, w11 = (W[..., i, j] * vm for i in (0, 1) for j in (0, 1))
    uc, vc = uv_c[..., 0], uv_c[..., 1]

    def residual(Xp):
        Xc = (Xp @ Rflat).reshape(-1, V, 3) - Rt
        z = Xc[..., 2]
        front = z > 0
        zi = 1.0 / np.where(front, z, 1.0)
        x = Xc[..., 0] * zi
        y = Xc[..., 1] * zi
        ex = f * x + k * y + xpp - uc
        ey = fa * y + ypp - vc
        rx = w00 * ex + w01 * ey
        ry = w10 * ex + w11 * ey
        cost = np.sum(rx * rx + ry * ry, axis=1)
        cost[np.any(~front & valid, axis=1)] = np.inf
        return cost, rx, ry, zi, x, y

    cost, rx, ry, zi, x, y = residual(X)
    lam = np.full(N, 1e-4)
    eye = np.eye(3)
    for _ in range(iterations):
        # d(u, v)/d(camera coords), then through R to world: J_world = J_cam R.
        a0, a1, a2 = f * zi, k * zi, -(f * x + k * y) * zi
        b1, b2 = fa * zi, -fa * y * zi
        Ju = a0[..., None] * R[:, 0] + a1[..., None] * R[:, 1] + a2[..., None] * R[:, 2]
        Jv = b1[..., None] * R[:, 1] + b2[..., None] * R[:, 2]
        J = np.concatenate([w00[..., None] * Ju + w01[..., None] * Jv,
                            w10[..., None] * Ju + w11[..., None] * Jv], axis=1)
        r = np.concatenate([rx, ry], axis=1)
        Jt = J.transpose(0, 2, 1)
        H = Jt @ J
        g = (Jt @ r[..., None])[..., 0]
        diag = np.diagonal(H, axis1=1, axis2=2)
        Hd = H + (lam[:, None] * diag + 1e-12)[:, None, :] * eye
        try:
            delta = -np.linalg.solve(Hd, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        Xn = X + delta
        costn, rxn, ryn, zin, xn, yn = residual(Xn)
        better = costn <= cost
        b2d = better[:, None]
        X = np.where(b2d, Xn, X)
        rx, ry = np.where(b2d, rxn, rx), np.where(b2d, ryn, ry)
        zi, x, y = np.where(b2d, zin, zi), np.where(b2d, xn, x), np.where(b2d, yn, y)
        cost = np.where(better, costn, cost)
        lam = np.where(better, lam * 0.1, lam * 10.0)
        # Stop once every point moved less than 10 nm: with quadratic convergence
        # what is left is far below any marker accuracy; more would only cost time.
        if not np.any(np.abs(delta) > _GN_STEP_TOL_MM):
            break
    return X


def triangulate_many(cameras: Sequence[Camera], uv, min_views: int = 2, refine: bool = True) -> np.ndarray:
    """Triangulate many points at once (the tracking hot path).

    Parameters
    ----------
    cameras : sequence of Camera, length V
    uv : array_like, shape (N, V, 2)
        Raw pixels of each point in each camera; NaN where a camera has no observation.
    min_views : int
        Fewest observations a point needs (at least 2).
    refine : bool
        Refine the linear solution by Levenberg-Marquardt on the reprojection error.

    Returns
    -------
    ndarray, shape (N, 3)
        World points; NaN rows for points seen by fewer than ``min_views`` cameras.

    Notes
    -----
    Linear DLT on corrected pixels (batched 3x3 normal equations), then a few batched LM
    iterations minimising the corrected-pixel residuals whitened by the inverse
    Jacobian of the correction at each observation, i.e. the raw-pixel error to
    first order.  :func:`triangulate` minimises the exact raw-pixel error.
    """
    cameras = list(cameras)
    uv = np.asarray(uv, dtype=np.float64)
    V = len(cameras)
    if uv.ndim != 3 or uv.shape[1:] != (V, 2):
        raise ValueError(f"uv must be (N, {V}, 2) for {V} cameras, got {uv.shape}")
    N = uv.shape[0]
    out = np.full((N, 3), np.nan)
    if N == 0 or V < 2:
        return out
    valid = np.all(np.isfinite(uv), axis=-1)
    uv0 = np.where(valid[..., None], uv, 0.0)
    uv_c = np.stack([cam.correct(uv0[:, i]) for i, cam in enumerate(cameras)], axis=1)
    valid &= np.all(np.isfinite(uv_c), axis=-1)
    ok = valid.sum(axis=1) >= max(2, int(min_views))
    if not np.any(ok):
        return out
    if not np.all(ok):
        valid, uv0, uv_c = valid[ok], uv0[ok], uv_c[ok]
    uv_c = np.where(valid[..., None], uv_c, 0.0)
    R, t, P, intr = _stack_cameras(cameras)
    X = _dlt(P, t, uv_c, valid)
    if refine:
        good = np.all(np.isfinite(X), axis=1)
        if not np.all(good):
            valid, uv0, uv_c = valid[good], uv0[good], uv_c[good]
        J = np.stack([cam.correct_jacobian(uv0[:, i]) for i, cam in enumerate(cameras)], axis=1)
        # Closed-form 2x2 inverse (a batched LAPACK call costs more than the rest).
        # Missing observations get the identity so that 0 * (inf or NaN) cannot
        # leak into the masked sums.
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        usable = valid & (np.abs(det) > 1e-12)
        det = np.where(usable, det, 1.0)
        W = np.empty_like(J)
        W[..., 0, 0] = np.where(usable, J[..., 1, 1] / det, 1.0)
        W[..., 1, 1] = np.where(usable, J[..., 0, 0] / det, 1.0)
        W[..., 0, 1] = np.where(usable, -J[..., 0, 1] / det, 0.0)
        W[..., 1, 0] = np.where(usable, -J[..., 1, 0] / det, 0.0)
        if np.any(good):
            X[good] = _gauss_newton(R, t, intr, uv_c, W, valid, X[good])
    out[ok] = X
    return out


def triangulate(cameras: Sequence[Camera], uv_raw, refine: bool = True) -> np.ndarray:
    """Triangulate one point from one raw observation per camera.

    Parameters
    ----------
    cameras : sequence of Camera, length V
    uv_raw : array_like, shape (V, 2)
        Raw pixels; a NaN row means the camera does not see the point.
    refine : bool
        Refine the linear (DLT) solution by Levenberg-Marquardt on the exact
        raw-pixel reprojection error (distortion included).

    Returns
    -------
    ndarray, shape (3,)
        The point, or NaN when fewer than 2 cameras see it.
    """
    from scipy.optimize import least_squares

    cameras = list(cameras)
    uv = np.asarray(uv_raw, dtype=np.float64).reshape(len(cameras), 2)
    X0 = triangulate_many(cameras, uv[None], refine=False)[0]
    if not refine or not np.all(np.isfinite(X0)):
        return X0
    use = [i for i in range(len(cameras)) if np.all(np.isfinite(uv[i]))]
    cams = [cameras[i] for i in use]
    obs = uv[use]

    def residual(X):
        pr = np.stack([c.project(X) for c in cams])
        return np.nan_to_num(pr - obs, nan=1e6).ravel()

    def jacobian(X):
        rows = []
        for c in cams:
            Xc = c.to_camera(X)
            z = Xc[2]
            xc, yc = Xc[0] / z, Xc[1] / z
            f, fa, k = c.focal_length, c.focal_length / c.aspect, c.skew
            Juv = np.array([[f / z, k / z, -(f * xc + k * yc) / z],
                            [0.0, fa / z, -fa * yc / z]]) @ c.rotation
            raw = c.project(X)
            if not np.all(np.isfinite(raw)):
                raw = c.project_corrected(X)
            rows.append(np.linalg.solve(c.correct_jacobian(raw), Juv))
        return np.vstack(rows)

    sol = least_squares(residual, X0, jac=jacobian, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    X = sol.x
    # Keep the linear solution if the refinement did not improve it (e.g. the
    # point fell behind a camera along the way).
    return X if np.sum(residual(X) ** 2) <= np.sum(residual(X0) ** 2) else X0


def reprojection_errors(cameras: Sequence[Camera], X, uv) -> np.ndarray:
    """Raw-pixel distances between observations and the projections of points.

    Parameters
    ----------
    cameras : sequence of Camera, length V
    X : array_like, shape (N, 3) or (3,)
    uv : array_like, shape (N, V, 2) or (V, 2)
        Raw observations (NaN where missing).

    Returns
    -------
    ndarray, shape (N, V) or (V,)
        Pixel errors; NaN for missing observations and points behind a camera.
    """
    X = _as_xyz(X)
    uv = np.asarray(uv, dtype=np.float64)
    proj = np.stack([c.project(X) for c in cameras], axis=-2)       # (..., V, 2)
    return np.linalg.norm(proj - uv, axis=-1)


# --------------------------------------------------------------------------- epipolar geometry

def _skew3(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_matrix(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """Fundamental matrix between two cameras, in corrected pixels.

    Returns
    -------
    ndarray, shape (3, 3)
        ``F`` with ``x_b^T F x_a = 0`` for corrected homogeneous pixels of the
        same world point; scaled to unit Frobenius norm.
    """
    # Relative pose: X_b = R_rel X_a + t_rel in camera coordinates.
    R_rel = cam_b.rotation @ cam_a.rotation.T
    t_rel = cam_b.rotation @ (cam_a.position - cam_b.position)
    E = _skew3(t_rel) @ R_rel
    F = np.linalg.inv(cam_b.K).T @ E @ np.linalg.inv(cam_a.K)
    n = np.linalg.norm(F)
    return F / n if n > 0 else F


def _homog(uv: np.ndarray) -> np.ndarray:
    return np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)


def epipolar_line(cam_a: Camera, cam_b: Camera, uv_a_raw) -> np.ndarray:
    """Epipolar lines in camera b of raw pixels of camera a.

    Parameters
    ----------
    uv_a_raw : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 3)
        ``(a, b, c)`` with ``a x + b y + c = 0`` in camera b's *corrected*
        pixels, normalised so ``a^2 + b^2 = 1`` (``|a x + b y + c|`` is then a
        distance in pixels).  Draw in raw pixels with ``cam_b.distort``.
    """
    xa = _homog(cam_a.correct(uv_a_raw))
    line = xa @ fundamental_matrix(cam_a, cam_b).T
    return line / np.hypot(line[..., 0], line[..., 1])[..., None]


def symmetric_epipolar_distance(cam_a: Camera, uv_a_raw, cam_b: Camera, uv_b_raw) -> np.ndarray:
    """Mean of the two point-to-epipolar-line distances of candidate matches, in pixels.

    ``0.5 * (d(x_b, F x_a) + d(x_a, F^T x_b))`` in corrected pixels.

    Parameters
    ----------
    uv_a_raw, uv_b_raw : array_like, shape (..., 2)
        Raw pixels in cameras a and b; broadcast against each other, so
        ``(N, 2)`` with ``(N, 2)`` gives N pair distances and ``(N, 1, 2)`` with
        ``(1, M, 2)`` gives the ``(N, M)`` matrix of all pairs.

    Returns
    -------
    ndarray, broadcast shape without the last axis
    """
    F = fundamental_matrix(cam_a, cam_b)
    xa = _homog(cam_a.correct(uv_a_raw))
    xb = _homog(cam_b.correct(uv_b_raw))
    la = xa @ F.T                  # lines in b
    lb = xb @ F                    # lines in a
    num = np.abs(np.sum(xb * la, axis=-1))
    da = num / np.hypot(la[..., 0], la[..., 1])
    db = num / np.hypot(lb[..., 0], lb[..., 1])
    return 0.5 * (da + db)


def centroid(cameras: Sequence[Camera]) -> np.ndarray:
    """Mean camera centre (world mm)."""
    return np.mean(np.stack([c.position for c in cameras]), axis=0)
