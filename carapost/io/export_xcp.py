"""File > Export XCP [Current Frame]: the take's cameras on one frame as an XCP file."""
from __future__ import annotations

from pathlib import Path

from ..core.errors import CaraError
from ..core.project import Project
from .xcp import write_xcp, xcp_from_cameras


def export_xcp(project: Project, path: str | Path, frame: int) -> None:
    """Write the cameras of ``frame`` (one KeyFrame each) to ``path`` atomically.

    Raises
    ------
    CaraError
        When the take has no cameras or the frame is outside the take.
    """
    if project.rig is None:
        raise CaraError("the take has no cameras to export (File > Import XCP first)")
    if not 0 <= frame < project.frame_count:
        raise CaraError(f"frame {frame} is outside the take (0-{project.frame_count - 1})")
    cams = project.rig.cameras_at(frame)
    write_xcp(path, xcp_from_cameras([[(0, c)] for c in cams], name=project.name))
