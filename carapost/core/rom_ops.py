"""Load ROM, Initialize from ROM [Brim Only] and the ROM Tools as commands.

The loaded ROM is another ``.cara`` project, opened memory-mapped and kept on
the project (:func:`loaded_rom`) with what the ROM Tools add to it: the
2D-to-ROM correspondences and the rigid alignments of the ROM's camera rig and
face that were solved from them.  Only the ROM's path is saved with the
project (``Project.rom_path``) with the ROM Tools' correspondences and
alignments; on the next use after opening the project the ROM is loaded again
from that path and they are applied to it.

Initialize from ROM on the current frame (the guide's "Initialize from ROM
algorithm"):

1. the ROM frame (ROM Frame Index): cameras, brim, labelled face points, sticks;
2. the ROM brim projected with the ROM cameras and matched to this frame's
   detections within the ROM Brim Point Tracking Distance, then the rigid rig
   solve and the per-camera refinement of Solve Calibration Brim;
3. the ROM face tracked from the ROM frame into this frame by the automatic
   tracker (:class:`~carapost.core.tracking.engine.FrameTracker`: the same
   candidate search, ratio test, elastic second pass and bad-point removal),
   with the ROM Face/Brim Point Tracking Distance and ROM Max Allowed 3D Point
   Error in place of the tracking ones;
4. Bundle Current Frame on the brim and the new points, and the points still
   farther than ROM Max Allowed 3D Point Error from where their ROM
   neighbours put them are dropped;
5. one command adds the brim points, the face points with the ROM's labels,
   the label list and the sticks, and sets the frame's cameras.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import rom as R
from .brim import Brim
from .commands import Command, CompoundCommand
from .edits import AddPoints, SetBrim, SetLabels, SetRig, SetSticks
from .errors import CaraError
from .points import FACE, SRC_NONE, ST_NONE
from .progress import Progress
from .project import Project, Stick
from .rig import CameraRig

log = logging.getLogger("carapost")

#: Where the loaded ROM is kept on the project (not saved: only ``rom_path`` is).
ROM_ATTR = "loaded_rom"
#: The ROM Tools' state read from the project file, applied when the ROM is loaded again.
SAVED_TOOLS_ATTR = "saved_rom_tools"

NO_ROM = ("no ROM is loaded: Initialize from ROM and the ROM Tools need a ROM take "
          "(Process > Load ROM, or CaraProcess.load_rom)")


@dataclass(frozen=True)
class Correspondence:
    """A ROM point and the detection of this take it corresponds to (Add 2D To ROM Correspondence)."""

    rom_point: int
    sensor: int
    frame: int
    detection: int
    uv: tuple[float, float]


@dataclass(frozen=True)
class RomState:
    """The loaded ROM and what the ROM Tools added to it.

    Attributes
    ----------
    path : str
        The ROM's ``.cara`` file.
    rom : Project
        The ROM take (memory-mapped, read only).
    correspondences : tuple of Correspondence
    rig_T, face_T : ndarray (4, 4)
        World motions of the ROM's cameras and of its face (ROM Tools solves).
    cam_T : tuple of ndarray (4, 4)
        Empty, or one motion per camera applied after ``rig_T``: cameras moved on their own.
    """

    path: str
    rom: Project
    correspondences: tuple = ()
    rig_T: np.ndarray = field(default_factory=R.identity)
    face_T: np.ndarray = field(default_factory=R.identity)
    cam_T: tuple = ()


def _read_rom(path: str | Path) -> Project:
    from ..io.cara import load_project   # io depends on core: import late

    path = Path(path)
    if path.suffix.lower() != ".cara":
        raise CaraError("a ROM is a carapost project (.cara) file", path)
    return load_project(path)


def loaded_rom(project: Project, required: bool = True) -> RomState | None:
    """The ROM loaded for ``project``, reloading it from ``project.rom_path`` after an open.

    Raises
    ------
    CaraError
        When ``required`` and no ROM is loaded, or the saved ROM file cannot be read.
    """
    state = getattr(project, ROM_ATTR, None)
    if state is not None and state.path == project.rom_path:
        return state
    if not project.rom_path:
        if required:
            raise CaraError(NO_ROM)
        return None
    try:
        state = _restored(RomState(project.rom_path, _read_rom(project.rom_path)),
                          getattr(project, SAVED_TOOLS_ATTR, None))
    except CaraError as e:
        raise CaraError(f"the ROM saved with this project cannot be loaded ({e}); load it again with "
                        "Process > Load ROM") from None
    setattr(project, ROM_ATTR, state)
    return state


def rom_tools_json(project: Project) -> dict | None:
    """What the ROM Tools added (correspondences, solved alignments), for the project file.

    The loaded state when there is one, else what the file it was opened from held.
    """
    state = getattr(project, ROM_ATTR, None)
    if state is None or state.path != project.rom_path:
        return getattr(project, SAVED_TOOLS_ATTR, None) if project.rom_path else None
    if not state.correspondences and np.array_equal(state.rig_T, R.identity()) \
            and np.array_equal(state.face_T, R.identity()) and not state.cam_T:
        return None
    out = {"correspondences": [[c.rom_point, c.sensor, c.frame, c.detection, list(c.uv)]
                               for c in state.correspondences],
           "rig_T": np.asarray(state.rig_T, float).ravel().tolist(),
           "face_T": np.asarray(state.face_T, float).ravel().tolist()}
    if state.cam_T:
        out["cam_T"] = [np.asarray(T, float).ravel().tolist() for T in state.cam_T]
    return out


def set_saved_rom_tools(project: Project, d: dict | None) -> None:
    """Keep the ROM Tools' state read from a project file until the ROM is loaded again."""
    setattr(project, SAVED_TOOLS_ATTR, d or None)


