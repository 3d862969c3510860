"""Project commands: Process > Interpolate Gaps and Edit > Remove Interpolated 3D Points.

Both compute on the project without changing it and return an undoable
:class:`~carapost.core.edits.SetPointData`; the caller runs it (through the
document's undo stack in the GUI).
"""
from __future__ import annotations

import numpy as np

from .edits import SetPointData
from .gapfill import fill_gaps, find_gaps
from .points import SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, SRC_TARGET, ST_INTERPOLATED, ST_NONE, ST_SINGLE

__all__ = ["interpolate_gaps", "remove_interpolated", "gap_frames", "weak_samples"]


def _range(project, start, end) -> tuple[int, int]:
    a0, a1 = project.active_range
    return project.check_range(a0 if start is None else int(start), a1 if end is None else int(end))


def _ids(project, point_ids) -> list[int]:
    if point_ids is None or len(point_ids) == 0:
        return list(project.points)          # the guide: no selection means every point
    for pid in point_ids:
        project.point(pid)                   # raises CaraError for an unknown id
    return [int(p) for p in point_ids]


def gap_frames(point, overwrite: bool) -> np.ndarray:
    """``(F,)`` bool: frames Interpolate Gaps fills for ``point``.

    Frames without a 3D sample; with ``overwrite`` also existing filled samples
    (the guide: "existing 3D points with either zero or one detection only
    attached"), i.e. status interpolated or single-sensor with fewer than two
    sensors' 2D samples.
    """
    g = point.status == ST_NONE
    if overwrite:
        filled = np.isin(point.status, (ST_INTERPOLATED, ST_SINGLE)) & (point.contributing() < 2)
        g |= filled
    return g


#: A tracked sample needs this many cameras' blobs (or Target Tracker samples) behind it to predict a gap.
FIRM_VIEWS = 2


def weak_samples(point) -> np.ndarray:
    """``(F,)`` bool: samples Interpolate Gaps keeps but does not predict a gap beside them from.

    Tracked samples with fewer than :data:`FIRM_VIEWS` cameras' blobs (or Target
    Tracker samples) behind them: patch tracks, which lag or stray as a point is
    being lost, and single-sensor samples, whose depth is the tracker's guess.  On
    the white 35-marker process take of seed 2, a patch-only sample 1.6 mm off
    before a 23-frame gap and a single-sensor one 1.4 mm off after it put the fill
    4.7 mm off; predicted from the samples beyond them, it is at most 0.58 mm off
    (docs/tracking-history.md, "Session 30").  Samples with no 2D samples at all (a C3D's,
    or placed by hand) are not weak.
    """
    firm = np.isin(point.src, (SRC_DETECTION, SRC_TARGET, SRC_KEYFRAME)).sum(axis=1)
    tracked = (point.status != ST_NONE) & (point.status != ST_INTERPOLATED)
    return tracked & (point.contributing() > 0) & (firm < FIRM_VIEWS)


