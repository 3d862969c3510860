"""Attach detections to brim markers by hand: the Brim window's click (Qt-free).

The GUI's counterpart of the brim entries of ``seeds.json`` (CONTRACT section 3):
both go through :func:`carapost.core.calib.seeds.brim_command`, so a click in
the Brim window and a seed change the project alike.  Brim marker ``i`` is the
brim definition's ``i``-th marker (CONTRACT section 4: circle order for an SVG).
"""
from __future__ import annotations

from typing import Iterable

import numpy as np

from .calib.brim_solve import brim_points
from .calib.seeds import brim_command
from .commands import Command
from .errors import CaraError
from .points import SRC_DETECTION

NO_BRIM = ("no calibration brim is set (Process > Initialize Default Calibration Brim, "
           "or File > Import Calibration Brim [svg])")


def attach_name(index: int) -> str:
    """The history entry of attaching to brim marker ``index``."""
    return f"Attach To Brim Marker {int(index)}"


def attach_to_brim_marker(project, frame: int, index: int, detections: Iterable[tuple[int, int, int]]) -> Command:
    """Attach the selected detections of ``frame`` to brim marker ``index``.

    Parameters
    ----------
    project : Project
    frame : int
        The current frame; every detection must be on it.
    index : int
        Brim marker index (the brim definition's order).
    detections : iterable of (sensor, frame, index)
        The detections selected in the camera views, at most one per channel.

    Returns
    -------
    Command
        One history entry ``"Attach To Brim Marker <index>"``, with ``summary``
        and ``select_after`` (the brim point).  The brim point is created when
        the marker has none; in a channel where it held a detection on
        ``frame`` the new one replaces it; a detection held by another point is
        detached from that point.

    Raises
    ------
    CaraError
        Without a brim, for a marker the brim does not have, without
        detections, or for a detection that is not on ``frame``, does not
        exist, or shares its channel with another selected detection.  Nothing
        changes then.
    """
    name = attach_name(index)
    if not 0 <= int(frame) < project.frame_count:
        raise CaraError(f"{name}: frame {frame} is outside the take (0-{project.frame_count - 1})")
    frame, index = int(frame), int(index)
    if project.brim is None or len(project.brim) == 0:
        raise CaraError(f"{name}: {NO_BRIM}")
    if not 0 <= index < len(project.brim):
        raise CaraError(f"{name}: the calibration brim {project.brim.name} has markers 0-{len(project.brim) - 1}")
    by_sensor: dict[int, int] = {}
    for s, f, i in dict.fromkeys((int(s), int(f), int(i)) for s, f, i in detections):
        if not 0 <= s < project.sensor_count:
            raise CaraError(f"{name}: the take has no channel {s}")
        if f != frame:
            raise CaraError(f"{name}: detection {i} of channel {s} is on frame {f}, not on the current frame {frame}")
        if not 0 <= i < project.detections[s].count(frame):
            raise CaraError(f"{name}: channel {s} has no detection {i} on frame {frame}")
        if s in by_sensor:
            raise CaraError(f"{name}: two selected detections are in channel {s}; a brim marker takes one "
                            "detection per channel, so deselect one of them")
        by_sensor[s] = i
    if not by_sensor:
        raise CaraError(f"{name} needs detections selected on the current frame (click one in each camera view "
                        "that sees the marker, Ctrl+click to add)")
    held = brim_points(project).get(index)
    pid = held.id if held is not None else project.next_point_id
    cmd = brim_command(project, frame, [(index, by_sensor)], name=name)
    chans = ", ".join(map(str, sorted(by_sensor)))
    before = 0 if held is None else int(np.count_nonzero(held.src[frame] == SRC_DETECTION))
    cmd.summary = (f"{name}: channel{'s' if len(by_sensor) > 1 else ''} {chans} on frame {frame} "
                   + (f"(new brim point {pid})" if held is None else f"(brim point {pid}, {before} channel(s) before)"))
    cmd.select_after = [pid]
    return cmd


def brim_attachments(project, frame: int) -> dict[int, list[int]]:
    """Brim marker index -> the channels where its brim point holds a detection on ``frame``.

    Markers without a brim point, or whose brim point has no detection on
    ``frame``, are absent.
    """
    out = {}
    markers = 0 if project.brim is None else len(project.brim)
    for idx, p in brim_points(project).items():
        if idx >= markers:          # left by a larger brim that was replaced
            continue
        chans = np.flatnonzero(p.src[frame] == SRC_DETECTION)
        if len(chans):
            out[int(idx)] = [int(c) for c in chans]
    return out