def _restored(state: RomState, d: dict | None) -> RomState:
    if not d:
        return state
    corr = tuple(Correspondence(int(a), int(s), int(f), int(det), (float(uv[0]), float(uv[1])))
                 for a, s, f, det, uv in d.get("correspondences", []))
    return replace(state, correspondences=corr,
                   rig_T=np.asarray(d.get("rig_T", R.identity().ravel()), float).reshape(4, 4),
                   face_T=np.asarray(d.get("face_T", R.identity().ravel()), float).reshape(4, 4),
                   cam_T=tuple(np.asarray(T, float).reshape(4, 4) for T in d.get("cam_T", [])))


class SetRomState(Command):
    """Replace the loaded ROM (and its path, saved with the project)."""

    def __init__(self, state: RomState | None, name: str):
        self.state = state
        self.name = name
        self._old = None

    def do(self, project: Project) -> None:
        self._old = (getattr(project, ROM_ATTR, None), project.rom_path)
        setattr(project, ROM_ATTR, self.state)
        project.rom_path = self.state.path if self.state is not None else ""

    def undo(self, project: Project) -> None:
        state, path = self._old
        setattr(project, ROM_ATTR, state)
        project.rom_path = path

    def nbytes(self) -> int:
        return 512   # the ROM itself is memory-mapped and shared, not kept by the command


def load_rom(project: Project, path: str | Path) -> Command:
    """Process > Load ROM: open the ``.cara`` of a ROM take for Initialize from ROM.

    Raises
    ------
    CaraError
        For a file that is not a readable ``.cara``, or a ROM whose channel count differs.
    """
    path = Path(path).absolute()
    rom = _read_rom(path)
    if rom.sensor_count != project.sensor_count:
        raise CaraError(f"the ROM has {rom.sensor_count} channels, this take {project.sensor_count}", path)
    faces = sum(1 for p in rom.points.values() if p.kind == FACE)
    cmd = SetRomState(RomState(str(path), rom), "Load ROM")
    cmd.summary = (f"Load ROM: {path.name}, {rom.frame_count} frames, {faces} face points, "
                   f"{len(rom.labels)} labels" + ("" if rom.rig is not None else " (no cameras: it cannot be used "
                                                                             "until it is calibrated)"))
    return cmd


