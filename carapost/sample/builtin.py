"""The built-in sample take that ``carapost gui`` (and ``make run``) opens without a file.

Rendered once into the user's cache folder, then set up as a project: media,
calibration, brim and labels, so a new user sees a real take at once.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/carapost/sample-<version>`` (``~/.cache/carapost/sample-0.1.0``).

    Versioned so that a newer renderer or project format renders its own take.
    """
    from .. import __version__

    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "carapost" / f"sample-{__version__}"


def builtin_sample_project(frames: int = 120, markers: int = 100) -> Path:
    """Path of the sample take's ``.cara`` project, rendering it on first use (about half a minute).

    Returns
    -------
    Path
        ``<cache>/Sample.cara``.
    """
    from ..core.document import Document
    from ..core.edits import SetBrim
    from ..io.brim_svg import read_brim_svg
    from ..io.cara import save_project
    from ..io.imports import import_labels_from_text, import_xcp
    from ..io.take import project_from_pico
    from .take import write_sample

    d = cache_dir()
    project_path = d / "Sample.cara"
    if project_path.exists():
        return project_path
    if not (d / "Sample_0.pico").exists():
        print(f"carapost: rendering the sample take into {d} (first use only) ...", file=sys.stderr, flush=True)
        write_sample(d, markers=markers, frames=frames, seed=0)
    project = project_from_pico(d / "Sample_0.pico")
    doc = Document(project)
    doc.run(import_xcp(project, d / "calibration.xcp"))
    doc.run(SetBrim(read_brim_svg(d / "brim.svg"), "Import Calibration Brim [svg]"))
    doc.run(import_labels_from_text(project, d / "labels.txt"))
    save_project(project, project_path)
    return project_path
