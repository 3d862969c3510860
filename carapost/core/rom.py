"""Initialize from ROM on arrays: the ROM frame, brim matching, camera and face alignment.

A ROM (range of motion) take of the same actor and marker set holds, on its
ROM frame, cameras, brim markers and labelled face points.  The functions here
compute, without touching any project, what :mod:`carapost.core.rom_ops` turns
into commands:

- :func:`rom_frame`: the ROM frame as arrays, after the alignments the ROM
  Tools solved (a rigid motion of the ROM's camera rig and of its face);
- :func:`match_brim` and :func:`robust_rig_fit`: the ROM brim projected with
  the ROM cameras and matched to this take's detections within the ROM Brim
  Point Tracking Distance, with the tracker's candidate search and one-to-one
  choice (:mod:`carapost.core.tracking.assign`), then the rigid rig solve of
  :mod:`carapost.core.calib.brim_solve` with mismatches dropped;
- :func:`solve_camera_pnp`, :func:`rig_motion` and :func:`solve_face_alignment`:
  the ROM Tools' solves from 2D-to-ROM correspondences.

Rigid motions are 4 x 4 matrices acting on world points (``X' = T X``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from .calib.brim_solve import FIT_TOLERANCE_PX, _apply_rigid, _rigid_residual, solve_rig
from .camera import Camera
from .errors import CaraError
from .points import BRIM, FACE, SRC_DETECTION, ST_NONE
from .tracking.assign import candidates, mutual_best

#: A brim match is accepted when the next candidate is this many times farther (the tracker's ratio test).
BRIM_RATIO = 2.0
#: Observations farther than this multiple of the median error (and of the fit tolerance) from the
#: rigid solve are mismatches.
OUTLIER_FACTOR = 3.0
#: Fewest brim markers matched for the rigid solve.
MIN_BRIM_MARKERS = 4
#: Displacements closer than this (px) vote together for a camera's image shift.
SHIFT_BANDWIDTH_PX = 4.0
#: A projected brim marker "lands on" a detection this close (px): how well a camera pose fits a frame.
LANDING_PX = 5.0
#: The ROM face is tracked again from where the first pass found it when it sat this far off (mm, largest
#: displacement of its points by the rigid motion): closer, the first pass's candidates were not confused.
FACE_REALIGN_MM = 1.0


def identity() -> np.ndarray:
    """The 4 x 4 identity motion."""
    return np.eye(4)


def motion(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The 4 x 4 motion ``X -> R X + t``."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def apply_motion(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Points ``X`` (N, 3) moved by ``T``."""
    X = np.asarray(X, float).reshape(-1, 3)
    return X @ T[:3, :3].T + T[:3, 3]


def move_cameras(cameras, T: np.ndarray) -> list[Camera]:
    """Cameras carried rigidly by the world motion ``T`` (their relative placement is kept)."""
    Q, t = T[:3, :3], T[:3, 3]
    return [c.with_pose(c.rotation @ Q.T, Q @ c.position + t) for c in cameras]


def rig_motion(old: Camera, new: Camera) -> np.ndarray:
    """The world motion that carries camera ``old`` onto ``new`` (the rest of the rig follows it)."""
    Q = new.rotation.T @ old.rotation
    return motion(Q, new.position - Q @ old.position)


@dataclass
class RomFrame:
    """The ROM frame as arrays.

    Attributes
    ----------
    ids : list of int
        ROM point ids of the face points present on the frame (row order).
    labels : list of str
    X : ndarray (N, 3)
        Their positions (world = brim frame, mm), face alignment applied.
    size : ndarray (N, S, 2)
        Blob (major, minor) of their attached detections (NaN none).
    brim_ids : dict
        ROM point id of each brim marker index that has a ROM brim point.
    markers : ndarray (B, 3)
        The ROM's brim.
    cameras : list of Camera
        The ROM frame's cameras, rig alignment applied.
    """

    ids: list
    labels: list
    X: np.ndarray
    size: np.ndarray
    brim_ids: dict
    markers: np.ndarray
    cameras: list