def rom_parameters(project: Project) -> dict:
    """The Initialize From ROM Parameters section."""
    g = "initialize_from_rom."
    return {k: project.properties[g + k] for k in ("rom_frame_index", "rom_face_point_tracking_distance",
                                                   "rom_brim_point_tracking_distance",
                                                   "rom_max_allowed_3d_point_error")}


def _frame_of(project: Project, state: RomState) -> R.RomFrame:
    return R.rom_frame(state.rom, rf_index(project), state.rig_T, state.face_T, state.cam_T or None)


def _take_cameras(project: Project, rom_cams) -> list:
    """The ROM's poses with this take's intrinsics (when it has a calibration), else the ROM's cameras."""
    if project.rig is None:
        return [c.copy() for c in rom_cams]
    return [t.with_pose(r.rotation, r.position) for t, r in zip(project.rig.cameras, rom_cams)]


# ----------------------------------------------------------------------------- display
def _shown_frame(project: Project):
    """The loaded ROM's frame for display, or None (no ROM, or one that cannot be used): never raises."""
    try:
        state = loaded_rom(project, required=False)
        return None if state is None else _frame_of(project, state)
    except CaraError:
        return None


def rom_projections(project: Project) -> dict | None:
    """Where the ROM frame's points fall in this take's views (the 2D views' ROM display).

    Returns
    -------
    dict or None
        ``ids`` (N,) ROM point ids, ``brim`` (N,) bool, ``labels``, ``uv`` (N, S, 2) raw
        pixels through the ROM cameras (as aligned by the ROM Tools); None without a ROM.
    """
    rf = _shown_frame(project)
    if rf is None:
        return None
    bids = sorted(rf.brim_ids)
    ids = list(rf.ids) + [rf.brim_ids[b] for b in bids]
    labels = list(rf.labels) + [f"Brim {b}" for b in bids]
    return {"ids": np.array(ids, int), "brim": np.r_[np.zeros(len(rf.ids), bool), np.ones(len(bids), bool)],
            "labels": labels, "uv": R.project_all(_take_cameras(project, rf.cameras), _points_3d(rf))}


def rom_points_3d(project: Project) -> np.ndarray:
    """The ROM frame's face points (aligned) and brim markers, ``(M, 3)`` mm; empty without a ROM (the 3D view)."""
    rf = _shown_frame(project)
    return np.zeros((0, 3)) if rf is None else _points_3d(rf)


def _points_3d(rf: R.RomFrame) -> np.ndarray:
    bids = sorted(rf.brim_ids)
    return np.concatenate([rf.X, rf.markers[bids]]) if bids else rf.X


# ----------------------------------------------------------------------------- Initialize from ROM
def _params(project: Project, rom_p: dict):
    from .tracking.params import TrackingParams

    return TrackingParams.from_project(project, {
        "face_point_tracking_distance": rom_p["rom_face_point_tracking_distance"],
        "brim_point_tracking_distance": rom_p["rom_brim_point_tracking_distance"],
        "max_allowed_3d_point_error": rom_p["rom_max_allowed_3d_point_error"],
        # One frame is tracked from the ROM: its points are the ROM's, none are made; and the frame's
        # detections are its own (the results' samples index them, and no dot found by the search is kept).
        "add_points_for_new_markers": False, "search_missing_views": False})


