"""Process menu handlers: blob detection, brims, calibration, Initialize 3D, bundle, tracking, gap filling.

Every operation is in the Qt-free core and returns a command without changing
the project.  The handlers here only gather what the user chose (current frame,
active range, selected points) and run the core function off the GUI thread
with :meth:`BackgroundRunner.run <carapost.gui.background.BackgroundRunner.run>`:
the progress bar follows it, Cancel stops it, and the returned command is pushed
on the document's undo stack in the GUI thread (its summary goes to the Log
pane).  A :class:`~carapost.core.errors.CaraError` is shown in the log and a
message box; a cancel leaves the project untouched (tracking keeps the frames
already done, as one undo step).
"""
from __future__ import annotations

import logging
from typing import Callable

from ..core.errors import CaraError
from ..core.progress import Cancelled

log = logging.getLogger("carapost")

#: Track handler arguments (registry ``arg``): (direction, single frame).
TRACK_MODES = {"forwards": (1, False), "backwards": (-1, False),
               "forwards_frame": (1, True), "backwards_frame": (-1, True)}


def _with_report(result):
    """A core ``(Command, report)`` pair as the command, the report kept on it (``command.report``)."""
    if isinstance(result, tuple):
        cmd, report = result
        if getattr(cmd, "report", None) is None:
            cmd.report = report
        return cmd
    return result


class ProcessActions:
    """Handlers of the Process menu."""

    def __init__(self, window):
        self.w = window

    @property
    def s(self):
        return self.w.session

    def _run(self, title: str, fn: Callable, cancellable: bool = True, on_done: Callable | None = None,
             preview=None) -> bool:
        """Run ``fn(progress) -> Command | (Command, report) | None`` in the background."""
        if self.s.project is None:
            return False
        return self.w.runner.run(lambda progress: _with_report(fn(progress)), title, on_done=on_done,
                                 cancellable=cancellable, preview=preview)

    # ------------------------------------------------------------- blobs, brims
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

    # ------------------------------------------------------------- calibration
    def solve_brim(self) -> None:
        """Solve Calibration Brim [Manual] on the current frame (from the brim points the user attached)."""
        from ..core.calib.brim_solve import solve_calibration_brim

        p, f = self.s.project, self.s.frame
        self._run("Solve Calibration Brim [Manual]", lambda _progress: solve_calibration_brim(p, f),
                  cancellable=False)

    def initialize_3d(self) -> None:
        """Initialize 3D on the current frame (grows face points from the seed points)."""
        from ..core.calib.init3d import initialize_3d

        p, f = self.s.project, self.s.frame
        self._run("Initialize 3D", lambda _progress: initialize_3d(p, f), cancellable=False)

    def bundle_frame(self) -> None:
        """Bundle Current Frame [Unconstrained]: cameras and points of the current frame."""
        from ..core.calib.bundle import bundle_current_frame

        p, f = self.s.project, self.s.frame
        self._run("Bundle Current Frame [Unconstrained]", lambda _progress: bundle_current_frame(p, f),
                  cancellable=False)

    def bundle_sequence(self) -> None:
        """Bundle Sequence [Unconstrained]: every frame of the active range on its own."""
        from ..core.calib.bundle import bundle_sequence

        p = self.s.project
        a, b = p.active_range
        self._run("Bundle Sequence [Unconstrained]", lambda progress: bundle_sequence(p, a, b, progress))

    # ------------------------------------------------------------- tracking
    def _images(self, project):
        """A TakeFrames on the window's frame cache when a channel has media, else None."""
        if not any(s.media.path and not s.media.missing for s in project.sensors):
            return None
        from ..io.frames import TakeFrames

        return TakeFrames(project, cache=self.s.loader.cache)

    def track(self, mode: str) -> None:
        """Track Forwards/Backwards [Sequence] (to the active range's end/start) or [Single Frame] (Ctrl+W).

        Tracks the selected points, or every point when none is selected.  After
        [Single Frame] the current frame moves one step in the tracking direction.
        A [Sequence] shows its frames as they are tracked when the Tracker
        settings Update Timeline / 2D View Every Frame are on (:mod:`.live_preview`).
        """
        from ..core.tracking import track
        from . import live_preview

        direction, single = TRACK_MODES[mode]
        p, f = self.s.project, self.s.frame
        title = ("Track Forwards" if direction > 0 else "Track Backwards") + \
            (" [Single Frame]" if single else " [Sequence]")
        a, b = p.active_range
        if single:
            stop = f + direction
            if not 0 <= stop < p.frame_count:
                raise CaraError(f"frame {f} is the {'last' if direction > 0 else 'first'} frame of the take")
        else:
            stop = b if direction > 0 else a
            if (stop - f) * direction <= 0:
                raise CaraError(f"frame {f} is at or past the {'end' if direction > 0 else 'start'} of the "
                                f"active range ({a}-{b}): nothing to track")
        ids = list(self.s.selection.points) or None

        def job(progress):
            images = self._images(p)
            try:
                cmd = track(p, f, direction, end_frame=None if single else stop, point_ids=ids,
                            single_frame=single, images=images, progress=progress)
            finally:
                if images is not None:
                    for s in range(p.sensor_count):
                        src = images.source(s)
                        if src is not None:
                            images.cache.clear(src)
                    images.close()
            if getattr(cmd, "cancelled", False):
                if not cmd.report.get("frames"):
                    raise Cancelled()
                cmd.summary += " — cancelled; the frames tracked so far are kept"
            return cmd

        def done(cmd):
            if single and cmd.report.get("frames"):
                self.w.navigate.set_frame(f + direction)

        self._run(title, job, cancellable=not single, on_done=done,
                  preview=None if single else live_preview.of(self.s))

    # ------------------------------------------------------------- gaps
    def interpolate_gaps(self) -> None:
        """Interpolate Gaps of the selected points (all when none) in the active range."""
        from ..core.gapfill_ops import interpolate_gaps

        p = self.s.project
        a, b = p.active_range
        ids = list(self.s.selection.points) or None

        def job(progress):
            cmd = interpolate_gaps(p, ids, a, b, progress=progress)
            n = sum(len(v["status"]) for _pid, _s, v in cmd.updates)
            if not n:
                raise CaraError(f"no gaps to fill in frames {a}-{b}"
                                + (" of the selected points" if ids else ""))
            pts = len({pid for pid, _s, _v in cmd.updates})
            cmd.summary = (f"Interpolate Gaps: {n} samples in {len(cmd.updates)} gap(s) of {pts} point(s), "
                           f"frames {a}-{b}")
            return cmd

        self._run("Interpolate Gaps", job)
