"""seeds.json (CONTRACT section 3): the clicks a person makes, applied headless."""
from __future__ import annotations

import numpy as np

from ..commands import Command, CompoundCommand
from ..edits import AddPoints, SetPointData
from ..editing import merge
from ..errors import CaraError
from ..points import BRIM, SRC_DETECTION
from .brim_solve import brim_points

#: A click takes the nearest detection within this distance (px).
CLICK_RADIUS_PX = 6.0


def nearest_detection(project, sensor: int, frame: int, uv, what: str) -> int:
    """Index of the detection nearest ``uv`` within :data:`CLICK_RADIUS_PX`, else CaraError naming ``what``."""
    rec = project.detections[sensor].frame(frame)
    if len(rec):
        d = np.hypot(rec["x"] - float(uv[0]), rec["y"] - float(uv[1]))
        i = int(np.argmin(d))
        if d[i] <= CLICK_RADIUS_PX:
            return i
    raise CaraError(f"seed {what}: no detection within {CLICK_RADIUS_PX:g} px of the click "
                    f"({float(uv[0]):.1f}, {float(uv[1]):.1f}) in channel {sensor} on frame {frame}")


def _sensor(project, key) -> int:
    s = int(key)
    if not 0 <= s < project.sensor_count:
        raise CaraError(f"seeds name channel {key}, the take has {project.sensor_count}")
    return s


def apply_seeds(project, seeds: dict, parts=("brim", "face")) -> Command:
    """Apply a seeds.json dict: brim correspondences and face seed points.

    Parameters
    ----------
    project : Project
    seeds : dict
        ``{"frame": F, "brim": [{"index", "uv"}], "face": [{"label"?, "uv"}]}``.
    parts : tuple of str
        Which lists to apply (the pipeline applies the brim before solving it,
        and the face seeds after).

    Returns
    -------
    Command
        One history entry; face seeds are Edit > Merge of their detections
        (triangulated when cameras are known), labelled when a label is given.

    Raises
    ------
    CaraError
        A click with no detection near it (the seed is named), an unknown brim
        index, or two seeds on one detection.  The project is left unchanged.
    """
    frame = int(seeds.get("frame", 0))
    if not 0 <= frame < project.frame_count:
        raise CaraError(f"seeds frame {frame} is outside the take (0-{project.frame_count - 1})")
    # Resolve every click first: a bad seed fails before anything changes.
    brim_entries, face_entries = [], []
    taken: dict[tuple[int, int], str] = {}

    def claim(s, i, what):
        if (s, i) in taken:
            raise CaraError(f"seeds {taken[(s, i)]} and {what} take the same detection {i} in channel {s}")
        taken[(s, i)] = what

    def resolve(entry, what) -> dict[int, int]:
        """Each click of a seed -> the detection it takes, per sensor."""
        dets = {}
        for key, uv in entry.get("uv", {}).items():
            s = _sensor(project, key)
            dets[s] = nearest_detection(project, s, frame, uv, what)
            claim(s, dets[s], what)
        return dets

    if "brim" in parts:
        for k, e in enumerate(seeds.get("brim", [])):
            idx = int(e["index"])
            what = f"brim[{k}] (brim marker {idx})"
            if project.brim is None:
                raise CaraError(f"seed {what}: no calibration brim is set")
            if not 0 <= idx < len(project.brim):
                n = len(project.brim)
                # Seeds written for another brim (a take's own brim.svg against a default one) fail here first.
                raise CaraError(f"seed {what}: the calibration brim has {n} markers (0-{n - 1}); is it the brim "
                                f"the take was captured with?")
            brim_entries.append((idx, resolve(e, what)))
    if "face" in parts:
        for k, e in enumerate(seeds.get("face", [])):
            label = e.get("label") or None
            what = f"face[{k}]" + (f" ({label})" if label else "")
            face_entries.append((label, resolve(e, what)))

    done: list[Command] = []
    try:
        if brim_entries:
            cmd = brim_command(project, frame, brim_entries)
            cmd.do(project)
            done.append(cmd)
        for label, dets in face_entries:
            if not dets:
                continue
            cmd = merge(project, frame, detections=[(s, frame, i) for s, i in dets.items()], label=label,
                        name="Merge Seed")
            cmd.do(project)
            done.append(cmd)
    finally:
        # Built by doing (each merge sees the previous ones); undone so that the caller pushes it.
        for c in reversed(done):
            c.undo(project)
    out = CompoundCommand("Apply Seeds", done)
    out.summary = f"Apply Seeds: {len(brim_entries)} brim and {len(face_entries)} face seeds on frame {frame}"
    return out


def brim_command(project, frame: int, entries, name: str = "Brim Seeds") -> Command:
    """Attach detections of ``frame`` to brim markers (seeds.json's brim entries, the Brim window's clicks).

    Parameters
    ----------
    project : Project
    frame : int
    entries : list of (int, dict)
        ``(brim marker index, {sensor: detection index})``, already checked against the project.
    name : str
        History entry.

    Returns
    -------
    Command
        Not yet done.  A missing brim point is created; an attachment replaces
        the brim point's earlier sample in that channel; a detection held by any
        other point is detached from it (a detection belongs to one point).
    """
    bp = brim_points(project)
    new, updates = [], []
    nid = project.next_point_id
    for idx, dets in entries:
        if idx in bp:
            p = bp[idx]
            row = {k: p.arrays[k][frame:frame + 1].copy() for k in ("src", "det", "uv", "score")}
        else:
            p = project.new_point(BRIM, brim_index=idx, point_id=nid)
            nid += 1
            row = {k: p.arrays[k][frame:frame + 1].copy() for k in ("src", "det", "uv", "score")}
        for s, i in dets.items():
            rec = project.detections[s].frame(frame)[i]
            row["src"][0, s] = SRC_DETECTION
            row["det"][0, s] = i
            row["uv"][0, s] = (rec["x"], rec["y"])
            row["score"][0, s] = rec["score"]
        if idx in bp:
            updates.append((p.id, frame, row))
        else:
            for k, v in row.items():
                p.arrays[k][frame:frame + 1] = v
            new.append(p)
    cmds: list[Command] = []
    # A detection belongs to one point: take it from whoever holds it.
    pairs = {(s, i) for _idx, dets in entries for s, i in dets.items()}
    mine = {p.id for p in bp.values()}
    for q in project.points.values():
        row = None
        for s, i in pairs:
            if q.src[frame, s] == SRC_DETECTION and q.det[frame, s] == i and not (
                    q.id in mine and any(q.brim_index == idx and dets.get(s) == i for idx, dets in entries)):
                if row is None:
                    row = {k: q.arrays[k][frame:frame + 1].copy() for k in ("src", "det", "uv", "score")}
                row["src"][0, s], row["det"][0, s] = 0, -1
                row["uv"][0, s], row["score"][0, s] = np.nan, np.nan
        if row is not None and q.id not in {u[0] for u in updates}:
            cmds.append(SetPointData([(q.id, frame, row)], name="Detach Detections"))
    if new:
        cmds.append(AddPoints(new, name="Add Brim Points"))
    if updates:
        cmds.append(SetPointData(updates, name="Attach Brim Detections"))
    return CompoundCommand(name, cmds)