def initialize_from_rom(project: Project, frame: int, brim_only: bool = False, images=None,
                        progress: Progress | None = None) -> Command:
    """Process > Initialize from ROM (``brim_only``: [Brim Only]) on ``frame``.

    Parameters
    ----------
    project : Project
        With blob detections on ``frame`` (or media to detect them) and a loaded ROM.
    frame : int
    brim_only : bool
        Only the brim points and the cameras.
    images : TakeFrames or callable, optional
        Used only to detect blobs on a frame that has none.
    progress : Progress, optional

    Returns
    -------
    Command
        Not applied.  ``summary`` is a log line; ``report`` a dict: ``brim_markers``
        matched, ``points`` created, ``labelled``, ``rms_px`` of the final bundle.

    Raises
    ------
    CaraError
        Without a ROM (the guide: "Initialize from ROM fails completely if no ROM
        take has been loaded"), or when the ROM brim cannot be found on the frame.
    """
    from .calib.brim_solve import _solution_command, brim_points, solve_brim
    from .tracking.api import _detections

    state = loaded_rom(project)
    name = "Initialize from ROM" + (" [Brim Only]" if brim_only else "")
    frame = project.clamp_frame(frame)
    rom = state.rom
    if rom.sensor_count != project.sensor_count:
        raise CaraError(f"the ROM has {rom.sensor_count} channels, this take {project.sensor_count}", state.path)
    rp = rom_parameters(project)
    rf = _frame_of(project, state)
    progress = progress or Progress()
    recs_of, detect_cmd = _detections(project, [frame], images, progress)
    progress.start(3, name)
    recs = recs_of(frame)
    det_xy = R.detections_xy(recs)
    used = R.used_detections(project.points.values(), frame, recs)
    # 1-2. Cameras from the ROM brim.
    cams0 = _take_cameras(project, rf.cameras)
    uv, det = R.match_brim(cams0, rf.markers, det_xy, used, rp["rom_brim_point_tracking_distance"])
    try:
        cams, uv, det, _rms = R.robust_rig_fit(cams0, rf.markers, uv, det)
        sol = solve_brim(cams, rf.markers, uv, det_xy, used, det, rom.brim.radius)
    except CaraError as e:
        raise CaraError(f"frame {frame}: {e}; increase ROM Brim Point Tracking Distance "
                        f"({rp['rom_brim_point_tracking_distance']:g} px), choose a closer ROM Frame Index, or "
                        "align the ROM with Process > ROM Tools > Solve ROM Camera From Correspondences") from None
    weak = _weak_channels(sol.det)
    if weak:
        log.warning(_weak_message(frame, sol.det, weak))
    progress.step(1)
    # The take gets the ROM's brim and cameras when it has none (or another brim: its brim points then
    # stand for other markers, so new ones are made).
    pre: list[Command] = []
    new_brim = project.brim is None or not np.array_equal(np.asarray(project.brim.markers), rf.markers)
    if new_brim:
        pre.append(SetBrim(Brim(rom.brim.name, rf.markers.copy(), rom.brim.svg, rom.brim.radius.copy()), name="Set Calibration Brim"))
    if project.rig is None:
        pre.append(SetRig(CameraRig([c.copy() for c in rom.rig.cameras], project.frame_count), name="Set Cameras"))
    bp = {} if new_brim else brim_points(project)
    face_cmds, report = None, {"brim_markers": int(np.count_nonzero(np.any(sol.det >= 0, axis=1))), "points": 0,
                               "labelled": 0, "rms_px": sol.rms, "weak_channels": weak}
    if not brim_only:
        sol, face_cmds = _face(project, frame, state, rf, sol, recs, rp, report)
    progress.step(1)
    brim_cmd = _solution_command(project, frame, sol, bp, "Initialize Brim", calibration=False,
                                 markers=rf.markers)
    cmds = ([detect_cmd] if detect_cmd is not None else []) + pre + [brim_cmd]
    if face_cmds is not None:
        new_ids = [p.id for c in brim_cmd.commands if isinstance(c, AddPoints) for p in c.points]
        start = max([project.next_point_id] + [i + 1 for i in new_ids])
        cmds += face_cmds(start)
    cmd = CompoundCommand(name, cmds)
    cmd.report = report
    cmd.summary = (f"{name}: frame {frame} from ROM frame {rp['rom_frame_index']} of {Path(state.path).name}, "
                   f"{report['brim_markers']} brim markers"
                   + ("" if brim_only else f", {report['points']} of {len(rf.ids)} face points "
                      f"({report['labelled']} labelled)") + f", RMS {report['rms_px']:.2f} px"
                   + (f"; the face sat up to {report['face_moved_mm']:g} mm off its ROM place in the brim and was "
                      "tracked again from there" if "face_moved_mm" in report else "")
                   + (f"; channels {', '.join(map(str, weak))} matched too few brim markers (see the warning)"
                      if weak else ""))
    progress.step(1)
    return cmd


