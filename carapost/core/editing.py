"""Manual editing: the Edit menu's point, detection, label and stick operations.

Each function validates its inputs against the project, computes the result
and returns one undoable :class:`~carapost.core.commands.Command` named after
the menu item; nothing changes until the caller pushes it on the undo stack.
Commands are built from the primitives of :mod:`carapost.core.edits` and keep
only the slices they change.  A command may carry ``select_after`` (point ids
the GUI selects once it ran) and ``summary`` (one line for the log).

The second half holds the queries the View menu's navigation items use (next
keyframe, next gap, fewest gaps, next label, point information).
"""
from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np

from .commands import Command, CompoundCommand
from .edits import AddPoints, ClearPointRange, DeletePoints, RenamePoint, SetLabels, SetPointData, SetSticks
from .errors import CaraError
from .points import (POINT_FIELDS, SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, ST_INTERPOLATED, ST_NONE,
                     ST_RECONSTRUCTED, Point)
from .project import Project, Stick

#: Half sizes (pattern w, h, search w, h) in pixels of a new target-track keyframe.
DEFAULT_KEYFRAME_BOX = (8.0, 8.0, 16.0, 16.0)

Detection = tuple[int, int, int]  #: (sensor, frame, index in that frame's records)


# ============================================================== small commands
class SetKeyframes(Command):
    """Replace a point's target-track keyframes (``(frame, sensor) -> box``)."""

    def __init__(self, pid: int, keyframes: dict, name: str = "Edit Keyframes"):
        self.pid = int(pid)
        self.keyframes = dict(keyframes)
        self.name = name
        self._old: dict = {}

    def do(self, project: Project) -> None:
        p = project.point(self.pid)
        self._old = dict(p.keyframes)
        p.keyframes = dict(self.keyframes)

    def undo(self, project: Project) -> None:
        project.point(self.pid).keyframes = dict(self._old)


class SetChannelSelection(Command):
    """The Selection pane's explicit channel selection (``[]``: the active view's channel)."""

    def __init__(self, channels: Iterable[int], name: str = "Select Channels"):
        self.channels = sorted({int(c) for c in channels})
        self.name = name
        self._old: list[int] = []

    def do(self, project: Project) -> None:
        bad = [c for c in self.channels if not 0 <= c < project.sensor_count]
        if bad:
            raise CaraError(f"the take has no channel {bad[0]}")
        self._old = list(project.channel_selection)
        project.channel_selection = list(self.channels)

    def undo(self, project: Project) -> None:
        project.channel_selection = list(self._old)


class RenameLabel(Command):
    """Rename a label of the label list, and the point that carries it."""

    def __init__(self, old: str, new: str, name: str = "Rename Label"):
        self.old, self.new = old, new.strip()
        self.name = name
        self._pid: int | None = None

    def do(self, project: Project) -> None:
        if self.old not in project.labels:
            raise CaraError(f"there is no label {self.old!r}")
        if not self.new:
            raise CaraError("a label needs a name")
        if self.new != self.old and self.new in project.labels:
            raise CaraError(f"the label {self.new!r} exists already")
        project.labels[project.labels.index(self.old)] = self.new
        holder = project.point_by_label(self.old)
        self._pid = holder.id if holder is not None else None
        if holder is not None:
            holder.label = self.new

    def undo(self, project: Project) -> None:
        project.labels[project.labels.index(self.new)] = self.old
        if self._pid is not None:
            project.points[self._pid].label = self.old


def _named(cmd: Command, summary: str = "", select_after: Sequence[int] | None = None) -> Command:
    cmd.summary = summary or cmd.name
    cmd.select_after = None if select_after is None else [int(i) for i in select_after]
    return cmd


# ===================================================================== helpers
def _has_data(p: Point, sl: slice) -> np.ndarray:
    """Frames of ``sl`` where the point has a 3D sample or any 2D sample."""
    return (p.status[sl] != ST_NONE) | np.any(p.src[sl] != SRC_NONE, axis=1)


def _check_frame(project: Project, frame: int) -> int:
    if not 0 <= int(frame) < project.frame_count:
        raise CaraError(f"frame {frame} is outside the take (0-{project.frame_count - 1})")
    return int(frame)


def _check_points(project: Project, ids: Iterable[int], what: str, least: int = 1) -> list[int]:
    ids = list(dict.fromkeys(int(i) for i in ids))
    for pid in ids:
        project.point(pid)
    if len(ids) < least:
        need = "a point" if least == 1 else f"{least} points"
        raise CaraError(f"{what} needs {need} selected")
    return ids


