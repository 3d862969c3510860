"""File > Export C3D: a project's points as a C3D file (CONTRACT section 5)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.points import BRIM, SRC_NONE, ST_INTERPOLATED, ST_NONE, ST_SINGLE, Point
from ..core.project import Project
from ..core.stabilize_ops import stabilize_array
from .c3d import write_c3d


def project_c3d_arrays(project: Project, start: int = 0, end: int | None = None):
    """What a C3D export of frames ``start..end`` (inclusive) holds.

    Returns
    -------
    positions : ndarray (F, P, 3)
        mm, NaN where the point has no 3D sample (or an interpolated one that
        ``export.include_interpolated`` leaves out).
    residuals : ndarray (F, P)
        RMS reprojection error in pixels of measured samples; 0 for interpolated
        and single-sensor samples (a modelled sample in C3D terms).
    masks : ndarray (F, P) uint8
        Bit i set where sensor i's 2D data built the sample; cleared for
        interpolated and single-sensor samples (reference 003).
    labels : list of str
        The point's label, or ``Point_<id>``.
    """
    props = project.properties
    end = project.frame_count - 1 if end is None else end
    sl = slice(start, end + 1)
    pts = exported_points(project)
    F = end - start + 1
    pos = np.full((F, len(pts), 3), np.nan)
    res = np.zeros((F, len(pts)))
    masks = np.zeros((F, len(pts)), np.uint8)
    bits = (1 << np.arange(min(project.sensor_count, 7))).astype(np.uint8)
    for j, p in enumerate(pts):
        st = p.status[sl]
        keep = st != ST_NONE
        if not props.export.include_interpolated:
            keep &= st != ST_INTERPOLATED
        pos[keep, j] = p.pos[sl][keep]
        measured = keep & (st != ST_INTERPOLATED) & (st != ST_SINGLE)
        r = np.asarray(p.residual[sl], float)
        res[measured, j] = np.nan_to_num(r[measured], nan=0.0)
        contributing = (p.src[sl][:, :len(bits)] != SRC_NONE)
        m = (contributing * bits).sum(axis=1).astype(np.uint8)
        masks[measured, j] = m[measured]
    if props.export.use_stabilized_data and project.stabilization is not None:
        # Stabilised (and aligned) positions; frames the stabilisation does not cover are missing.
        pos = stabilize_array(project, pos, start)
        gone = ~np.isfinite(pos).all(axis=2)
        res[gone] = 0.0
        masks[gone] = 0
    return pos, res, masks, [p.name for p in pts]


def exported_points(project: Project) -> list[Point]:
    """The points an export writes, in project order (brim points unless ``export.include_brim_points`` is off)."""
    keep_brim = project.properties.export.include_brim_points
    return [p for p in project.points.values() if keep_brim or p.kind != BRIM]


def export_range(project: Project) -> tuple[int, int]:
    """First and last frame an export writes: the active range with ``export.active_range_only``, else the take."""
    return project.active_range if project.properties.export.active_range_only else (0, project.frame_count - 1)


def export_c3d(project: Project, path: str | Path) -> None:
    """Write the project's points to ``path`` (atomic), honouring the Export properties."""
    start, end = export_range(project)
    pos, res, masks, labels = project_c3d_arrays(project, start, end)
    write_c3d(path, pos, labels, project.frame_rate, residuals=res, camera_masks=masks, first_frame=start + 1)