def rom_frame(rom, frame: int, rig_T: np.ndarray | None = None, face_T: np.ndarray | None = None,
              cam_T=None) -> RomFrame:
    """Read ``frame`` of the ROM project ``rom`` (see :class:`RomFrame`).

    ``rig_T`` moves every camera, then ``cam_T`` (one motion per camera, or None) each camera on its own.

    Raises
    ------
    CaraError
        When the frame is outside the ROM or the ROM has no cameras or brim.
    """
    if not 0 <= frame < rom.frame_count:
        raise CaraError(f"the ROM Frame Index {frame} is outside the ROM take (frames 0-{rom.frame_count - 1})")
    if rom.rig is None:
        raise CaraError("the ROM take has no cameras: calibrate and initialise it first")
    if rom.brim is None or len(rom.brim) == 0:
        raise CaraError("the ROM take has no calibration brim")
    S = rom.sensor_count
    face = [p for p in rom.points.values() if p.kind == FACE and p.status[frame] != ST_NONE
            and np.all(np.isfinite(p.pos[frame]))]
    X = np.array([p.pos[frame] for p in face], float).reshape(-1, 3)
    size = np.full((len(face), S, 2), np.nan)
    for s in range(S):
        rec = rom.detections[s].frame(frame)
        for i, p in enumerate(face):
            d = p.det[frame, s]
            if p.src[frame, s] == SRC_DETECTION and 0 <= d < len(rec):
                size[i, s] = (rec[d]["major"], rec[d]["minor"])
    brim_ids = {p.brim_index: p.id for p in rom.points.values()
                if p.kind == BRIM and 0 <= p.brim_index < len(rom.brim)}
    cams = rom.rig.cameras_at(frame)
    if rig_T is not None:
        cams = move_cameras(cams, rig_T)
    if cam_T is not None:
        cams = [move_cameras([c], T)[0] for c, T in zip(cams, cam_T)]
    if face_T is not None:
        X = apply_motion(face_T, X)
    return RomFrame([p.id for p in face], [p.label for p in face], X, size, brim_ids,
                    np.asarray(rom.brim.markers, float), cams)


def rom_point_position(rom, frame: int, pid: int, face_T: np.ndarray | None = None) -> np.ndarray:
    """World position of ROM point ``pid`` on the ROM frame (a brim point: its marker)."""
    try:
        p = rom.points[pid]
    except KeyError:
        raise CaraError(f"the ROM has no point {pid}") from None
    if p.kind == BRIM and rom.brim is not None and 0 <= p.brim_index < len(rom.brim):
        return np.asarray(rom.brim.markers[p.brim_index], float)
    if p.status[frame] == ST_NONE or not np.all(np.isfinite(p.pos[frame])):
        raise CaraError(f"ROM point {p.name} has no 3D position on the ROM frame {frame}")
    X = np.asarray(p.pos[frame], float)
    return apply_motion(face_T, X)[0] if face_T is not None else X


def project_all(cameras, X: np.ndarray) -> np.ndarray:
    """Raw pixels ``(N, S, 2)`` of world points in every camera (NaN behind one)."""
    X = np.asarray(X, float).reshape(-1, 3)
    if len(X) == 0:
        return np.zeros((0, len(cameras), 2))
    return np.stack([c.project(X) for c in cameras], axis=1)