def _weak_channels(det: np.ndarray) -> list[int]:
    """Channels that matched fewer than :data:`~carapost.core.rom.MIN_BRIM_MARKERS` brim markers while another
    matched at least twice that many: their camera has most likely moved relative to the rest since the ROM."""
    n = np.count_nonzero(det >= 0, axis=0)
    if n.max(initial=0) < 2 * R.MIN_BRIM_MARKERS:
        return []
    return [int(s) for s in np.flatnonzero(n < R.MIN_BRIM_MARKERS)]


def _weak_message(frame: int, det: np.ndarray, weak: list[int]) -> str:
    n = np.count_nonzero(det >= 0, axis=0)
    which = ", ".join(f"channel {s}: {n[s]}" for s in weak)
    others = ", ".join(str(int(v)) for s, v in enumerate(n) if s not in weak)
    ch = weak[0]
    return (f"Initialize from ROM: frame {frame}: too few ROM brim markers matched a detection ({which}; the other "
            f"channels {others} of {det.shape[0]}): that camera has probably moved since the ROM and its pose "
            f"here is unreliable.  Undo, then for channel {ch} click 4 or more ROM brim points and their "
            "detections (Process > ROM Tools > Add 2D To ROM Correspondence, Ctrl+L), run ROM Tools > Solve ROM "
            "Camera From Correspondences, and Initialize from ROM again")


