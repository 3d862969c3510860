"""Open a written sample take as a user starts on it: for benchmarks that score the pipeline against its truth."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def open_sample_take(folder, markers: int, start: int = 0, end: int = 0):
    """The sample take in ``folder`` with its XCP imported and blobs detected on frames ``start..end``.

    The guide's Initialize 3D parameters for the set's size are set: Max Allowed
    Depth 60 mm (the default, sparse sets) or 16 mm (more than 60 markers).

    Returns
    -------
    (Project, Document, dict)
        The project, the document whose undo stack holds those steps, and ``truth.npz``'s arrays.
    """
    from carapost.core.blob_ops import detect_blobs_range
    from carapost.core.document import Document
    from carapost.io.imports import import_xcp
    from carapost.io.take import project_from_input

    folder = Path(folder)
    truth = dict(np.load(folder / "truth.npz"))
    project = project_from_input(str(folder / "Sample_0.pico"), None)
    doc = Document(project)
    if markers > 60:
        project.properties.set("initialize_3d.max_allowed_depth", 16.0)
    doc.run(import_xcp(project, folder / "calibration.xcp", None))
    doc.run(detect_blobs_range(project, start, end))
    return project, doc, truth


def initialise_from_seeds(folder, project, doc, frame: int | None = None) -> None:
    """The first half of ``carapost process`` on an opened sample take: its ``seeds.json`` clicks, Solve
    Calibration Brim with its ``brim.svg``, Bundle Current Frame and Initialize 3D (one undo step each).

    ``frame``: initialise on this frame instead (negative: from the end), with the clicks a person
    makes there (:func:`carapost.sample.take.seeds_of_take`); default the frame of ``seeds.json``.
    """
    import json

    from carapost.core.pipeline import process_to_init3d
    from carapost.io.brim_svg import read_brim_svg

    from .take import seeds_of_take

    folder = Path(folder)
    seeds = json.loads((folder / "seeds.json").read_text())
    if frame is not None:
        seeds = seeds_of_take(folder, frame)
    process_to_init3d(project, seeds, read_brim_svg(folder / "brim.svg"), log=lambda s: None, stack=doc.stack)


def faint_by_camera(markers: int, seed: int, white: bool = False, *, frames: int) -> list[set]:
    """Per camera, the labels of the sample take's markers that are faint on frame 0.

    Faint: in view, but the paint barely changes the image (black paint on a dense
    black brow; :data:`carapost.core.blobs.synth.FAINT`).  Renders frame 0 of the take of
    ``frames`` frames again (its motion, and so its frame 0, depends on its length; with white
    markers for a ``--white`` take: they are never faint).
    """
    from carapost.core.blobs.synth import sample_frames

    return [set(f.faint_names or ()) for f in sample_frames(white, seed=seed, frames=1, markers=markers,
                                                            take_frames=frames)]


def seen(visible: np.ndarray, labels, faint: list[set]) -> np.ndarray:
    """``visible`` (``(..., cameras, markers)`` bool) less each camera's faint markers (a copy)."""
    out = np.asarray(visible).astype(bool).copy()
    labels = [str(v) for v in labels]
    for s, names in enumerate(faint):
        for m, lab in enumerate(labels):
            if lab in names:
                out[..., s, m] = False
    return out