def _check_detections(project: Project, detections: Iterable[Detection]) -> list[Detection]:
    out = list(dict.fromkeys((int(s), int(f), int(i)) for s, f, i in detections))
    for s, f, i in out:
        if not 0 <= s < project.sensor_count:
            raise CaraError(f"the take has no sensor {s}")
        _check_frame(project, f)
        if not 0 <= i < project.detections[s].count(f):
            raise CaraError(f"sensor {s} has no detection {i} on frame {f}")
    return out


def _clear_2d(row: dict, r: int, s: int) -> None:
    for k in ("src", "det", "uv", "score"):
        row[k][r, s] = POINT_FIELDS[k][2]


def _attach(row: dict, r: int, s: int, index: int, record) -> None:
    row["src"][r, s] = SRC_DETECTION
    row["det"][r, s] = index
    row["uv"][r, s] = (record["x"], record["y"])
    row["score"][r, s] = record["score"]


def reconstruct_sample(project: Project, frame: int, src: np.ndarray, uv: np.ndarray):
    """Triangulate one point on ``frame`` from its 2D samples.

    Parameters
    ----------
    project : Project
    frame : int
    src : ndarray (S,)
        ``SRC_*`` per sensor.
    uv : ndarray (S, 2)
        Raw pixels per sensor.

    Returns
    -------
    (pos, residual) or None
        The 3D position (mm) and RMS reprojection error (px), or None when the
        cameras are unknown or fewer than two sensors see the point.
    """
    from .camera import reprojection_errors, triangulate

    valid = (src != SRC_NONE) & np.all(np.isfinite(uv), axis=1)
    if project.rig is None or np.count_nonzero(valid) < 2:
        return None
    cams = project.rig.cameras_at(frame)
    obs = np.where(valid[:, None], uv, np.nan).astype(np.float64)
    X = triangulate(cams, obs)
    if not np.all(np.isfinite(X)):
        return None
    err = reprojection_errors(cams, X, obs)[valid]
    return X, float(np.sqrt(np.nanmean(err ** 2)))


def _set_3d(project: Project, frame: int, row: dict, r: int) -> bool:
    """Re-triangulate row ``r`` (frame ``frame``) in place; True when it has a 3D position."""
    got = reconstruct_sample(project, frame, row["src"][r], row["uv"][r])
    if got is None:
        return False
    row["pos"][r], row["residual"][r], row["status"][r] = got[0], got[1], ST_RECONSTRUCTED
    return True


def _detach_from_others(project: Project, frame: int, pairs: Iterable[tuple[int, int]], keep: set[int]):
    """SetPointData detaching detections ``(sensor, index)`` of ``frame`` from points not in ``keep``."""
    pairs = list(pairs)
    updates = []
    for q in project.points.values():
        if q.id in keep:
            continue
        row = None
        for s, i in pairs:
            if q.src[frame, s] == SRC_DETECTION and q.det[frame, s] == i:
                if row is None:
                    row = {k: q.arrays[k][frame:frame + 1].copy() for k in ("src", "det", "uv", "score")}
                _clear_2d(row, 0, s)
        if row is not None:
            updates.append((q.id, frame, row))
    return SetPointData(updates, name="Detach Detections") if updates else None