# ----------------------------------------------------------------------------- brim
def image_shift(pred: np.ndarray, xy: np.ndarray, radius: float) -> np.ndarray:
    """The commonest displacement from predicted to detected positions, among pairs within ``radius``.

    When a rig has moved, the projections of a rigid object all slide by
    about the same amount in an image: the displacements of the true pairs
    pile up while the others scatter.  Returns ``(0, 0)`` without a clear mode.
    """
    ok = np.all(np.isfinite(pred), axis=1)
    if len(xy) == 0 or np.count_nonzero(ok) < MIN_BRIM_MARKERS:
        return np.zeros(2)
    near = cKDTree(xy).query_ball_point(pred[ok], float(radius))
    v = np.array([xy[j] - p for p, js in zip(pred[ok], near) for j in js]).reshape(-1, 2)
    if len(v) < MIN_BRIM_MARKERS:
        return np.zeros(2)
    counts = cKDTree(v).query_ball_point(v, SHIFT_BANDWIDTH_PX, return_length=True)
    best = int(np.argmax(counts))
    if counts[best] < MIN_BRIM_MARKERS:
        return np.zeros(2)
    return v[np.linalg.norm(v - v[best], axis=1) <= SHIFT_BANDWIDTH_PX].mean(axis=0)


def match_brim(cameras, markers: np.ndarray, det_xy: list, used: list, radius: float):
    """Match projected brim markers to detections within ``radius`` pixels.

    Each camera's projections first slide by their commonest displacement to
    the detections within ``radius`` (:func:`image_shift`); then the tracker's
    choice: the nearest free detections of each projection
    (:func:`~carapost.core.tracking.assign.candidates`), kept when the next one
    is :data:`BRIM_RATIO` times farther, one detection per marker and marker
    per detection (:func:`~carapost.core.tracking.assign.mutual_best`).

    Parameters
    ----------
    cameras : list of Camera
    markers : ndarray (B, 3)
    det_xy : list of ndarray (D_s, 2)
        Raw pixels of each camera's detections.
    used : list of ndarray (D_s,) bool
        Detections other points hold.
    radius : float
        ROM Brim Point Tracking Distance (px).

    Returns
    -------
    uv : ndarray (B, S, 2)
        Matched raw pixels, NaN none.
    det : ndarray (B, S) int
        Matched detection indices, -1 none.
    """
    B, S = len(markers), len(cameras)
    uv = np.full((B, S, 2), np.nan)
    det = np.full((B, S), -1)
    proj = project_all(cameras, markers)
    for s in range(S):
        xy = np.asarray(det_xy[s], float).reshape(-1, 2)
        if len(xy) == 0:
            continue
        free = ~np.asarray(used[s], bool)
        pred = proj[:, s] + image_shift(proj[:, s], xy[free], radius)
        idx, dist = candidates(cKDTree(xy), free, pred, np.full(B, float(radius)), k=2)
        ok = (idx[:, 0] >= 0) & (dist[:, 1] >= BRIM_RATIO * dist[:, 0])
        rows = np.flatnonzero(ok)
        acc = mutual_best(rows, idx[rows, 0], dist[rows, 0], B, len(xy))
        rows = rows[acc]
        det[rows, s] = idx[rows, 0]
        uv[rows, s] = xy[idx[rows, 0]]
    return uv, det


def robust_rig_fit(cameras, markers: np.ndarray, uv: np.ndarray, det: np.ndarray, rounds: int = 4):
    """The rigid rig solve on matched brim markers, dropping mismatches until the rest fit.

    A first solve with a Cauchy loss (mismatches barely pull it) tells the
    mismatches apart; then the rigid rig solve of Solve Calibration Brim runs
    on the rest, dropping any observation far outside the others' errors.

    Returns
    -------
    cameras : list of Camera
    uv, det : the matches that fit (copies)
    rms : float
        RMS reprojection error (px) of the kept matches.

    Raises
    ------
    CaraError
        Fewer than :data:`MIN_BRIM_MARKERS` markers matched, or no consistent fit.
    """
    uv, det = uv.copy(), det.copy()
    _enough(uv)
    obs = np.all(np.isfinite(uv), axis=-1)
    fun = _rigid_residual(cameras, markers, uv, obs)
    x = least_squares(fun, np.zeros(6), loss="cauchy", f_scale=FIT_TOLERANCE_PX / 2, x_scale="jac").x
    cams = _apply_rigid(cameras, x)
    rms = np.inf
    for _ in range(rounds):
        err = np.where(obs, np.linalg.norm(project_all(cams, markers) - uv, axis=-1), np.nan)
        limit = max(FIT_TOLERANCE_PX, OUTLIER_FACTOR * float(np.nanmedian(err)))
        bad = obs & ~(err <= limit)
        uv[bad] = np.nan
        det[bad] = -1
        obs &= ~bad
        _enough(uv)
        cams, rms = solve_rig(cameras, markers, uv)
        if not np.any(bad):
            break
    if not rms <= FIT_TOLERANCE_PX:
        raise CaraError(f"the ROM brim does not fit this frame's detections (RMS {rms:.1f} px after the rig "
                        "solve)")
    return cams, uv, det, rms