def _face(project, frame, state, rf, sol, recs, rp, report):
    """Track the ROM face into ``frame``, bundle, reject; returns the final brim solution and a builder."""
    from .calib.brim_solve import BrimSolution
    from .calib.bundle import bundle_cameras
    from .tracking import elastic
    from .tracking.engine import FrameTracker
    from .tracking.geometry import RigState

    S, N = project.sensor_count, len(rf.ids)
    if N == 0:
        raise CaraError(f"the ROM frame {rp['rom_frame_index']} has no face points with a 3D position")
    already = sum(1 for p in project.face_points() if p.status[frame] != ST_NONE)
    if already:
        log.warning(f"Initialize from ROM: frame {frame} already has {already} face points; this run adds a "
                    "second, independent set of points (Edit > Undo removes it)")
    params = _params(project, rp)

    def track_from(X0):
        return FrameTracker(RigState(sol.cameras), X0, np.full((N, S, 2), np.nan), rf.size, rf.markers,
                            params, brim_radius=state.rom.brim.radius).step(frame, recs)

    res, X_ref = track_from(rf.X), rf.X
    # The face may sit elsewhere in the brim than in the ROM (the helmet put on again): dense markers
    # (the lips) then have a neighbour as close as their own blob and the first pass leaves them.  The
    # points it did find tell where the face is: track again from the ROM face moved there.
    M = R.face_motion(rf.X, res.X, res.status != ST_NONE)
    if M is not None and R.motion_size(M, rf.X) > R.FACE_REALIGN_MM:
        X_moved = R.apply_motion(M, rf.X)
        again = track_from(X_moved)
        if np.count_nonzero(again.status != ST_NONE) >= np.count_nonzero(res.status != ST_NONE):
            res, X_ref = again, X_moved
            report["face_moved_mm"] = round(R.motion_size(M, rf.X), 2)
    # Bundle Current Frame on the brim (fixed) and the face points seen twice or more.
    bobs = res.brim_det >= 0
    multi = np.count_nonzero(res.src != SRC_NONE, axis=1) >= 2
    brows = np.flatnonzero(np.any(bobs, axis=1))
    frows = np.flatnonzero(multi & (res.status != ST_NONE))
    Xb = np.concatenate([rf.markers[brows], res.X[frows]])
    uvb = np.concatenate([np.where(bobs[brows, :, None], res.brim_uv[brows], np.nan),
                          np.where((res.src[frows] != SRC_NONE)[..., None], res.uv[frows], np.nan)])
    fixed = np.r_[np.ones(len(brows), bool), np.zeros(len(frows), bool)]
    cams, Xo, err = bundle_cameras(_cams_of(res, sol.cameras), Xb, fixed, uvb)
    X = res.X.copy()
    X[frows] = Xo[len(brows):]
    # Points still far from where their ROM neighbours put them are mismatches.
    nb = elastic.neighbours(X_ref)
    off = np.full(nb.shape + (3,), np.nan)
    elastic.update_offsets(off, nb, X_ref, np.ones(N, bool))
    have = res.status != ST_NONE
    pred, _ = elastic.predict(X, have, nb, off)
    dev = np.linalg.norm(X - pred, axis=1)
    keep = have & ~(np.isfinite(dev) & (dev > rp["rom_max_allowed_3d_point_error"]))
    ferr = np.full((N, S), np.nan)
    ferr[frows] = err[len(brows):]
    berr = np.full(res.brim_err.shape, np.nan)
    berr[brows] = err[:len(brows)]
    rms = float(np.sqrt(np.nanmean(err ** 2))) if np.any(np.isfinite(err)) else float("nan")
    final = BrimSolution(cams, res.brim_det, np.where(bobs[..., None], res.brim_uv, np.nan), berr, sol.rms_rigid, rms)
    report.update(brim_markers=int(np.count_nonzero(np.any(bobs, axis=1))), points=int(keep.sum()), rms_px=rms)
    taken = {p.label for p in project.points.values() if p.label}
    report["labelled"] = int(sum(1 for i in np.flatnonzero(keep) if rf.labels[i] and rf.labels[i] not in taken))

    def build(start_id: int) -> list[Command]:
        rows = np.flatnonzero(keep)
        new, id_of = [], {}
        for k, i in enumerate(rows):
            label = rf.labels[i] if rf.labels[i] not in taken else ""
            p = project.new_point(FACE, label=label, point_id=start_id + k)
            p.pos[frame] = X[i]
            p.status[frame] = res.status[i]
            e = ferr[i] if multi[i] else res.residual[i:i + 1]
            p.residual[frame] = np.sqrt(np.nanmean(e ** 2)) if np.any(np.isfinite(e)) else np.nan
            p.src[frame], p.det[frame], p.uv[frame], p.score[frame] = res.src[i], res.det[i], res.uv[i], res.score[i]
            new.append(p)
            id_of[rf.ids[i]] = p.id
        out: list[Command] = [AddPoints(new, name="Add Points From ROM")]
        labels = list(project.labels) + [lab for lab in state.rom.labels if lab not in project.labels]
        labels += [lab for lab in rf.labels if lab and lab not in labels]
        if labels != project.labels:
            out.append(SetLabels(labels, name="Add ROM Labels"))
        sticks = [Stick(id_of[s.a], id_of[s.b], tuple(s.color)) for s in state.rom.sticks
                  if s.a in id_of and s.b in id_of]
        if sticks:
            out.append(SetSticks(list(project.sticks) + sticks, name="Add ROM Sticks"))
        return out

    report["second_set"] = bool(already)
    return final, build


def _cams_of(res, cameras) -> list:
    """The tracker's final cameras of the frame as Camera objects."""
    return [c.with_pose(res.R[s], res.C[s]) for s, c in enumerate(cameras)]


# ----------------------------------------------------------------------------- ROM Tools
def _with(state: RomState, name: str, summary: str, **changes) -> Command:
    cmd = SetRomState(replace(state, **changes), name)
    cmd.summary = summary
    return cmd