# ======================================================================= merge
def merge(project: Project, frame: int, point_ids: Sequence[int] = (), detections: Iterable[Detection] = (),
          label: str | None = None, name: str = "Merge") -> Command:
    """Edit > Merge: the selected points and detections become one point.

    Parameters
    ----------
    project : Project
    frame : int
        The current frame; selected detections must be on it.
    point_ids : sequence of int
        Selected points in selection order; the first one is kept.
    detections : iterable of (sensor, frame, index)
        Selected detections: at most one per sensor.
    label : str, optional
        Label for the merged point (Merge and Select Next Label).
    name : str
        History entry.

    Returns
    -------
    Command
        With ``select_after = [merged point id]``.

    Notes
    -----
    On every frame other than ``frame`` the first selected point that has data
    there wins.  On ``frame`` the 2D samples are combined sensor by sensor
    (first selected wins, selected detections override) and the point is
    triangulated from them when the cameras are known.  A detection attached to
    another point is detached from it: a detection belongs to one point.

    Raises
    ------
    CaraError
        For two detections in one sensor, a detection on another frame, or a
        selection with nothing to merge.
    """
    frame = _check_frame(project, frame)
    ids = _check_points(project, point_ids, name, least=0)
    dets = _check_detections(project, detections)
    by_sensor: dict[int, int] = {}
    for s, f, i in dets:
        if f != frame:
            raise CaraError(f"{name}: detection {i} of sensor {s} is on frame {f}, not on the current frame {frame}")
        if s in by_sensor:
            raise CaraError(f"{name}: two selected detections are in sensor {s}; a point takes at most one "
                            "detection per sensor on a frame, so deselect one of them")
        by_sensor[s] = i
    if not by_sensor and len(ids) < 2:
        raise CaraError(f"{name} needs two or more points, or detections, selected")

    new_point = None if ids else project.new_point()
    target = project.point(ids[0]) if ids else new_point
    others = [project.point(i) for i in ids[1:]]
    # The frames this command rewrites: the current one and wherever a merged point has data.
    lo = hi = frame
    for o in others:
        present = np.flatnonzero(_has_data(o, slice(None)))
        if len(present):
            lo, hi = min(lo, int(present[0])), max(hi, int(present[-1]))
    sl = slice(lo, hi + 1)
    row = {k: a[sl].copy() for k, a in target.arrays.items()}
    r = frame - lo
    taken = _has_data(target, sl)
    keyframes = dict(target.keyframes)
    for o in others:
        fill = _has_data(o, sl) & ~taken
        fill[r] = False
        for k in row:
            row[k][fill] = o.arrays[k][sl][fill]
        taken |= fill
        for s in range(project.sensor_count):          # current frame: sensor by sensor
            if row["src"][r, s] == SRC_NONE and o.src[frame, s] != SRC_NONE:
                for k in ("src", "det", "uv", "score"):
                    row[k][r, s] = o.arrays[k][frame, s]
        if row["status"][r] == ST_NONE and o.status[frame] != ST_NONE:
            for k in ("pos", "status", "residual"):
                row[k][r] = o.arrays[k][frame]
        for key, box in o.keyframes.items():
            keyframes.setdefault(key, box)
    for s, i in by_sensor.items():
        _attach(row, r, s, i, project.detections[s].frame(frame)[i])
    triangulated = _set_3d(project, frame, row, r)

    cmds: list[Command] = []
    detach = _detach_from_others(project, frame, by_sensor.items(), set(ids))
    if detach is not None:
        cmds.append(detach)
    if new_point is not None:
        for k, v in row.items():
            new_point.arrays[k][sl] = v
        cmds.append(AddPoints([new_point]))
    else:
        cmds.append(SetPointData([(target.id, lo, row)]))
        if keyframes != target.keyframes:
            cmds.append(SetKeyframes(target.id, keyframes))
    gone = {o.id for o in others}
    if gone and any(s.a in gone or s.b in gone for s in project.sticks):
        cmds.append(SetSticks(_remap_sticks(project.sticks, gone, target.id)))
    if others:
        cmds.append(DeletePoints(sorted(gone)))
    final = label if label is not None else (target.label or next((o.label for o in others if o.label), ""))
    if final != target.label:
        cmds.append(RenamePoint(target.id, final))
    what = []
    if len(ids) > 1:
        what.append(f"{len(ids)} points")
    if by_sensor:
        what.append(f"{len(by_sensor)} detection{'s' if len(by_sensor) > 1 else ''}")
    summary = (f"{name}: {' and '.join(what)} into point {target.id}"
               + (f" (labelled {final})" if final else "")
               + (f", triangulated on frame {frame} (RMS error {row['residual'][r]:.2f} px)" if triangulated else ""))
    return _named(CompoundCommand(name, cmds), summary, [target.id])


def _remap_sticks(sticks: list[Stick], gone: set[int], target: int) -> list[Stick]:
    out, seen = [], set()
    for s in sticks:
        a, b = (target if s.a in gone else s.a), (target if s.b in gone else s.b)
        key = (min(a, b), max(a, b))
        if a != b and key not in seen:
            seen.add(key)
            out.append(Stick(a, b, s.color))
    return out