def _enough(uv: np.ndarray) -> None:
    obs = np.all(np.isfinite(uv), axis=-1)
    n_markers = int(np.count_nonzero(np.any(obs, axis=1)))
    if n_markers < MIN_BRIM_MARKERS or np.count_nonzero(obs) < 6:
        raise CaraError(f"only {n_markers} brim markers of the ROM frame matched a detection within the "
                        "ROM Brim Point Tracking Distance")


def face_motion(X_rom: np.ndarray, X_take: np.ndarray, ok: np.ndarray, rounds: int = 3) -> np.ndarray | None:
    """The rigid motion carrying the ROM face ``X_rom`` onto the points found in the take, robustly.

    A least-squares fit (:func:`~carapost.core.stabilize.kabsch`) on the points
    found (``ok``), refitted without those farther than three times the median
    error (and 1 mm) from it: expressions differ a little, mismatches a lot.

    Returns
    -------
    ndarray (4, 4) or None
        None with fewer than 6 points found.
    """
    from .stabilize import kabsch

    use = np.asarray(ok, bool) & np.all(np.isfinite(X_take), axis=1) & np.all(np.isfinite(X_rom), axis=1)
    T = None
    for _ in range(rounds):
        if np.count_nonzero(use) < 6:
            return T
        Rt = kabsch(X_rom[use], X_take[use])
        T = motion(Rt[:, :3], Rt[:, 3])
        err = np.linalg.norm(apply_motion(T, X_rom) - X_take, axis=1)
        keep = use & (err <= max(1.0, 3.0 * float(np.median(err[use]))))
        if np.array_equal(keep, use):
            break
        use = keep
    return T


def motion_size(T: np.ndarray, X: np.ndarray) -> float:
    """The largest displacement (mm) of the points ``X`` under the motion ``T``."""
    X = np.asarray(X, float).reshape(-1, 3)
    return float(np.max(np.linalg.norm(apply_motion(T, X) - X, axis=1), initial=0.0))


