"""Process menu handlers for the operations that exist: blob detection and the default brims.

The other Process items stay disabled in the action registry until their
issues wire them (a ``handler`` here and ``available=True`` there).
"""
from __future__ import annotations

import logging

log = logging.getLogger("carapost")


class ProcessActions:
    """Handlers of the Process menu."""

    def __init__(self, window):
        self.w = window

    @property
    def s(self):
        return self.w.session

    def detect_blobs(self, which: str) -> None:
        """Detect Blobs [Current Frame] / [Active Range], in the background with progress and cancel."""
        from ..core import blob_ops

        p, f = self.s.project, self.s.frame
        if which == "frame":
            # the images the views already decoded, so nothing is read twice
            images = {s: img for s in range(p.sensor_count)
                      if (img := self.s.loader.image(s, f)) is not None}
            self.w.runner.run(lambda _progress: blob_ops.detect_blobs_current_frame(p, f, images=images),
                              "Detect Blobs [Current Frame]", cancellable=False)
        else:
            a, b = p.active_range
            self.w.runner.run(lambda progress: blob_ops.detect_blobs_range(p, a, b, progress=progress),
                              "Detect Blobs [Active Range]")

    def default_brim(self, version: str) -> None:
        """Initialize Default Calibration Brim [v2.0 / v1.1 / v1.0]."""
        from ..core.brim import default_brim
        from ..core.edits import SetBrim

        name = f"Initialize Default Calibration Brim [{version}]"
        self.s.attempt(lambda: SetBrim(default_brim(version), name=name))