def create_points_from_detections(project: Project, detections: Iterable[Detection]) -> Command:
    """Edit > Create Points From Detections: a new point per selected detection.

    Raises
    ------
    CaraError
        When no detection is selected.
    """
    dets = _check_detections(project, detections)
    if not dets:
        raise CaraError("Create Points From Detections needs detections selected")
    cmds: list[Command] = []
    points = []
    base = project.next_point_id
    for k, (s, f, i) in enumerate(dets):
        p = project.new_point(point_id=base + k)
        row = {n: p.arrays[n][f:f + 1] for n in ("src", "det", "uv", "score")}
        _attach(row, 0, s, i, project.detections[s].frame(f)[i])
        points.append(p)
    # Detach the detections from the points holding them (one owner per detection),
    # one command per frame so that two detections of one point on a frame are both detached.
    by_frame: dict[int, list[tuple[int, int]]] = {}
    for s, f, i in dets:
        by_frame.setdefault(f, []).append((s, i))
    for f, pairs in by_frame.items():
        d = _detach_from_others(project, f, pairs, set())
        if d is not None:
            cmds.append(d)
    cmds.append(AddPoints(points))
    name = "Create Points From Detections"
    return _named(CompoundCommand(name, cmds), f"{name}: {len(points)} new point(s)", [p.id for p in points])


# ================================================================ delete, clear
def delete_detections(project: Project, detections: Iterable[Detection], keep_points: set[int] = frozenset()):
    """Commands removing detections from their frames and fixing the indices points hold."""
    dets = _check_detections(project, detections)
    cells: dict[tuple[int, int], list[int]] = {}
    for s, f, i in dets:
        cells.setdefault((s, f), []).append(i)
    new_cells = {}
    updates: dict[tuple[int, int], dict] = {}
    for (s, f), idx in cells.items():
        rec = project.detections[s].frame(f)
        removed = np.zeros(len(rec), bool)
        removed[idx] = True
        new_cells[(s, f)] = rec[~removed].copy()
        shift = np.cumsum(removed)                     # removed records at or before each index
        for q in project.points.values():
            if q.id in keep_points or q.src[f, s] != SRC_DETECTION or q.det[f, s] < 0:
                continue
            d = int(q.det[f, s])
            if d >= len(rec):
                continue
            row = updates.setdefault((q.id, f), {k: q.arrays[k][f:f + 1].copy() for k in ("src", "det", "uv", "score")})
            if removed[d]:
                _clear_2d(row, 0, s)
            else:
                row["det"][0, s] = d - shift[d]
    from .edits import SetFrameDetections

    cmds: list[Command] = [SetFrameDetections(new_cells, name="Delete Detections")]
    if updates:
        cmds.append(SetPointData([(pid, f, row) for (pid, f), row in updates.items()], name="Fix Detection Indices"))
    return cmds


def delete_selected(project: Project, point_ids: Sequence[int] = (), detections: Iterable[Detection] = (),
                    sticks: Sequence[int] = ()) -> Command:
    """Edit > Delete Selected: the selected points (whole take), detections and sticks.

    Raises
    ------
    CaraError
        When nothing is selected.
    """
    ids = _check_points(project, point_ids, "Delete Selected", least=0)
    dets = list(detections)
    gone = {int(i) for i in sticks if 0 <= int(i) < len(project.sticks)}
    if not ids and not dets and not gone:
        raise CaraError("Delete Selected needs points, detections or sticks selected")
    cmds: list[Command] = []
    if gone:
        cmds.append(SetSticks([st for i, st in enumerate(project.sticks) if i not in gone], name="Delete Sticks"))
    if dets:
        cmds += delete_detections(project, dets, keep_points=set(ids))
    if ids:
        cmds.append(DeletePoints(ids))
    parts = ([f"{len(ids)} point(s)"] if ids else []) + ([f"{len(dets)} detection(s)"] if dets else []) + (
        [f"{len(gone)} stick(s)"] if gone else [])
    return _named(CompoundCommand("Delete Selected", cmds), "Delete Selected: " + " and ".join(parts), [])


def detach_detections(project: Project, point_ids: Sequence[int], sensors: Sequence[int], start: int, end: int,
                      name: str) -> Command:
    """Edit > Detach Detections: drop the points' 2D data of ``sensors`` on ``start..end``.

    Raises
    ------
    CaraError
        Without points or sensors, or for a range outside the take.
    """
    ids = _check_points(project, point_ids, name)
    sensors = sorted({int(s) for s in sensors})
    if not sensors:
        raise CaraError(f"{name} needs a channel: click in a camera view or select channels in the Selection pane")
    project.check_range(start, end)
    chans = ", ".join(str(s) for s in sensors)
    return _named(ClearPointRange(ids, start, end, sensors, name=name),
                  f"{name}: {len(ids)} point(s), channel(s) {chans}, frames {start}-{end}")


