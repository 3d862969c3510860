"""Solve Calibration Brim [Manual] and per-frame camera solves from the brim.

Steps (the guide's "Solve calibration brim algorithm"):

1. One rigid solve of the whole rig from the brim correspondences, keeping the
   calibration's camera-to-camera placement: four separate PnP solves from a
   handful of clicked markers miss the camera centres by millimetres, while
   the rigid solve has 6 unknowns for every observation of all cameras.
2. Project the known brim; attach the nearest unused detection to every brim
   marker whose projection has exactly one detection near it.
3. Refine with all matched markers: the rig again, then each camera on its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..camera import Camera, matrix_to_quaternion
from ..commands import Command, CompoundCommand
from ..edits import AddPoints, SetCameraPoses, SetPointData
from ..errors import CaraError
from ..points import BRIM, SRC_DETECTION, SRC_NONE, ST_RECONSTRUCTED, ST_SINGLE
from ..disc_image import camera_offsets
from .nearest import nearest_with_clearance

#: RMS (px) above which the attached detections do not fit the brim.
FIT_TOLERANCE_PX = 6.0
#: Gate (px) around a projected brim marker for its detection, and the clearance
#: the next detection must keep for the match to be unambiguous.
MATCH_GATE_PX = 4.0
MATCH_CLEARANCE = 2.0
#: Fewest matched markers for a camera's own refinement (else it keeps the rig pose).
MIN_PER_CAMERA = 6


@dataclass
class BrimSolution:
    """Result of :func:`solve_brim`.

    Attributes
    ----------
    cameras : list of Camera
        Solved cameras (world = brim frame).
    det : ndarray (M, S) int
        Detection index matched to each brim marker in each camera (-1 none).
    uv : ndarray (M, S, 2)
        Raw pixels of the matches (NaN none).
    err : ndarray (M, S)
        Reprojection errors (px) of the matches (less their dots' perspective offsets).
    rms_rigid : float
        RMS error (px) of the rigid solve from the given correspondences.
    rms : float
        Final RMS error (px) over all matches.
    """

    cameras: list
    det: np.ndarray
    uv: np.ndarray
    err: np.ndarray
    rms_rigid: float
    rms: float


def _rigid_residual(cameras, markers, uv, obs):
    def fun(x):
        Q = Rotation.from_rotvec(x[:3]).as_matrix()
        Y = markers @ Q.T + x[3:]
        out = []
        for s, cam in enumerate(cameras):
            m = obs[:, s]
            if np.any(m):
                out.append((cam.project(Y[m]) - uv[m, s]).ravel())
        return np.nan_to_num(np.concatenate(out), nan=1e4)
    return fun


def _apply_rigid(cameras, x):
    """Cameras of the rig once the brim sits at ``Y = Q X + p`` in the calibration's frame."""
    Q = Rotation.from_rotvec(x[:3]).as_matrix()
    p = x[3:]
    return [c.with_pose(c.rotation @ Q, Q.T @ (c.position - p)) for c in cameras]


def _pnp_guess(cam: Camera, markers, uv):
    """Brim placement ``(rotvec, p)`` in the calibration frame from one camera's PnP."""
    import cv2

    pts = cam.correct(uv)
    flag = cv2.SOLVEPNP_IPPE if np.allclose(markers[:, 2], 0) else cv2.SOLVEPNP_EPNP
    try:
        ok, rvec, tvec = cv2.solvePnP(markers.astype(np.float64), pts.astype(np.float64), cam.K, None, flags=flag)
    except cv2.error:
        return None
    if not ok:
        return None
    Rp = cv2.Rodrigues(rvec)[0]
    Q = cam.rotation.T @ Rp
    p = cam.rotation.T @ tvec.ravel() + cam.position
    return np.concatenate([Rotation.from_matrix(Q).as_rotvec(), p])


def solve_rig(cameras, markers, uv):
    """Rigid solve of the whole rig (relative camera placement kept).

    Parameters
    ----------
    cameras : list of Camera
        Initial cameras; their relative placement is kept.
    markers : ndarray (M, 3)
    uv : ndarray (M, S, 2)
        Raw observations, NaN where none.

    Returns
    -------
    cameras : list of Camera
    rms : float
        RMS reprojection error (px).
    """
    obs = np.all(np.isfinite(uv), axis=-1)
    fun = _rigid_residual(cameras, markers, uv, obs)
    starts = [np.zeros(6)]
    for s, cam in enumerate(cameras):
        if np.count_nonzero(obs[:, s]) >= 4:
            g = _pnp_guess(cam, markers[obs[:, s]], uv[obs[:, s], s])
            if g is not None:
                starts.append(g)
    best = None
    for x0 in starts:
        sol = least_squares(fun, x0, method="lm", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    n = np.count_nonzero(obs)
    rms = float(np.sqrt(2 * best.cost / n))
    return _apply_rigid(cameras, best.x), rms


def refine_camera(cam: Camera, markers, uv) -> Camera:
    """One camera's pose refined on its matched markers (exact raw-pixel error)."""
    def fun(x):
        c = cam.with_pose(Rotation.from_rotvec(x[:3]).as_matrix() @ cam.rotation, cam.position + x[3:])
        return np.nan_to_num((c.project(markers) - uv).ravel(), nan=1e4)
    sol = least_squares(fun, np.zeros(6), method="lm", x_scale="jac")
    x = sol.x
    return cam.with_pose(Rotation.from_rotvec(x[:3]).as_matrix() @ cam.rotation, cam.position + x[3:])


def match_markers(cameras, markers, det_xy, used, known_det, gate=MATCH_GATE_PX, clearance=MATCH_CLEARANCE):
    """Attach unambiguous free detections to projected brim markers.

    Parameters
    ----------
    det_xy : list of ndarray (D_s, 2)
        Every camera's detections on the frame.
    used : list of ndarray (D_s,) bool
        Detections that belong to other points.
    known_det : ndarray (M, S) int
        Matches already made (kept as they are).

    Returns
    -------
    ndarray (M, S) int
    """
    det = known_det.copy()
    for s, cam in enumerate(cameras):
        xy = det_xy[s]
        if len(xy) == 0:
            continue
        free = ~used[s].copy()
        free[det[:, s][det[:, s] >= 0]] = False
        proj = cam.project(markers)
        d = np.linalg.norm(proj[:, None] - xy[None], axis=-1)
        d = np.where(np.isfinite(d), d, np.inf)
        # Clearance against every detection (used ones too): a crowded spot is ambiguous.
        best, bd, second = nearest_with_clearance(d, np.where(free[None], d, np.inf))
        # A detection claimed by two markers goes to neither.
        cand = (det[:, s] < 0) & (bd <= gate) & (second > clearance * gate)
        idx, counts = np.unique(best[cand], return_counts=True)
        dup = set(idx[counts > 1].tolist())
        for m in np.flatnonzero(cand):
            if int(best[m]) not in dup:
                det[m, s] = int(best[m])
    return det


def _centred(cameras, markers, radius, uv):
    """``uv`` less each brim dot's perspective offset under ``cameras``: where the dots' centres project."""
    if radius is None or not np.any(np.asarray(radius) > 0):
        return uv
    return uv - camera_offsets(cameras, markers, radius)


def solve_brim(cameras, markers, seed_uv, det_xy, used, seed_det, radius=None) -> BrimSolution:
    """The three steps of Solve Calibration Brim on arrays.

    Parameters
    ----------
    cameras : list of Camera
        Initial cameras (their relative placement is trusted).
    markers : ndarray (M, 3)
    seed_uv : ndarray (M, S, 2)
        Attached observations (NaN none).
    det_xy, used : per camera detections and their used mask (see :func:`match_markers`).
    seed_det : ndarray (M, S) int
        Detection indices of the attached observations (-1 none, or not a detection).
    radius : ndarray (M,), optional
        The dots' radii (mm, :attr:`.Brim.radius`).  Where known, each detection has its dot's
        perspective offset (:func:`~carapost.core.disc_image.disc_image_offsets`), from the cameras of the
        previous step, taken off before each solve after the first.

    Raises
    ------
    CaraError
        Fewer than 4 brim markers attached, or a brim that does not fit.
    """
    obs = np.all(np.isfinite(seed_uv), axis=-1)
    nm = int(np.count_nonzero(np.any(obs, axis=1)))
    if nm < 4 or np.count_nonzero(obs) < 6:
        raise CaraError(f"Solve Calibration Brim needs 4 or more brim markers attached to detections "
                        f"(found {nm} markers, {int(np.count_nonzero(obs))} observations)")
    cams, rms_rigid = solve_rig(cameras, markers, seed_uv)
    if not rms_rigid <= FIT_TOLERANCE_PX:
        raise CaraError(f"the calibration brim does not fit the attached detections: RMS reprojection error "
                        f"{rms_rigid:.1f} px after solving the rig (tolerance {FIT_TOLERANCE_PX:g} px); check "
                        "the brim definition and the brim correspondences")
    S = len(cameras)
    det = match_markers(cams, markers, det_xy, used, seed_det)
    uv = seed_uv.copy()
    for s in range(S):
        m = (det[:, s] >= 0) & ~obs[:, s]
        uv[m, s] = det_xy[s][det[m, s]]
    cams, _ = solve_rig(cams, markers, _centred(cams, markers, radius, uv))
    # Second pass: the better rig may reach markers the seeds' solve could not.
    det = match_markers(cams, markers, det_xy, used, det)
    for s in range(S):
        m = (det[:, s] >= 0) & ~np.all(np.isfinite(uv[:, s]), axis=-1)
        uv[m, s] = det_xy[s][det[m, s]]
    cams, _ = solve_rig(cams, markers, _centred(cams, markers, radius, uv))
    uv_o = _centred(cams, markers, radius, uv)
    out = []
    for s, cam in enumerate(cams):
        m = np.all(np.isfinite(uv[:, s]), axis=-1)
        out.append(refine_camera(cam, markers[m], uv_o[m, s]) if np.count_nonzero(m) >= MIN_PER_CAMERA else cam)
    err = np.stack([np.linalg.norm(c.project(markers) - uv_o[:, s], axis=-1) for s, c in enumerate(out)], axis=1)
    rms = float(np.sqrt(np.nanmean(err ** 2)))
    return BrimSolution(out, det, uv, err, rms_rigid, rms)


# ----------------------------------------------------------------------------- project level
class SetCalibrationPose(Command):
    """Replace the calibration (XCP) poses of the rig's cameras (seed-frame brim solve)."""

    def __init__(self, cameras, name: str = "Set Calibration Pose"):
        self.cameras = [c.copy() for c in cameras]
        self.name = name
        self._old = None

    def do(self, project) -> None:
        if project.rig is None:
            raise CaraError("no camera calibration is loaded (File > Import XCP)")
        self._old = list(project.rig.cameras)
        project.rig.cameras = [c.copy() for c in self.cameras]

    def undo(self, project) -> None:
        project.rig.cameras = self._old


def brim_points(project) -> dict[int, object]:
    """Brim points by brim marker index."""
    return {p.brim_index: p for p in project.points.values() if p.kind == BRIM and p.brim_index >= 0}


def _frame_inputs(project, frame):
    if project.rig is None:
        raise CaraError("no camera calibration is loaded: the cameras have no intrinsics (File > Import XCP)")
    if project.brim is None or len(project.brim) == 0:
        raise CaraError("no calibration brim is set (Process > Initialize Default Calibration Brim, "
                        "or File > Import Calibration Brim [svg])")
    S = project.sensor_count
    M = len(project.brim)
    bp = brim_points(project)
    seed_uv = np.full((M, S, 2), np.nan)
    seed_det = np.full((M, S), -1)
    for i, p in bp.items():
        if i >= M:
            continue
        for s in range(S):
            if p.src[frame, s] != SRC_NONE:
                seed_uv[i, s] = p.uv[frame, s]
                if p.src[frame, s] == SRC_DETECTION:
                    seed_det[i, s] = p.det[frame, s]
    det_xy, used = [], []
    for s in range(S):
        rec = project.detections[s].frame(frame)
        det_xy.append(np.column_stack([rec["x"], rec["y"]]).astype(float))
        u = np.zeros(len(rec), bool)
        for p in project.points.values():
            if p.kind != BRIM and p.src[frame, s] == SRC_DETECTION and 0 <= p.det[frame, s] < len(rec):
                u[p.det[frame, s]] = True
        used.append(u)
    return bp, seed_uv, seed_det, det_xy, used


def _solution_command(project, frame, sol: BrimSolution, bp, name, calibration: bool, markers=None):
    # ``markers``: a brim the compound command sets before this one (Initialize from ROM on a take without one).
    S = project.sensor_count
    markers = project.brim.markers if markers is None else markers
    new_points, updates = [], []
    next_id = project.next_point_id
    for m in range(len(markers)):
        has = np.all(np.isfinite(sol.uv[m]), axis=-1)
        if not np.any(has) and m not in bp:
            continue
        row = {"src": np.zeros((1, S), np.uint8), "det": np.full((1, S), -1, np.int32),
               "uv": np.full((1, S, 2), np.nan, np.float32), "score": np.full((1, S), np.nan, np.float16)}
        for s in np.flatnonzero(has):
            d = sol.det[m, s]
            row["src"][0, s] = SRC_DETECTION if d >= 0 else SRC_NONE
            row["det"][0, s] = d
            row["uv"][0, s] = sol.uv[m, s]
            if d >= 0:
                row["score"][0, s] = project.detections[s].frame(frame)[d]["score"]
        n = int(np.count_nonzero(has))
        row["pos"] = markers[m][None].astype(np.float32) if n else np.full((1, 3), np.nan, np.float32)
        row["status"] = np.array([ST_RECONSTRUCTED if n >= 2 else (ST_SINGLE if n else 0)], np.uint8)
        row["residual"] = np.array([np.sqrt(np.nanmean(sol.err[m][has] ** 2)) if n else np.nan], np.float16)
        if m in bp:
            updates.append((bp[m].id, frame, row))
        else:
            p = project.new_point(BRIM, brim_index=m, point_id=next_id)
            next_id += 1
            for k, v in row.items():
                p.arrays[k][frame:frame + 1] = v
            new_points.append(p)
    q = np.stack([matrix_to_quaternion(c.rotation) for c in sol.cameras])[:, None]
    pos = np.stack([c.position for c in sol.cameras])[:, None]
    cmds: list[Command] = []
    if new_points:
        cmds.append(AddPoints(new_points, name="Add Brim Points"))
    if updates:
        cmds.append(SetPointData(updates, name="Attach Brim Detections"))
    cmds.append(SetCameraPoses(frame, q, pos, np.ones((S, 1), bool)))
    if calibration:
        cmds.append(SetCalibrationPose(sol.cameras))
    cmd = CompoundCommand(name, cmds)
    matched = int(np.count_nonzero(np.any(sol.det >= 0, axis=1)))
    cmd.summary = (f"{name}: frame {frame}, {matched} brim markers matched, RMS reprojection error "
                   f"{sol.rms:.3f} px (rigid solve from the correspondences: {sol.rms_rigid:.2f} px)")
    cmd.solution = sol
    return cmd


def solve_calibration_brim(project, frame: int) -> Command:
    """Process > Solve Calibration Brim [Manual] on ``frame``.

    Starts from the calibration (XCP) poses; the result becomes the frame's
    poses and the rig's calibration pose.

    Returns
    -------
    Command
        Adds/updates one brim point per matched marker, sets the cameras of
        ``frame`` and the calibration pose.  ``command.solution`` holds the
        :class:`BrimSolution`, ``command.summary`` a line for the log.
    """
    frame = project.clamp_frame(frame)
    bp, seed_uv, seed_det, det_xy, used = _frame_inputs(project, frame)
    sol = solve_brim(project.rig.cameras, project.brim.markers, seed_uv, det_xy, used, seed_det,
                     project.brim.radius)
    return _solution_command(project, frame, sol, bp, "Solve Calibration Brim [Manual]", calibration=True)


def solve_frame_cameras(project, frame: int) -> Command:
    """Solve the cameras of ``frame`` from the brim points attached on it.

    Starts from the frame's current cameras (nearest solved frame); does not
    touch the calibration pose.  Same result layout as :func:`solve_calibration_brim`.
    """
    frame = project.clamp_frame(frame)
    bp, seed_uv, seed_det, det_xy, used = _frame_inputs(project, frame)
    sol = solve_brim(project.rig.cameras_at(frame), project.brim.markers, seed_uv, det_xy, used, seed_det,
                     project.brim.radius)
    return _solution_command(project, frame, sol, bp, "Solve Frame Cameras", calibration=False)
