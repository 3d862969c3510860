"""Build a project from a take's media (File > Import Pico Files, CLI INPUT).

A take is one media source per channel: ``<take>_<channel>.pico`` files, or any
video files or image folders given in channel order (``--sources``).
"""
from __future__ import annotations

import logging
from pathlib import Path

from ..core.errors import CaraError
from ..core.project import MediaRef, Project, SensorInfo
from .media import FrameSource, open_source, take_files

log = logging.getLogger("carapost")

#: Metadata keys a capture may carry for the blob detector's settings, and our property keys.
PICO_BLOB_KEYS = {
    "blob.white_min_radius": "blob.white_min_radius", "blob.white_max_radius": "blob.white_max_radius",
    "blob.black_min_radius": "blob.black_min_radius", "blob.black_max_radius": "blob.black_max_radius",
    "blob.find_black_blobs": "blob.find_black_blobs", "blob.find_white_blobs": "blob.find_white_blobs",
    "blob.black_threshold": "blob.black_threshold", "blob.white_threshold": "blob.white_threshold",
}


def project_from_sources(paths: list[str | Path], name: str = "") -> Project:
    """A new project with one sensor per media source.

    Parameters
    ----------
    paths : list of path
        One ``.pico``, video file or image folder per channel, in channel order.
    name : str
        Take name (default: derived from the first file).

    Returns
    -------
    Project
        Sensors carry the media's size, frame count and path; the take's frame
        count is the longest channel's (shorter channels are reported in the log).

    Raises
    ------
    CaraError
        When a source is missing or unreadable (naming it).
    """
    if not paths:
        raise CaraError("a take needs at least one media source")
    sources: list[FrameSource] = []
    try:
        for p in paths:
            sources.append(open_source(p))
        return project_from_open_sources(sources, name)
    finally:
        for s in sources:
            s.close()


def project_from_open_sources(sources: list[FrameSource], name: str = "") -> Project:
    """Like :func:`project_from_sources` for sources already open."""
    counts = [s.frame_count for s in sources]
    if max(counts) < 1:
        raise CaraError("the take has no frames", sources[0].path)
    frames = max(counts)
    first = sources[0]
    if not name:
        name = first.path.stem.rsplit("_", 1)[0] if first.kind == "pico" else first.path.stem
    project = Project(frames, len(sources), float(first.frame_rate or 60.0),
                      first.metadata.get("this_capture.timecode", first.metadata.get("timecode", "00:00:00:00")),
                      name=name)
    for i, s in enumerate(sources):
        project.sensors[i] = SensorInfo(f"Channel {i}", int(s.width), int(s.height), int(s.frame_count),
                                        media=MediaRef(str(Path(s.path).absolute()), kind=s.kind))
        for w in s.warnings:
            log.warning(w)
        if s.frame_count != frames:
            log.warning(f"{s.path}: channel {i} has {s.frame_count} frames, the take {frames}")
    blob = {}
    for key, prop in PICO_BLOB_KEYS.items():
        if key in first.metadata:
            blob[prop] = first.metadata[key]
    project.pico_blob_parameters = blob
    if blob:
        from ..core.properties import property_def

        for k, v in blob.items():
            project.properties.set(k, property_def(k).coerce(v))
    return project


def project_from_pico(pico_path: str | Path) -> Project:
    """A project from all channel files of the take ``pico_path`` belongs to."""
    files = take_files(pico_path)
    return project_from_sources(files)


def project_from_input(input_path: str | Path | None, sources: list[str] | None = None) -> Project:
    """The CLI's INPUT: a ``.pico`` (its whole take), a ``.cara`` project, or ``--sources``."""
    if sources:
        return project_from_sources(sources)
    if input_path is None:
        raise CaraError("give a .pico file, a .cara project or --sources S0 S1 ...")
    p = Path(input_path)
    if p.suffix.lower() == ".cara":
        from .cara import load_project

        return load_project(p)
    if p.suffix.lower() == ".pico":
        return project_from_pico(p)
    return project_from_sources([p])