def clear_selected(project: Project, point_ids: Sequence[int], start: int, end: int, name: str) -> Command:
    """Edit > Clear Selected: remove the points' data on ``start..end`` (detections stay in the take)."""
    ids = _check_points(project, point_ids, name)
    project.check_range(start, end)
    return _named(ClearPointRange(ids, start, end, None, name=name),
                  f"{name}: {len(ids)} point(s), frames {start}-{end}")


def clear_active_range(project: Project) -> Command:
    """Edit > Clear Active Range: every point's data in the active range (detections stay)."""
    a, b = project.active_range
    ids = list(project.points)
    if not ids:
        raise CaraError("Clear Active Range: the take has no points")
    return _named(ClearPointRange(ids, a, b, None, name="Clear Active Range"),
                  f"Clear Active Range: {len(ids)} point(s), frames {a}-{b}")


def split_point(project: Project, pid: int, frame: int) -> Command:
    """Edit > Split Selected Point: from ``frame`` on, the point's data moves to a new point.

    Raises
    ------
    CaraError
        When the point has no data from ``frame`` on.
    """
    frame = _check_frame(project, frame)
    p = project.point(pid)
    tail = slice(frame, project.frame_count)
    if not np.any(_has_data(p, tail)) and not any(f >= frame for f, _s in p.keyframes):
        raise CaraError(f"Split Selected Point: point {pid} has no data from frame {frame} on")
    new = project.new_point(kind=p.kind, brim_index=p.brim_index)
    for k, a in p.arrays.items():
        new.arrays[k][tail] = a[tail]
    new.keyframes = {key: box for key, box in p.keyframes.items() if key[0] >= frame}
    cmds: list[Command] = [AddPoints([new]), ClearPointRange([pid], frame, project.frame_count - 1, None)]
    if new.keyframes:
        cmds.append(SetKeyframes(pid, {key: box for key, box in p.keyframes.items() if key[0] < frame}))
    name = "Split Selected Point"
    return _named(CompoundCommand(name, cmds), f"{name}: point {pid} from frame {frame} on is now point {new.id}",
                  [new.id])


def remove_interpolated(project: Project, point_ids: Sequence[int] | None, start: int, end: int) -> Command:
    """Edit > Remove Interpolated 3D Points on ``start..end`` (all points when ``point_ids`` is empty).

    Raises
    ------
    CaraError
        When there is no interpolated sample to remove.
    """
    project.check_range(start, end)
    ids = list(point_ids) if point_ids else list(project.points)
    updates = []
    n = 0
    for pid in ids:
        p = project.point(pid)
        m = p.status[start:end + 1] == ST_INTERPOLATED
        hit = np.flatnonzero(m)
        if not len(hit):
            continue
        a, b = start + int(hit[0]), start + int(hit[-1]) + 1
        mm = m[hit[0]:hit[-1] + 1]
        vals = {k: p.arrays[k][a:b].copy() for k in ("pos", "status", "residual")}
        for k in vals:
            vals[k][mm] = POINT_FIELDS[k][2]
        updates.append((pid, a, vals))
        n += len(hit)
    name = "Remove Interpolated 3D Points"
    if not updates:
        raise CaraError(f"{name}: no interpolated samples in frames {start}-{end}")
    return _named(SetPointData(updates, name=name), f"{name}: {n} samples of {len(updates)} point(s)")


# ===================================================================== labels
def rename_point(project: Project, pid: int, label: str) -> Command:
    """Edit > Rename Point (``""`` unlabels; a label held by another point moves to this one)."""
    project.point(pid)
    label = label.strip()
    return _named(RenamePoint(pid, label), f"Rename Point: point {pid} is now {label or 'unlabelled'}")


def unlabel(project: Project, point_ids: Sequence[int]) -> Command:
    """Edit > Unlabel Selected Points."""
    from .edits import Unlabel

    ids = _check_points(project, point_ids, "Unlabel Selected Points")
    return _named(Unlabel(ids), f"Unlabel Selected Points: {len(ids)} point(s)")


