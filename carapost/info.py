"""``carapost info FILE``: a summary of what a project, calibration, video or C3D file holds."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .core.errors import CaraError


def describe(path: str | Path) -> dict:
    """Summarise a ``.cara``, ``.xcp``, ``.pico`` or ``.c3d`` file as a nested dict.

    Raises
    ------
    CaraError
        For a missing file, an unknown kind of file or a bad one.
    """
    path = Path(path)
    if not path.exists():
        raise CaraError("no such file", path)
    ext = path.suffix.lower()
    if ext == ".cara":
        return _describe_cara(path)
    if ext == ".xcp":
        return _describe_xcp(path)
    if ext == ".pico":
        from .io.pico import pico_info

        return pico_info(path)
    if ext == ".c3d":
        from .io.c3d import c3d_info

        return c3d_info(path)
    raise CaraError("unknown kind of file (expected .cara, .xcp, .pico or .c3d)", path)


def _describe_cara(path: Path) -> dict:
    from .io.cara import load_project, read_header

    version, _ = read_header(path)
    p = load_project(path)
    present = sum(int(np.count_nonzero(pt.status)) for pt in p.points.values())
    return {
        "file": str(path), "kind": "carapost project", "format_version": version,
        "take": p.name, "frames": p.frame_count, "frame_rate": p.frame_rate, "timecode_start": p.timecode_start,
        "sensors": [{"name": s.name, "size": f"{s.width}x{s.height}", "frames": s.frame_count,
                     "rotation_deg": 90 * s.rotation, "image_offset": s.image_offset,
                     "media": s.media.path + (" (missing)" if s.media.missing else "")} for s in p.sensors],
        "detections": [d.total() for d in p.detections],
        "points": {"face": sum(1 for x in p.points.values() if x.kind == "face"),
                   "brim": sum(1 for x in p.points.values() if x.kind == "brim"),
                   "labelled": sum(1 for x in p.points.values() if x.label),
                   "samples_3d": present},
        "labels": len(p.labels), "sticks": len(p.sticks),
        "cameras": "none" if p.rig is None else f"{p.rig.sensors} ({int(p.rig.solved.sum())} solved poses)",
        "brim": "none" if p.brim is None else f"{p.brim.name} ({len(p.brim)} markers)",
        "active_range": list(p.active_range), "view_range": list(p.view_range),
        "changed_properties": p.properties.changed(),
    }


def _describe_xcp(path: Path) -> dict:
    from .io.xcp import read_xcp

    x = read_xcp(path)
    cams = []
    for c in x.cameras:
        cam = c.keyframes[0].camera
        cams.append({
            "name": cam.name, "device_id": cam.device_id, "sensor_size": f"{cam.sensor_size[0]}x{cam.sensor_size[1]}",
            "focal_length_px": round(float(cam.focal_length), 3), "distortion": cam.distortion_model,
            "keyframes": len(c.keyframes),
            "position_mm": [round(float(v), 3) for v in cam.position],
        })
    return {"file": str(path), "kind": "XCP camera calibration", "cameras": len(cams), "camera": cams}
