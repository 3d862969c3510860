"""Bundle adjustment: camera extrinsics and 3D points from attached 2D data.

The solver is batched over frames: frames are independent given the fixed
intrinsics, so Bundle Sequence solves blocks of frames with the same array
code that Bundle Current Frame runs on a batch of one.

Method: Levenberg-Marquardt with analytic derivatives and the Schur
complement (points eliminated, the 6V x 6V camera system solved), robust
Huber weights (iteratively reweighted) at about a pixel so that a mismatched
detection cannot drag the solution.  Residuals are corrected-pixel errors
whitened by the inverse Jacobian of the lens correction at the observation:
to first order the raw-pixel error the detector measured, without inverting
the distortion every iteration.

Gauge: brim points are held at their known brim positions (the brim defines
the world frame).  A frame with no brim point fixes its first camera and the
distance from it to the next camera (the scale).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brim import brim_image_offsets
from ..camera import matrix_to_quaternion
from ..commands import CompoundCommand
from ..edits import SetCameraPoses, SetPointData
from ..errors import CaraError
from ..points import BRIM, SRC_NONE, ST_RECONSTRUCTED, ST_SINGLE
from ..progress import Progress

#: Huber threshold (px): residuals above it count linearly.
HUBER_PX = 1.0
#: Frames per block of Bundle Sequence (bounds memory: ~25 MB per block of 160 points).
SEQUENCE_BLOCK = 128


# ----------------------------------------------------------------------------- batched core
def _rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors ``w`` (..., 3)."""
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    small = th < 1e-12
    ths = np.where(small, 1.0, th)
    k = w / ths[..., 0]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    I = np.eye(3)
    Rm = I + np.sin(ths) * K + (1 - np.cos(ths)) * (K @ K)
    return np.where(small, I, Rm)


def _intrinsics(cameras) -> np.ndarray:
    return np.array([[c.focal_length, c.focal_length / c.aspect, c.skew,
                      c.principal_point[0], c.principal_point[1]] for c in cameras])


def whiten(cameras, uv: np.ndarray):
    """Corrected observations and whitening matrices of raw observations.

    Parameters
    ----------
    cameras : sequence of Camera (V)
        Only the intrinsics are used.
    uv : ndarray (..., N, V, 2)
        Raw pixels, NaN where missing.

    Returns
    -------
    uv_c : ndarray (..., N, V, 2)
        Corrected pixels (0 where missing).
    W : ndarray (..., N, V, 2, 2)
        Inverse Jacobian of the correction at each observation (identity where missing).
    valid : ndarray (..., N, V) bool
    """
    valid = np.all(np.isfinite(uv), axis=-1)
    uv0 = np.where(valid[..., None], uv, 0.0)
    uv_c = np.empty_like(uv0)
    J = np.empty(uv0.shape + (2,))
    for v, cam in enumerate(cameras):
        uv_c[..., v, :] = cam.correct(uv0[..., v, :])
        J[..., v, :, :] = cam.correct_jacobian(uv0[..., v, :])
    det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    valid &= np.isfinite(det) & (np.abs(det) > 1e-12) & np.all(np.isfinite(uv_c), axis=-1)
    det = np.where(valid, det, 1.0)
    W = np.empty_like(J)
    W[..., 0, 0] = np.where(valid, J[..., 1, 1] / det, 1.0)
    W[..., 1, 1] = np.where(valid, J[..., 0, 0] / det, 1.0)
    W[..., 0, 1] = np.where(valid, -J[..., 0, 1] / det, 0.0)
    W[..., 1, 0] = np.where(valid, -J[..., 1, 0] / det, 0.0)
    uv_c = np.where(valid[..., None], uv_c, 0.0)
    return uv_c, W, valid


def _residuals(R, C, intr, X, uv_c, W, valid):
    """Whitened residuals (B,N,V,2), camera coordinates and front mask."""
    Xc = ((X[:, :, None, :] - C[:, None, :, :])[..., None, :] @ np.swapaxes(R, -1, -2)[:, None])[..., 0, :]
    z = Xc[..., 2]
    front = z > 1e-9
    zi = 1.0 / np.where(front, z, 1.0)
    x, y = Xc[..., 0] * zi, Xc[..., 1] * zi
    f, fa, k, xpp, ypp = (intr[:, i] for i in range(5))
    e = np.stack([f * x + k * y + xpp, fa * y + ypp], axis=-1) - uv_c
    r = (W @ e[..., None])[..., 0]
    r = np.where(valid[..., None], r, 0.0)
    return r, Xc, zi, x, y, front