def delete_labels(project: Project, labels: Sequence[str]) -> Command:
    """Edit > Delete Selected Labels (their points are unlabelled)."""
    gone = set(labels)
    if not gone:
        raise CaraError("Delete Selected Labels needs labels selected in the Labelling pane")
    return _named(SetLabels([lb for lb in project.labels if lb not in gone], name="Delete Selected Labels"),
                  f"Delete Selected Labels: {len(gone)} label(s)")


def clear_all_labels(project: Project) -> Command:
    """Edit > Clear All Labels (every point is unlabelled)."""
    return _named(SetLabels([], name="Clear All Labels"), f"Clear All Labels: {len(project.labels)} label(s)")


def reorder_labels(project: Project, order: Sequence[str]) -> Command:
    """The Labelling pane's drag and drop: the same labels in a new order."""
    if sorted(order) != sorted(project.labels):
        raise CaraError("reordering must keep the same labels")
    return _named(SetLabels(list(order), name="Reorder Labels"))


# ===================================================================== sticks
def create_stick(project: Project, point_ids: Sequence[int]) -> Command:
    """Edit > Create Stick from Selected Point: a stick between the two selected points."""
    ids = _check_points(project, point_ids, "Create Stick", least=2)
    if len(ids) != 2:
        raise CaraError("Create Stick needs exactly two points selected")
    a, b = ids
    if any({s.a, s.b} == {a, b} for s in project.sticks):
        raise CaraError(f"points {a} and {b} already have a stick")
    return _named(SetSticks(project.sticks + [Stick(a, b)], name="Create Stick from Selected Point"),
                  f"Create Stick: points {a} and {b}")


def create_stick_mesh(project: Project, frame: int) -> Command:
    """Edit > Create Stick Mesh: a Delaunay mesh over the face points with 3D data on ``frame``."""
    from scipy.spatial import Delaunay, QhullError

    frame = _check_frame(project, frame)
    pts = [p for p in project.face_points() if p.status[frame] != ST_NONE and np.all(np.isfinite(p.pos[frame]))]
    if len(pts) < 3:
        raise CaraError(f"Create Stick Mesh needs three face points with 3D data on frame {frame}")
    X = np.array([p.pos[frame] for p in pts], float)
    X -= X.mean(axis=0)
    # The face is roughly a surface seen from the front: mesh it in its two main directions.
    _u, _s, vt = np.linalg.svd(X, full_matrices=False)
    try:
        tri = Delaunay(X @ vt[:2].T)
    except QhullError:
        raise CaraError("Create Stick Mesh: the points lie on a line") from None
    have = {frozenset((s.a, s.b)) for s in project.sticks}
    sticks = list(project.sticks)
    for simplex in tri.simplices:
        for j in range(3):
            a, b = pts[simplex[j]].id, pts[simplex[(j + 1) % 3]].id
            if frozenset((a, b)) not in have:
                have.add(frozenset((a, b)))
                sticks.append(Stick(min(a, b), max(a, b)))
    added = len(sticks) - len(project.sticks)
    return _named(SetSticks(sticks, name="Create Stick Mesh"), f"Create Stick Mesh: {added} sticks")


def set_stick_color(project: Project, indices: Sequence[int], color: tuple[int, int, int]) -> Command:
    """Edit > Edit Stick Color for sticks ``indices`` (all when empty)."""
    if not project.sticks:
        raise CaraError("Edit Stick Color: the take has no sticks")
    which = set(indices) if indices else set(range(len(project.sticks)))
    sticks = [Stick(s.a, s.b, tuple(int(c) for c in color) if i in which else s.color)
              for i, s in enumerate(project.sticks)]
    return _named(SetSticks(sticks, name="Edit Stick Color"), f"Edit Stick Color: {len(which)} stick(s)")


# =============================================================== target tracks
def add_target_track(project: Project, sensor: int, frame: int, uv) -> Command:
    """Edit > Add Target Track click: a new point with a keyframe at ``uv`` in ``sensor``."""
    frame = _check_frame(project, frame)
    p = project.new_point()
    p.src[frame, sensor] = SRC_KEYFRAME
    p.uv[frame, sensor] = uv
    p.score[frame, sensor] = 1.0
    p.keyframes[(frame, int(sensor))] = DEFAULT_KEYFRAME_BOX
    return _named(AddPoints([p], name="Add Target Track"),
                  f"Add Target Track: point {p.id}, channel {sensor}, frame {frame}", [p.id])


