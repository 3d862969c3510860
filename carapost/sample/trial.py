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
