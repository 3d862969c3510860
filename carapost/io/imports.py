"""File-menu imports that build undoable commands: Import XCP and Import Labels."""
from __future__ import annotations

from pathlib import Path

from ..core.edits import SetLabels, SetRig
from ..core.errors import CaraError
from ..core.labels import merge_labels, read_label_file
from ..core.project import Project
from ..core.rig import rig_from_keyframes
from .cara import read_labels
from .xcp import read_xcp


def import_xcp(project: Project, path: str | Path, log=None) -> SetRig:
    """File > Import XCP: the command that sets the take's cameras from an XCP file.

    XCP cameras map to sensors in file order.  A file with more cameras than the
    take has sensors uses the first ones (and says so through ``log``).

    Raises
    ------
    CaraError
        For a bad file, or one with fewer cameras than the take has sensors.
    """
    xcp = read_xcp(path)
    n = project.sensor_count
    if len(xcp.cameras) < n:
        raise CaraError(f"has {len(xcp.cameras)} cameras; the take has {n} sensors", path)
    if len(xcp.cameras) > n and log is not None:
        log.warning(f"{path}: {len(xcp.cameras)} cameras; using the first {n} for the take's sensors")
    kfs = [[(k.frame, k.camera) for k in c.keyframes] for c in xcp.cameras[:n]]
    return SetRig(rig_from_keyframes(kfs, project.frame_count), name="Import XCP")


def import_labels_from_text(project: Project, path: str | Path) -> SetLabels:
    """File > Import Labels From Text File: adds to the labels; duplicates get `` - Copy``."""
    return SetLabels(merge_labels(project.labels, read_label_file(path)), name="Import Labels From Text File")


def import_labels_from_cara(project: Project, path: str | Path) -> SetLabels:
    """File > Import Labels From Cara File."""
    return SetLabels(merge_labels(project.labels, read_labels(path)), name="Import Labels From Cara File")
