"""File > Export FBX: a project's points as animated Nulls in a binary FBX 7.4 file (CONTRACT section 5).

The node tree::

    Face                  a static Null at the origin
      <label>             one animated Null per face point
    Brim                  (only when brim points are exported)
      <label>             one animated Null per brim point

Each point's Null is named like its C3D point (its label, or ``Point_<id>``)
and keyed at the take's frame numbers and frame rate with its position in the
brim (world) frame in mm; frames without a 3D sample have no key.  The Export
properties apply as for C3D (see :mod:`.export_c3d`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.points import BRIM
from ..core.project import Project
from .export_c3d import export_range, exported_points, project_c3d_arrays
from .fbx import FbxScene

FACE_NODE = "Face"
BRIM_NODE = "Brim"


def project_fbx_scene(project: Project, frame_range: tuple[int, int] | None = None) -> FbxScene:
    """The FBX scene of a project's points (see the module docstring).

    Parameters
    ----------
    project : Project
    frame_range : (int, int), optional
        First and last frame (inclusive, zero-based); default: the export range
        of the Export properties (the active range or the whole take).

    Raises
    ------
    CaraError
        When ``frame_range`` is outside the take.
    """
    start, end = export_range(project) if frame_range is None else project.check_range(*frame_range)
    pos, _res, _masks, names = project_c3d_arrays(project, start, end)
    kinds = [p.kind for p in exported_points(project)]
    scene = FbxScene(project.frame_rate, take_name=project.name or "Take 001")
    scene.set_time_span(start, end)
    face = scene.add_null(FACE_NODE)
    brim = scene.add_null(BRIM_NODE) if BRIM in kinds else None
    frames = np.arange(start, end + 1)
    for j, (name, kind) in enumerate(zip(names, kinds)):
        node = scene.add_null(name, parent=brim if kind == BRIM else face)
        keep = ~np.isnan(pos[:, j, 0])
        scene.set_translation_keys(node, frames[keep], pos[keep, j])
    return scene


def write_fbx(project: Project, path: str | Path, frame_range: tuple[int, int] | None = None) -> None:
    """Write the project's points to ``path`` as binary FBX 7.4 (atomic).

    Parameters
    ----------
    project : Project
    path : path-like
    frame_range : (int, int), optional
        First and last frame (inclusive); default: the Export properties' range.

    Raises
    ------
    CaraError
        When the range is outside the take or the file cannot be written (an
        existing file is then left as it was).
    """
    project_fbx_scene(project, frame_range).write(path)