def interpolate_gaps(project, point_ids=None, start: int | None = None, end: int | None = None,
                     progress=None) -> SetPointData:
    """Interpolate Gaps over the selected points (all when none) on a frame range.

    Parameters
    ----------
    project : Project
    point_ids : list of int, optional
        Points to fill; None or empty: every point.
    start, end : int, optional
        Inclusive frame range; default the active range.  Gaps are predicted
        from the whole take but only frames in the range are written.
    progress : Progress, optional

    Returns
    -------
    SetPointData
        Writes ``pos``, ``status`` (``ST_SINGLE`` where the single-sensor ray
        constrained the sample, else ``ST_INTERPOLATED``) and ``residual``
        (NaN: a filled sample has no reprojection error) on every filled run.

    Notes
    -----
    Honours the Gap-Filling Parameters: Overwrite Existing Filled Gaps, Use
    Forwards / Backwards Prediction, Allow Single Sensor Tracking Gap-Filling
    (a gap frame where exactly one sensor has a 2D sample of the point, with a
    camera rig, is put on that sensor's ray).
    """
    start, end = _range(project, start, end)
    ids = _ids(project, point_ids)
    props = project.properties
    overwrite = bool(props["gap_filling.overwrite_existing_filled_gaps"])
    forwards = bool(props["gap_filling.use_forwards_prediction"])
    backwards = bool(props["gap_filling.use_backwards_prediction"])
    single = bool(props["gap_filling.allow_single_sensor_tracking_gap_filling"])

    # Every point is a potential neighbour; columns in project order.
    all_ids = list(project.points)
    col = {pid: i for i, pid in enumerate(all_ids)}
    n_f = project.frame_count
    pos = np.full((n_f, len(all_ids), 3), np.nan)
    for pid, i in col.items():
        p = project.points[pid]
        have = p.status != ST_NONE
        pos[have, i] = p.pos[have]
    gaps = {}
    weak = {}
    targets = []
    in_range = np.zeros(n_f, bool)
    in_range[start:end + 1] = True
    origins = directions = None
    for pid in ids:
        p = project.points[pid]
        g = gap_frames(p, overwrite) & in_range
        if not g.any():
            continue
        targets.append(col[pid])
        gaps[col[pid]] = g
        weak[col[pid]] = weak_samples(p)
        if single and project.rig is not None:
            n_src = p.contributing()
            for f in np.flatnonzero(g & (n_src == 1)):
                s = int(np.flatnonzero(p.src[f] != SRC_NONE)[0])
                uv = p.uv[f, s]
                if not np.isfinite(uv).all():
                    continue
                o, d = project.rig.camera(s, int(f)).ray(np.asarray(uv, float))
                if origins is None:
                    origins = np.full(pos.shape, np.nan)
                    directions = np.full(pos.shape, np.nan)
                origins[f, col[pid]] = o
                directions[f, col[pid]] = np.reshape(d, 3)
    if not targets:
        return SetPointData([], name="Interpolate Gaps")
    # Frames outside the range that are gaps stay gaps, but are not written.
    for i in targets:
        pid = all_ids[i]
        gaps[i] = gaps[i] | (gap_frames(project.points[pid], overwrite) & ~in_range)
    rays = (origins, directions) if origins is not None else None
    filled, mask = fill_gaps(pos, forwards=forwards, backwards=backwards, targets=targets, rays=rays,
                             gaps=gaps, weak=weak, progress=progress)
    updates = []
    for i in targets:
        m = mask[:, i] & in_range
        if rays is not None:
            on_ray = np.isfinite(origins[:, i]).all(-1)
        else:
            on_ray = np.zeros(n_f, bool)
        for s, e in find_gaps(m):
            n = e - s + 1
            status = np.where(on_ray[s:e + 1], ST_SINGLE, ST_INTERPOLATED).astype(np.uint8)
            updates.append((all_ids[i], s, {"pos": filled[s:e + 1, i].astype(np.float32),
                                            "status": status,
                                            "residual": np.full(n, np.nan, np.float16)}))
    return SetPointData(updates, name="Interpolate Gaps")


def remove_interpolated(project, point_ids=None, start: int | None = None, end: int | None = None) -> SetPointData:
    """Remove Interpolated 3D Points: clear the ``ST_INTERPOLATED`` samples on a frame range.

    Parameters
    ----------
    project : Project
    point_ids : list of int, optional
        Selected points; None or empty: every point.
    start, end : int, optional
        Inclusive range; default the active range.

    Returns
    -------
    SetPointData
        Sets ``pos`` NaN, ``status`` ``ST_NONE`` and ``residual`` NaN on those
        samples; 2D data is kept.
    """
    start, end = _range(project, start, end)
    updates = []
    for pid in _ids(project, point_ids):
        p = project.points[pid]
        m = np.zeros(project.frame_count, bool)
        m[start:end + 1] = p.status[start:end + 1] == ST_INTERPOLATED
        for s, e in find_gaps(m):
            n = e - s + 1
            updates.append((pid, s, {"pos": np.full((n, 3), np.nan, np.float32),
                                     "status": np.full(n, ST_NONE, np.uint8),
                                     "residual": np.full(n, np.nan, np.float16)}))
    return SetPointData(updates, name="Remove Interpolated 3D Points")