def edit_target_track(project: Project, pid: int, sensor: int, frame: int, uv) -> Command:
    """Edit > Edit Target Track click: the point's sample in ``sensor`` becomes a keyframe at ``uv``."""
    frame = _check_frame(project, frame)
    p = project.point(pid)
    row = {k: a[frame:frame + 1].copy() for k, a in p.arrays.items()}
    row["src"][0, sensor] = SRC_KEYFRAME
    row["det"][0, sensor] = -1
    row["uv"][0, sensor] = uv
    row["score"][0, sensor] = 1.0
    _set_3d(project, frame, row, 0)
    kf = dict(p.keyframes)
    kf[(frame, int(sensor))] = p.keyframes.get((frame, int(sensor)), DEFAULT_KEYFRAME_BOX)
    name = "Edit Target Track"
    return _named(CompoundCommand(name, [SetPointData([(pid, frame, row)]), SetKeyframes(pid, kf)]),
                  f"{name}: point {pid}, channel {sensor}, frame {frame}", [pid])


# ==================================================================== queries
def keyframe_frames(project: Project, point_ids: Iterable[int]) -> list[int]:
    """Sorted frames holding a target-track keyframe of any of the points."""
    frames = {f for pid in point_ids if pid in project.points for f, _s in project.points[pid].keyframes}
    return sorted(frames)


def next_keyframe(project: Project, point_ids: Iterable[int], frame: int, direction: int) -> int | None:
    """View > Next/Prev Key Frame: the next keyframe after ``frame`` (wrapping), None without keyframes."""
    frames = keyframe_frames(project, point_ids)
    if not frames:
        return None
    if direction > 0:
        later = [f for f in frames if f > frame]
        return later[0] if later else frames[0]
    earlier = [f for f in frames if f < frame]
    return earlier[-1] if earlier else frames[-1]


def gap_starts(point: Point) -> np.ndarray:
    """First frames of the point's gaps: runs without 3D between its first and last 3D sample."""
    present = point.status != ST_NONE
    idx = np.flatnonzero(present)
    if len(idx) < 2:
        return np.zeros(0, np.int64)
    seg = present[idx[0]:idx[-1] + 1]
    return np.flatnonzero(seg[:-1] & ~seg[1:]) + 1 + idx[0]


def next_gap(point: Point, frame: int) -> int | None:
    """View > Go To Next Gap of Selected Point: the frame before the next gap after ``frame`` (wrapping)."""
    starts = gap_starts(point)
    if not len(starts):
        return None
    later = starts[starts - 1 > frame]
    return int((later[0] if len(later) else starts[0]) - 1)


def point_with_fewest_gaps(project: Project) -> int | None:
    """View > Select Point With Fewest Gaps: among face points with gaps, the one with fewest (None: no gaps)."""
    best, best_n = None, None
    for p in project.face_points():
        n = len(gap_starts(p))
        if n and (best_n is None or n < best_n):
            best, best_n = p.id, n
    return best


def label_states(project: Project, frame: int) -> dict[str, str]:
    """Labelling pane colours: label -> ``"unassigned"``, ``"assigned"`` or ``"absent"`` (no 3D on ``frame``)."""
    holders = {p.label: p for p in project.points.values() if p.label}
    out = {}
    for lb in project.labels:
        p = holders.get(lb)
        out[lb] = "unassigned" if p is None else ("absent" if p.status[frame] == ST_NONE else "assigned")
    return out


def label_is_missing(project: Project, label: str, frame: int) -> bool:
    """A "disconnected" label: no point, no 3D on ``frame``, or 3D without any 2D sample."""
    p = project.point_by_label(label)
    return p is None or p.status[frame] == ST_NONE or not np.any(p.src[frame] != SRC_NONE)


def next_label(project: Project, current: str | None, frame: int, direction: int, missing_only: bool) -> str | None:
    """View > Select Next/Previous Label: the label after ``current`` in the list (wrapping).

    With ``missing_only`` (Properties > Labelling > Navigate Missing Labels
    Only) labels that are connected on ``frame`` are skipped.
    """
    labels = project.labels
    if not labels:
        return None
    n = len(labels)
    i = labels.index(current) if current in labels else (-1 if direction > 0 else n)
    for k in range(1, n + 1):
        lb = labels[(i + direction * k) % n]
        if not missing_only or label_is_missing(project, lb, frame):
            return lb
    return None