def add_2d_to_rom_correspondence(project: Project, rom_point: int, detections) -> Command:
    """ROM Tools > Add 2D To ROM Correspondence (Ctrl+L): ROM point ``rom_point`` is the selected detection.

    Parameters
    ----------
    rom_point : int
        A point id of the ROM take (face or brim).
    detections : iterable of (sensor, frame, index)
        The selection: exactly one detection (the one channel it is in).

    Raises
    ------
    CaraError
        Without a ROM, for an unknown ROM point, or unless one detection is selected.
    """
    state = loaded_rom(project)
    dets = list(detections)
    if len(dets) != 1:
        raise CaraError(f"select one detection in one channel for the ROM point (selected: {len(dets)})")
    s, f, i = (int(v) for v in dets[0])
    if not (0 <= s < project.sensor_count and 0 <= f < project.frame_count and 0 <= i < project.detections[s].count(f)):
        raise CaraError(f"no detection {i} in channel {s} on frame {f}")
    rom_p = state.rom.points.get(int(rom_point))
    if rom_p is None:
        raise CaraError(f"the ROM has no point {rom_point}")
    rec = project.detections[s].frame(f)[i]
    c = Correspondence(int(rom_point), s, f, i, (float(rec["x"]), float(rec["y"])))
    # One correspondence per ROM point and channel: a new click replaces the old one.
    kept = tuple(k for k in state.correspondences if not (k.rom_point == c.rom_point and k.sensor == s))
    n = len(kept) + 1
    return _with(state, "Add 2D To ROM Correspondence",
                 f"Add 2D To ROM Correspondence: ROM point {rom_p.name} = detection {i} of channel {s} "
                 f"({n} correspondences)", correspondences=kept + (c,))


def clear_2d_to_rom_correspondences(project: Project) -> Command:
    """ROM Tools > Clear 2D To ROM Correspondence: forget every correspondence."""
    state = loaded_rom(project)
    if not state.correspondences:
        raise CaraError("there are no 2D to ROM correspondences to clear")
    return _with(state, "Clear 2D To ROM Correspondence",
                 f"Clear 2D To ROM Correspondence: {len(state.correspondences)} removed", correspondences=())


def _corr_arrays(state: RomState, frame: int, items):
    X = np.array([R.rom_point_position(state.rom, frame, k.rom_point, state.face_T) for k in items]).reshape(-1, 3)
    uv = np.array([k.uv for k in items], float).reshape(-1, 2)
    return X, uv


def solve_rom_camera_from_correspondences(project: Project, sensor: int | None = None) -> Command:
    """ROM Tools > Solve ROM Camera From Correspondences.

    The camera of the channel with 4 or more correspondences (the one with the
    most, or ``sensor``) is solved by PnP from them.  Each other camera then
    either follows it rigidly (the whole helmet moved: the rig's relative
    placement is kept) or stays where it is (only this camera was knocked, as
    the guide's "correspondences for only the camera channel that has the
    misalignment" implies): whichever puts more of the ROM brim on this
    frame's detections in that camera's channel (:func:`~carapost.core.rom.brim_landings`).

    Raises
    ------
    CaraError
        Without a ROM, or with fewer than 4 correspondences in the channel.
    """
    state = loaded_rom(project)
    rf = _frame_of(project, state)
    counts = np.bincount([k.sensor for k in state.correspondences], minlength=project.sensor_count)
    s = int(np.argmax(counts)) if sensor is None else int(sensor)
    items = [k for k in state.correspondences if k.sensor == s]
    if len(items) < 4:
        raise CaraError(f"Solve ROM Camera From Correspondences needs 4 or more correspondences in one channel "
                        f"(channel {s} has {len(items)}); add them with Add 2D To ROM Correspondence (Ctrl+L)")
    X, uv = _corr_arrays(state, rf_index(project), items)
    cams = _take_cameras(project, rf.cameras)
    before = float(np.sqrt(np.nanmean(np.sum((cams[s].project(X) - uv) ** 2, axis=1))))
    new = R.solve_camera_pnp(cams[s], X, uv)
    after = float(np.sqrt(np.nanmean(np.sum((new.project(X) - uv) ** 2, axis=1))))
    M = R.rig_motion(cams[s], new)
    moved = float(np.linalg.norm(new.position - cams[s].position))
    follow = _followers(project, rf, cams, M, s, int(np.bincount([k.frame for k in items]).argmax()))
    head = (f"Solve ROM Camera From Correspondences: channel {s} from {len(items)} correspondences, "
            f"error {before:.1f} -> {after:.2f} px, the camera moved {moved:.1f} mm")
    name = "Solve ROM Camera From Correspondences"
    if all(follow) and not state.cam_T:
        return _with(state, name, head + ", the rest of the ROM rig with it", rig_T=M @ state.rig_T)
    old = state.cam_T or tuple(R.identity() for _ in cams)
    stay = [o for o in range(len(cams)) if not follow[o]]
    moved_too = [o for o in range(len(cams)) if follow[o] and o != s]
    tail = (f"; channels {', '.join(map(str, stay))} stay (the ROM brim lands on their detections as they are)"
            + (f", channels {', '.join(map(str, moved_too))} move with it" if moved_too else ""))
    return _with(state, name, head + tail, cam_T=tuple(M @ T if follow[o] else T for o, T in enumerate(old)))