def _robust_cost(r, valid, front, delta):
    e = np.sqrt(np.sum(r * r, axis=-1))
    rho = np.where(e <= delta, e * e, 2 * delta * e - delta * delta)
    cost = np.sum(np.where(valid, rho, 0.0), axis=(1, 2))
    behind = np.any(valid & ~front, axis=(1, 2))
    return np.where(behind, np.inf, cost), e


def bundle_batch(R, C, intr, X, point_free, uv_c, W, valid, fix_camera=None, iterations: int = 15,
                 huber: float = HUBER_PX, tol: float = 1e-7):
    """Bundle-adjust a batch of independent frames.

    Parameters
    ----------
    R : ndarray (B, V, 3, 3)
        World-to-camera rotations (initial).
    C : ndarray (B, V, 3)
        Camera centres, mm (initial).
    intr : ndarray (V, 5)
        ``f, f/aspect, skew, xpp, ypp`` of each camera.
    X : ndarray (B, N, 3)
        Points (initial); rows of unused points may hold anything finite.
    point_free : ndarray (B, N) bool
        Points that are estimated; the others are held fixed (brim points) or unused.
    uv_c, W, valid : from :func:`whiten`, shapes (B,N,V,2), (B,N,V,2,2), (B,N,V)
    fix_camera : ndarray (B, V) bool, optional
        Cameras held fixed.
    iterations : int
        Most LM iterations.
    huber : float
        Huber threshold in pixels.

    Returns
    -------
    R, C, X : the refined values
    err : ndarray (B, N, V)
        Per-observation reprojection errors (px, first order), NaN where not observed.
    """
    R, C, X = R.copy(), C.copy(), X.copy()
    B, N, V = valid.shape
    fixc = np.zeros((B, V), bool) if fix_camera is None else fix_camera.copy()
    # A camera seeing fewer than 3 points cannot be solved: hold it.
    fixc |= np.count_nonzero(valid, axis=1) < 3
    free = point_free & (np.count_nonzero(valid, axis=2) >= 2)
    # The scale gauge of frames without fixed points: keep |C1 - C0| (camera 0 held).
    anchored = np.any(~point_free & np.any(valid, axis=2), axis=1)
    scale_frames = ~anchored & (V > 1)
    fixc[scale_frames, 0] = True
    d0 = np.linalg.norm(C[:, 1] - C[:, 0], axis=-1) if V > 1 else np.zeros(B)
    f, fa, k = intr[:, 0], intr[:, 1], intr[:, 2]
    lam = np.full(B, 1e-3)
    r, Xc, zi, x, y, front = _residuals(R, C, intr, X, uv_c, W, valid)
    cost, e = _robust_cost(r, valid, front, huber)
    active = np.ones(B, bool)
    I3 = np.eye(3)
    for _ in range(iterations):
        if not np.any(active):
            break
        wgt = np.where(valid, np.where(e <= huber, 1.0, huber / np.maximum(e, 1e-12)), 0.0)
        # d(corrected uv)/d(camera coords): A (B,N,V,2,3), then whitened.
        A = np.zeros(valid.shape + (2, 3))
        A[..., 0, 0] = f * zi
        A[..., 0, 1] = k * zi
        A[..., 0, 2] = -(f * x + k * y) * zi
        A[..., 1, 1] = fa * zi
        A[..., 1, 2] = -fa * y * zi
        WA = W @ A
        JX = WA @ R[:, None]                   # d r / d X
        # Left perturbation R <- exp([w]) R: dXc/dw = -[Xc]x, dXc/dC = -R.
        S = np.zeros(valid.shape + (3, 3))
        S[..., 0, 1], S[..., 0, 2] = -Xc[..., 2], Xc[..., 1]
        S[..., 1, 0], S[..., 1, 2] = Xc[..., 2], -Xc[..., 0]
        S[..., 2, 0], S[..., 2, 1] = -Xc[..., 1], Xc[..., 0]
        Jw = -(WA @ S)
        Jc = np.concatenate([Jw, -JX], axis=-1)                      # (B,N,V,2,6)
        JXf = JX * free[:, :, None, None, None]
        sw = wgt[..., None, None]
        JcT = np.swapaxes(Jc, -1, -2) * sw
        Hcc = (JcT @ Jc).sum(axis=1)                 # (B,V,6,6)
        gc = (JcT @ r[..., None])[..., 0].sum(axis=1)
        Hcp = JcT @ JXf               # (B,N,V,6,3)
        JXT = np.swapaxes(JXf, -1, -2) * sw
        Hpp = (JXT @ JXf).sum(axis=2)
        gp = (JXT @ r[..., None])[..., 0].sum(axis=2)
        # LM damping on the diagonals.
        dpp = np.diagonal(Hpp, axis1=-2, axis2=-1)
        Hpp = Hpp + (lam[:, None, None] * dpp + 1e-9)[..., None] * I3
        Hpp = np.where(free[..., None, None], Hpp, I3)
        Hpp_inv = np.linalg.inv(Hpp)
        Hpp_inv = np.where(free[..., None, None], Hpp_inv, 0.0)
        dcc = np.diagonal(Hcc, axis1=-2, axis2=-1)
        Hcc = Hcc + (lam[:, None, None] * dcc + 1e-9)[..., None] * np.eye(6)
        # Scale gauge residual: w_s (|C1 - C0| - d0), derivative along the baseline.
        if np.any(scale_frames):
            bl = C[:, 1] - C[:, 0]
            dist = np.linalg.norm(bl, axis=-1)
            u = bl / np.maximum(dist, 1e-12)[:, None]
            ws = 1e6 * scale_frames
            Hcc[:, 1, 3:, 3:] += ws[:, None, None] * u[:, :, None] * u[:, None, :]
            gc[:, 1, 3:] += (ws * (dist - d0))[:, None] * u
        T = Hcp @ Hpp_inv[:, :, None]              # (B,N,V,6,3)
        T2 = T.transpose(0, 2, 3, 1, 4).reshape(B, V * 6, N * 3)
        Hcp2 = Hcp.transpose(0, 1, 4, 2, 3).reshape(B, N * 3, V * 6)
        Sm = -(T2 @ Hcp2)
        idx = np.arange(V)
        Sm = Sm.reshape(B, V, 6, V, 6)
        Sm[:, idx, :, idx, :] += Hcc.transpose(1, 0, 2, 3)
        Sm = Sm.reshape(B, V * 6, V * 6)
        rhs = gc.reshape(B, V * 6) - (T @ gp[:, :, None, :, None])[..., 0].sum(axis=1).reshape(B, V * 6)
        fmask = np.repeat(fixc, 6, axis=1)                            # (B, 6V)
        Sm = np.where(fmask[:, :, None] | fmask[:, None, :], 0.0, Sm)
        Sm[:, np.arange(6 * V), np.arange(6 * V)] += fmask
        rhs = np.where(fmask, 0.0, rhs)
        try:
            dc = -np.linalg.solve(Sm, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            dc = -np.stack([np.linalg.lstsq(s, g, rcond=None)[0] for s, g in zip(Sm, rhs)])
        dc = np.where(active[:, None], dc, 0.0).reshape(B, V, 6)
        dp = -(Hpp_inv @ (gp + (np.swapaxes(Hcp, -1, -2) @ dc[:, None, :, :, None])[..., 0].sum(axis=2))[..., None])[..., 0]
        dp = np.where(active[:, None, None], dp, 0.0)
        Rn = _rodrigues(dc[..., :3]) @ R
        Cn = C + dc[..., 3:]
        Xn = X + dp
        rn, Xcn, zin, xn, yn, frontn = _residuals(Rn, Cn, intr, Xn, uv_c, W, valid)
        costn, en = _robust_cost(rn, valid, frontn, huber)
        better = active & (costn <= cost)
        b1, b2, b3 = better[:, None, None, None], better[:, None, None], better[:, None, None]
        R = np.where(b1, Rn, R)
        C, X = np.where(b2, Cn, C), np.where(b3, Xn, X)
        r, Xc = np.where(b1, rn, r), np.where(b1, Xcn, Xc)
        zi, x, y = (np.where(better[:, None, None], a, b) for a, b in ((zin, zi), (xn, x), (yn, y)))
        e = np.where(better[:, None, None], en, e)
        front = np.where(better[:, None, None], frontn, front)
        rel = (cost - costn) / np.maximum(cost, 1e-30)
        step = np.maximum(np.abs(dc).max(axis=(1, 2)), np.abs(dp).max(axis=(1, 2)))
        cost = np.where(better, costn, cost)
        lam = np.where(better, lam * 0.2, lam * 10.0)
        # Converged frames stop; the others carry on (and their damping grows on failure).
        # A step that changes the cost by less than 1e-6 of it (accepted or not) means
        # convergence: the remaining change is far below the detection noise.
        active &= ~((step < tol) | (np.abs(rel) < 1e-6) | (lam > 1e8))
    err = np.where(valid, e, np.nan)
    return R, C, X, err


# ----------------------------------------------------------------------------- frame data
@dataclass
class FrameData:
    """The points of one frame that a bundle uses.

    Attributes
    ----------
    ids : list of int
        Point ids, in row order.
    X : ndarray (N, 3)
        Initial positions (brim markers for brim points).
    fixed : ndarray (N,) bool
        Brim points (held at their known positions).
    uv : ndarray (N, S, 2)
        Attached raw observations, NaN where none.
    """

    ids: list
    X: np.ndarray
    fixed: np.ndarray
    uv: np.ndarray


def gather_frame(project, frame: int, cameras=None) -> FrameData:
    """Collect the points of ``frame`` with 2D data (brim points at their markers, their detections less
    their dots' perspective offsets under ``cameras``, by default the frame's)."""
    from ..camera import triangulate_many

    S = project.sensor_count
    ids, Xs, fixed, uvs, dots = [], [], [], [], []
    brim = project.brim
    for p in project.points.values():
        src = p.src[frame]
        uv = np.where((src != SRC_NONE)[:, None], p.uv[frame].astype(float), np.nan)
        n = np.count_nonzero(np.all(np.isfinite(uv), axis=1))
        is_brim = p.kind == BRIM and brim is not None and 0 <= p.brim_index < len(brim)
        if n == 0 or (n < 2 and not is_brim):
            continue
        ids.append(p.id)
        fixed.append(is_brim)
        Xs.append(brim.markers[p.brim_index] if is_brim else p.pos[frame].astype(float))
        uvs.append(uv)
        if is_brim:
            dots.append(p.brim_index)
    X = np.array(Xs, float).reshape(-1, 3)
    uv = np.array(uvs, float).reshape(-1, S, 2)
    fixed = np.array(fixed, bool)
    cams = cameras if cameras is not None else project.rig.cameras_at(frame)
    if dots:
        # The brim's dots are held at their centres: their detections, at their images' centres, less the
        # perspective offset between the two.
        uv[fixed] -= brim_image_offsets(cams, brim, dots)
    need = ~fixed & ~np.all(np.isfinite(X), axis=1)
    if np.any(need):
        X[need] = triangulate_many(cams, uv[need])
    keep = np.all(np.isfinite(X), axis=1)
    return FrameData([i for i, k in zip(ids, keep) if k], X[keep], fixed[keep], uv[keep])


def bundle_cameras(cameras, X, fixed, uv, huber: float = HUBER_PX, iterations: int = 15):
    """Bundle one frame.

    Parameters
    ----------
    cameras : list of Camera (V)
    X : ndarray (N, 3)
    fixed : ndarray (N,) bool
    uv : ndarray (N, V, 2) raw pixels, NaN missing

    Returns
    -------
    cameras : list of Camera
        With refined poses.
    X : ndarray (N, 3)
    err : ndarray (N, V)
        Reprojection errors in raw pixels (exact), NaN where not observed.
    """
    R = np.stack([c.rotation for c in cameras])[None]
    C = np.stack([c.position for c in cameras])[None]
    uv_c, W, valid = whiten(cameras, uv[None])
    R, C, Xo, _ = bundle_batch(R, C, _intrinsics(cameras), X[None].astype(float), ~fixed[None], uv_c, W, valid,
                               iterations=iterations, huber=huber)
    cams = [c.with_pose(R[0, v], C[0, v]) for v, c in enumerate(cameras)]
    Xo = Xo[0]
    proj = np.stack([c.project(Xo) for c in cams], axis=1)
    err = np.linalg.norm(proj - uv, axis=-1)
    return cams, Xo, err


def _require_rig(project):
    if project.rig is None:
        raise CaraError("no camera calibration is loaded: the cameras have no intrinsics (File > Import XCP)")


def _point_updates(project, frame, ids, X, err, fixed, start=None):
    upd = []
    for i, pid in enumerate(ids):
        e = err[i]
        n = np.count_nonzero(np.isfinite(e))
        res = float(np.sqrt(np.nanmean(e ** 2))) if n else np.nan
        status = ST_RECONSTRUCTED if (n >= 2 or fixed[i]) else ST_SINGLE
        upd.append((pid, frame, {"pos": X[i][None].astype(np.float32), "status": np.array([status], np.uint8),
                                 "residual": np.array([res], np.float16)}))
    return upd


def bundle_current_frame(project, frame: int, name: str = "Bundle Current Frame [Unconstrained]"):
    """Process > Bundle Current Frame [Unconstrained].

    Returns
    -------
    (Command, dict)
        The command (new camera poses of ``frame`` and new point positions) and a
        report: ``rms_px`` (final RMS reprojection error), ``points``, ``observations``.

    Raises
    ------
    CaraError
        Without cameras, or with fewer than 3 points seen on the frame.
    """
    _require_rig(project)
    frame = project.clamp_frame(frame)
    cams = project.rig.cameras_at(frame)
    data = gather_frame(project, frame, cams)
    if len(data.ids) < 3:
        raise CaraError(f"Bundle Current Frame needs 3 or more points with 2D data on frame {frame} "
                        f"(found {len(data.ids)})")
    new_cams, X, err = bundle_cameras(cams, data.X, data.fixed, data.uv)
    X[data.fixed] = data.X[data.fixed]
    q = np.stack([matrix_to_quaternion(c.rotation) for c in new_cams])[:, None]
    pos = np.stack([c.position for c in new_cams])[:, None]
    cmds = [SetCameraPoses(frame, q, pos, np.ones((len(cams), 1), bool), name="Set Camera Poses"),
            SetPointData(_point_updates(project, frame, data.ids, X, err, data.fixed), name="Set Points")]
    rms = float(np.sqrt(np.nanmean(err ** 2))) if np.any(np.isfinite(err)) else float("nan")
    report = {"rms_px": rms, "points": len(data.ids), "observations": int(np.count_nonzero(np.isfinite(err)))}
    cmd = CompoundCommand(name, cmds)
    cmd.summary = f"{name}: frame {frame}, {len(data.ids)} points, RMS reprojection error {rms:.3f} px"
    return cmd, report


def bundle_sequence(project, start: int | None = None, end: int | None = None, progress: Progress | None = None,
                    name: str = "Bundle Sequence [Unconstrained]"):
    """Process > Bundle Sequence [Unconstrained]: every frame of the range bundled on its own.

    Frames are independent given the fixed intrinsics; blocks of frames are
    solved together by :func:`bundle_batch`.

    Returns
    -------
    (Command, dict)
        Report: ``rms_px`` over all observations, ``frames`` solved.
    """
    _require_rig(project)
    start = 0 if start is None else start
    end = project.frame_count - 1 if end is None else end
    start, end = project.check_range(start, end)
    progress = progress or Progress()
    S = project.sensor_count
    base = project.rig.cameras
    pts = list(project.points.values())
    brim = project.brim
    is_brim = np.array([p.kind == BRIM and brim is not None and 0 <= p.brim_index < len(brim) for p in pts], bool)
    markers = np.array([brim.markers[p.brim_index] if b else np.zeros(3) for p, b in zip(pts, is_brim)]).reshape(-1, 3)
    brim_idx = np.array([p.brim_index for p, b in zip(pts, is_brim) if b], int)
    brim_r = brim.radius[brim_idx] if brim is not None else np.zeros(0)
    n = end - start + 1
    quat = project.rig.quat[:, start:end + 1].copy()
    cpos = project.rig.position[:, start:end + 1].copy()
    solved = project.rig.solved[:, start:end + 1].copy()
    pos_out = np.stack([p.pos[start:end + 1] for p in pts], axis=1) if pts else np.zeros((n, 0, 3), np.float32)
    res_out = np.stack([p.residual[start:end + 1] for p in pts], axis=1) if pts else np.zeros((n, 0), np.float16)
    st_out = np.stack([p.status[start:end + 1] for p in pts], axis=1) if pts else np.zeros((n, 0), np.uint8)
    intr = _intrinsics(base)
    sq_sum, count, done_frames = 0.0, 0, 0
    progress.start(n, name)
    from ..camera import quaternion_to_matrix, triangulate_many

    for b0 in range(0, n, SEQUENCE_BLOCK):
        b1 = min(n, b0 + SEQUENCE_BLOCK)
        fr = slice(start + b0, start + b1)
        uv = np.stack([np.where((p.src[fr] != SRC_NONE)[..., None], p.uv[fr].astype(float), np.nan) for p in pts],
                      axis=1) if pts else np.zeros((b1 - b0, 0, S, 2))
        X = pos_out[b0:b1].astype(float)
        X[:, is_brim] = markers[is_brim]
        cams_src = [[project.rig.source_frame(s, f) for s in range(S)] for f in range(start + b0, start + b1)]
        R = np.empty((b1 - b0, S, 3, 3))
        C = np.empty((b1 - b0, S, 3))
        for i, row in enumerate(cams_src):
            for s, sf in enumerate(row):
                if sf < 0:
                    R[i, s], C[i, s] = base[s].rotation, base[s].position
                else:
                    R[i, s] = quaternion_to_matrix(project.rig.quat[s, sf])
                    C[i, s] = project.rig.position[s, sf]
        if np.any(brim_r > 0):
            for i in range(b1 - b0):
                uv[i, is_brim] -= brim_image_offsets([base[s].with_pose(R[i, s], C[i, s]) for s in range(S)],
                                                     brim, brim_idx)
        nobs = np.count_nonzero(np.all(np.isfinite(uv), axis=-1), axis=2)
        usable = (nobs >= 2) | (is_brim[None] & (nobs >= 1))
        # Points without a position but with 2+ views start from a triangulation.
        need = usable & ~is_brim[None] & ~np.all(np.isfinite(X), axis=-1)
        for i in np.flatnonzero(np.any(need, axis=1)):
            rows = np.flatnonzero(need[i])
            cams = [base[s].with_pose(R[i, s], C[i, s]) for s in range(S)]
            X[i, rows] = triangulate_many(cams, uv[i, rows])
        usable &= np.all(np.isfinite(X), axis=-1)
        X = np.where(usable[..., None], X, 0.0)
        uvm = np.where(usable[..., None, None], uv, np.nan)
        uv_c, W, valid = whiten(base, uvm)
        frame_ok = np.count_nonzero(np.any(valid, axis=2), axis=1) >= 3
        R, C, X, err = bundle_batch(R, C, intr, X, usable & ~is_brim[None], uv_c, W, valid)
        for i in np.flatnonzero(frame_ok):
            quat[:, b0 + i] = matrix_to_quaternion(R[i])
            cpos[:, b0 + i] = C[i]
            solved[:, b0 + i] = True
        ok = usable & frame_ok[:, None]
        e2 = np.where(np.isfinite(err), err ** 2, 0.0)
        cnt = np.count_nonzero(np.isfinite(err), axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            res = np.sqrt(e2.sum(axis=2) / cnt)
        X[:, is_brim] = markers[is_brim]
        pos_out[b0:b1] = np.where(ok[..., None], X, pos_out[b0:b1])
        res_out[b0:b1] = np.where(ok, res, res_out[b0:b1])
        st_out[b0:b1] = np.where(ok, np.where((cnt >= 2) | is_brim[None], ST_RECONSTRUCTED, ST_SINGLE), st_out[b0:b1])
        sq_sum += float(e2[ok].sum())
        count += int(cnt[ok].sum())
        done_frames += int(frame_ok.sum())
        progress.step(b1 - b0)
    rms = float(np.sqrt(sq_sum / count)) if count else float("nan")
    updates = [(p.id, start, {"pos": pos_out[:, j].astype(np.float32), "residual": res_out[:, j].astype(np.float16),
                              "status": st_out[:, j]}) for j, p in enumerate(pts)]
    cmd = CompoundCommand(name, [SetCameraPoses(start, quat, cpos, solved, name="Set Camera Poses"),
                                 SetPointData(updates, name="Set Points")])
    cmd.summary = f"{name}: {done_frames} frames, RMS reprojection error {rms:.3f} px"
    return cmd, {"rms_px": rms, "frames": done_frames}