def brim_landings(camera: Camera, markers: np.ndarray, xy: np.ndarray, tol: float = LANDING_PX) -> int:
    """How many brim markers projected by ``camera`` land within ``tol`` px of a detection ``xy`` (D, 2)."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    pred = camera.project(np.asarray(markers, float).reshape(-1, 3))
    pred = pred[np.all(np.isfinite(pred), axis=1)]
    if len(xy) == 0 or len(pred) == 0:
        return 0
    d, _ = cKDTree(xy).query(pred, distance_upper_bound=float(tol))
    return int(np.count_nonzero(np.isfinite(d)))


# ----------------------------------------------------------------------------- ROM Tools
def solve_camera_pnp(camera: Camera, X: np.ndarray, uv: np.ndarray) -> Camera:
    """One camera's pose from 4 or more 3D-2D correspondences (raw pixels), starting from its pose.

    Raises
    ------
    CaraError
        With fewer than 4 correspondences.
    """
    X = np.asarray(X, float).reshape(-1, 3)
    uv = np.asarray(uv, float).reshape(-1, 2)
    if len(X) < 4:
        raise CaraError(f"Solve ROM Camera needs 4 or more correspondences in the channel (found {len(X)})")

    def fun(x):
        c = camera.with_pose(Rotation.from_rotvec(x[:3]).as_matrix() @ camera.rotation, camera.position + x[3:])
        return np.nan_to_num((c.project(X) - uv).ravel(), nan=1e4)

    # The current pose is a few degrees off at most, so a local solve from it is enough; several
    # starts guard against a shallow minimum with so few points.
    best = None
    for x0 in _starts(camera, X, uv):
        sol = least_squares(fun, x0, method="lm", x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    x = best.x
    return camera.with_pose(Rotation.from_rotvec(x[:3]).as_matrix() @ camera.rotation, camera.position + x[3:])


def _starts(camera: Camera, X, uv):
    """Starting offsets for :func:`solve_camera_pnp`: none, and OpenCV's PnP when it succeeds."""
    yield np.zeros(6)
    try:
        import cv2

        pts = camera.correct(uv)
        ok, rvec, tvec = cv2.solvePnP(X, pts.astype(np.float64), camera.K, None, flags=cv2.SOLVEPNP_SQPNP)
    except Exception:  # noqa: BLE001 - a failed PnP start only means the local solve is used alone
        return
    if ok:
        R = cv2.Rodrigues(rvec)[0]
        C = -R.T @ tvec.ravel()
        yield np.concatenate([Rotation.from_matrix(R @ camera.rotation.T).as_rotvec(), C - camera.position])


def solve_face_alignment(cameras, X: np.ndarray, sensors: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The rigid motion of ROM face points that best fits their 2D correspondences.

    Parameters
    ----------
    cameras : list of Camera
        Cameras of the take's frame.
    X : ndarray (N, 3)
        ROM positions of the corresponded points.
    sensors : ndarray (N,) int
        Channel of each correspondence.
    uv : ndarray (N, 2)
        Raw pixels of the corresponding detections.

    Returns
    -------
    ndarray (4, 4)
        The motion; applied about the points' centroid, so a small correction stays small.

    Raises
    ------
    CaraError
        With fewer than 3 correspondences.
    """
    X = np.asarray(X, float).reshape(-1, 3)
    if len(X) < 3:
        raise CaraError(f"Solve ROM Face Alignment needs 3 or more correspondences (found {len(X)})")
    c = X.mean(axis=0)
    sensors = np.asarray(sensors, int)

    def fun(x):
        Y = (X - c) @ Rotation.from_rotvec(x[:3]).as_matrix().T + c + x[3:]
        out = np.empty((len(X), 2))
        for s in np.unique(sensors):
            m = sensors == s
            out[m] = cameras[s].project(Y[m]) - uv[m]
        return np.nan_to_num(out.ravel(), nan=1e4)

    x = least_squares(fun, np.zeros(6), method="lm", x_scale="jac").x
    R = Rotation.from_rotvec(x[:3]).as_matrix()
    return motion(R, c + x[3:] - R @ c)


def detections_xy(recs: list) -> list[np.ndarray]:
    """Raw pixels ``(D, 2)`` of each sensor's detection records."""
    return [np.column_stack([r["x"], r["y"]]).astype(float) if len(r) else np.zeros((0, 2)) for r in recs]


def used_detections(points, frame: int, recs: list, kinds=(FACE,)) -> list[np.ndarray]:
    """Per sensor, the detections that points of ``kinds`` hold on ``frame``."""
    out = [np.zeros(len(r), bool) for r in recs]
    for p in points:
        if p.kind not in kinds:
            continue
        for s, r in enumerate(recs):
            d = p.det[frame, s]
            if p.src[frame, s] == SRC_DETECTION and 0 <= d < len(r):
                out[s][d] = True
    return out


__all__ = ["RomFrame", "rom_frame", "rom_point_position", "project_all", "match_brim", "robust_rig_fit",
           "solve_camera_pnp", "solve_face_alignment", "rig_motion", "move_cameras", "apply_motion", "motion",
           "identity", "detections_xy", "used_detections", "brim_landings", "face_motion", "motion_size"]