def _followers(project: Project, rf: R.RomFrame, cams: list, M: np.ndarray, s: int, frame: int) -> list[bool]:
    """Per camera, whether it moves with camera ``s`` (by ``M``): it fits ``frame``'s brim detections better so.

    A channel where neither pose puts a brim marker on a detection follows
    (nothing says the rig did not move as a whole).
    """
    recs = [project.detections[o].frame(frame) for o in range(len(cams))]
    xy = R.detections_xy(recs)
    out = []
    for o, cam in enumerate(cams):
        if o == s:
            out.append(True)
            continue
        moved = R.move_cameras([cam], M)[0]
        n_stay = R.brim_landings(cam, rf.markers, xy[o])
        n_move = R.brim_landings(moved, rf.markers, xy[o])
        out.append(n_move > n_stay or n_move == n_stay == 0)
    return out


#: The property that says which ROM frame Initialize from ROM uses.
ROM_FRAME_INDEX = "initialize_from_rom.rom_frame_index"


def rf_index(project: Project) -> int:
    """The ROM Frame Index property."""
    return int(project.properties[ROM_FRAME_INDEX])


def solve_rom_face_alignment_from_correspondences(project: Project, frame: int) -> Command:
    """ROM Tools > Solve ROM Face Alignment From Correspondences.

    A rigid motion of the ROM face (relative to the brim) fitted to the face
    correspondences of every channel, seen through this frame's cameras (the
    take's own when its cameras are solved on ``frame``, else the ROM's as aligned).

    Raises
    ------
    CaraError
        Without a ROM, or with fewer than 3 face correspondences.
    """
    state = loaded_rom(project)
    rf = _frame_of(project, state)
    items = [k for k in state.correspondences
             if k.rom_point in state.rom.points and state.rom.points[k.rom_point].kind == FACE]
    if len(items) < 3:
        raise CaraError(f"Solve ROM Face Alignment From Correspondences needs 3 or more face point correspondences "
                        f"(found {len(items)})")
    frame = project.clamp_frame(frame)
    if project.rig is not None and bool(np.all(project.rig.solved[:, frame])):
        cams = project.rig.cameras_at(frame)
    else:
        cams = _take_cameras(project, rf.cameras)
    X, uv = _corr_arrays(state, rf_index(project), items)
    sensors = np.array([k.sensor for k in items])
    M = R.solve_face_alignment(cams, X, sensors, uv)
    Y = R.apply_motion(M, X)
    err = [np.linalg.norm(cams[s].project(y[None])[0] - u) for s, y, u in zip(sensors, Y, uv)]
    ang = float(np.degrees(np.arccos(np.clip((np.trace(M[:3, :3]) - 1) / 2, -1, 1))))
    return _with(state, "Solve ROM Face Alignment From Correspondences",
                 f"Solve ROM Face Alignment From Correspondences: {len(items)} correspondences, RMS "
                 f"{float(np.sqrt(np.mean(np.square(err)))):.2f} px, the ROM face turned {ang:.1f} deg",
                 face_T=M @ state.face_T)


__all__ = ["Correspondence", "RomState", "loaded_rom", "load_rom", "initialize_from_rom", "rom_projections",
           "rom_points_3d",
           "add_2d_to_rom_correspondence", "clear_2d_to_rom_correspondences",
           "solve_rom_camera_from_correspondences", "solve_rom_face_alignment_from_correspondences",
           "rom_parameters"]
