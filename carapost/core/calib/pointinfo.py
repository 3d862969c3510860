"""View > Get Point Information and View > Distance Between Two Points, as data."""
from __future__ import annotations

import numpy as np

from ..camera import centroid
from ..errors import CaraError
from ..points import SRC_DETECTION, SRC_NONE, ST_NONE


def point_information(project, pid: int, frame: int) -> dict:
    """Everything Get Point Information reports about a point on ``frame``.

    Returns
    -------
    dict
        ``id, label, kind, frame, position`` (mm or None), ``residual`` (px),
        ``sensors``: per sensor ``{uv, major, minor}`` (sizes of the attached
        detection, px; None without one), ``caddy_distance``: ``{"0-1": mm, ...}``
        to each caddy's cameras' centroid, ``all_cameras_distance`` (mm).
    """
    p = project.point(pid)
    frame = project.clamp_frame(frame)
    present = p.status[frame] != ST_NONE
    info = {"id": p.id, "label": p.label, "kind": p.kind, "frame": frame,
            "position": p.pos[frame].astype(float).tolist() if present else None,
            "residual": float(p.residual[frame]) if present else None, "sensors": {},
            "caddy_distance": {}, "all_cameras_distance": None}
    for s in range(project.sensor_count):
        if p.src[frame, s] == SRC_NONE:
            info["sensors"][s] = None
            continue
        e = {"uv": p.uv[frame, s].astype(float).tolist(), "major": None, "minor": None}
        d = int(p.det[frame, s])
        if p.src[frame, s] == SRC_DETECTION and 0 <= d < project.detections[s].count(frame):
            rec = project.detections[s].frame(frame)[d]
            e["major"], e["minor"] = float(rec["major"]), float(rec["minor"])
        info["sensors"][s] = e
    if project.rig is not None and present:
        cams = project.rig.cameras_at(frame)
        X = p.pos[frame].astype(float)
        for a, b in project.caddies():
            info["caddy_distance"][f"{a}-{b}"] = float(np.linalg.norm(X - centroid([cams[a], cams[b]])))
        info["all_cameras_distance"] = float(np.linalg.norm(X - centroid(cams)))
    return info


def format_point_information(info: dict) -> str:
    """The log text of :func:`point_information`."""
    lines = [f"Point {info['id']} ({info['label'] or 'unlabelled'}, {info['kind']}) on frame {info['frame']}:"]
    if info["position"] is None:
        lines.append("  3D: none on this frame")
    else:
        x, y, z = info["position"]
        lines.append(f"  3D: ({x:.3f}, {y:.3f}, {z:.3f}) mm, residual {info['residual']:.3f} px")
    for s, e in info["sensors"].items():
        if e is None:
            lines.append(f"  sensor {s}: no 2D data")
        else:
            size = f", size {e['major']:.1f} x {e['minor']:.1f} px" if e["major"] is not None else ""
            lines.append(f"  sensor {s}: ({e['uv'][0]:.2f}, {e['uv'][1]:.2f}) px{size}")
    for k, v in info["caddy_distance"].items():
        lines.append(f"  distance to the centroid of caddy {k}: {v:.2f} mm")
    if info["all_cameras_distance"] is not None:
        lines.append(f"  distance to the centroid of all cameras: {info['all_cameras_distance']:.2f} mm")
    return "\n".join(lines)


def distance_between_points(project, a: int, b: int, frame: int) -> dict:
    """Distance between two points on ``frame`` in brim units (mm: the brim defines the world).

    Raises
    ------
    CaraError
        When either point has no 3D position on the frame.
    """
    pa, pb = project.point(a), project.point(b)
    for p in (pa, pb):
        if p.status[frame] == ST_NONE:
            raise CaraError(f"point {p.name} has no 3D position on frame {frame}")
    d = float(np.linalg.norm(pa.pos[frame].astype(float) - pb.pos[frame].astype(float)))
    return {"a": a, "b": b, "frame": frame, "distance": d, "units": "mm",
            "text": f"Distance between {pa.name} and {pb.name} on frame {frame}: {d:.3f} mm"}
