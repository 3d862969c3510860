"""Target Tracker handlers: the Tracker pane's buttons, Edit > Gaps To Keys and the keyframe nudges.

The work is in :mod:`carapost.core.target_ops`; the handlers gather the
selected points, the current frame, the Selection pane's channels and the
images, and run the command.  Track back to start / forward to end run off the
GUI thread (:class:`~carapost.gui.background.BackgroundRunner`): the progress
bar follows them, its Cancel discards the run (nothing changes), while the
button that started the run turns into Pause, which stops it and keeps the
frames tracked so far (one undo step).  The single-frame buttons run at once
and step the current frame along with the track.  While a run goes, Update
Timeline / 2D View Every Frame show its frames as they are tracked
(:mod:`.live_preview`).
"""
from __future__ import annotations

import logging
import threading

import numpy as np
from PySide6.QtCore import QObject

from ..core import target_ops
from . import live_preview

log = logging.getLogger("carapost")

#: Registry ids of the track buttons, by mode.
TRACK_ACTIONS = {"back_to_start": "tracker.back_to_start", "back_one": "tracker.back_one",
                 "forward_one": "tracker.forward_one", "forward_to_end": "tracker.forward_to_end"}
#: Pause text of a running track button (the Tracker pane shows "||").
PAUSE = "Pause"
#: Nudge directions on screen (x right, y down) by registry ``arg``.
NUDGES = {"left": (-1, 0), "right": (1, 0), "up": (0, -1), "down": (0, 1)}


def screen_to_raw(dx: float, dy: float, rotation: int) -> tuple[float, float]:
    """A step on screen in a view rotated ``rotation`` quarter turns clockwise, in raw image pixels."""
    for _ in range(int(rotation) % 4):
        dx, dy = dy, -dx          # undo one clockwise quarter turn
    return float(dx), float(dy)


class TargetActions(QObject):
    """Handlers of the Target Tracker (``target.*`` in the action registry)."""

    def __init__(self, window):
        super().__init__(window)
        self.w = window
        self.running_mode = ""
        self._pause = threading.Event()

    @property
    def s(self):
        return self.w.session

    # ------------------------------------------------------------- helpers
    def _channels(self):
        """The Selection pane's explicit channels, or None (every channel with a 2D sample)."""
        return list(self.s.project.channel_selection) or None

    def _images(self):
        """``images(sensor, frame)`` from the views' sources and frame cache (blank without media)."""
        loader = self.s.loader
        sources, offsets = list(loader.sources), list(loader.offsets)
        p = self.s.project
        if not any(src is not None for src in sources):
            return None

        def image(s: int, f: int) -> np.ndarray:
            src = sources[s] if s < len(sources) else None
            i = f - (offsets[s] if s < len(offsets) else 0)
            if src is None or not 0 <= i < src.frame_count:
                return np.zeros((p.sensors[s].height, p.sensors[s].width), np.uint8)
            return loader.cache.get(src, i)
        return image

    def _set_pause(self, mode: str, on: bool) -> None:
        qa = self.w.action(TRACK_ACTIONS[mode])
        spec = self.w.actionset.spec[TRACK_ACTIONS[mode]]
        qa.setText(PAUSE if on else spec.title)
        qa.setToolTip("Stop tracking here and keep the frames tracked so far" if on else spec.tooltip)

    # ------------------------------------------------------------- tracking
    def track(self, mode: str) -> None:
        """The Tracker pane's <, |<, >|, > (the running one pauses the run)."""
        if self.running_mode:
            if mode == self.running_mode:
                self._pause.set()
                log.info("Target Tracker: pausing")
            else:
                log.warning("Target Tracker: a run is in progress; pause it first")
            return
        if self.s.busy:
            log.warning(f"{target_ops.TRACK_MODES[mode][0]}: wait until the running job has finished")
            return
        p, f = self.s.project, self.s.frame
        ids = list(self.s.selection.points)
        title, direction, single = target_ops.TRACK_MODES[mode]
        images, chans = self._images(), self._channels()
        if single:
            if self.s.attempt(target_ops.track_targets, p, f, mode, images, ids, chans):
                self.w.navigate.set_frame(f + direction)
            return
        self._pause.clear()

        def job(progress):
            return target_ops.track_targets(p, f, mode, images, ids, chans, progress=progress,
                                            should_stop=self._pause.is_set)

        def done(cmd):
            self.w.navigate.set_frame(cmd.report["last"])

        self.running_mode = mode
        self._set_pause(mode, True)
        started = self.w.runner.run(job, title, on_done=done, preview=live_preview.of(self.s))
        if started:
            self.w.runner.jobFinished.connect(self._finished)
        else:
            self._finished(title, False)

    def _finished(self, _title: str, _ok: bool) -> None:
        try:
            self.w.runner.jobFinished.disconnect(self._finished)
        except (RuntimeError, TypeError):
            pass
        if self.running_mode:
            self._set_pause(self.running_mode, False)
        self.running_mode = ""

    # ------------------------------------------------------------- keyframes
    def add_keyframe(self) -> None:
        """Tracker pane > Add Keyframe To Current Frame."""
        self.s.attempt(target_ops.add_keyframes, self.s.project, self.s.selection.points, self.s.frame,
                       self._channels())

    def gaps_to_keys(self) -> None:
        """Edit > Gaps To Keys."""
        self.s.attempt(target_ops.gaps_to_keys, self.s.project, self.s.selection.points, self._channels())

    def clear_tracked(self) -> None:
        """Tracker pane > Clear Tracked Points (selected points, active range)."""
        p = self.s.project
        self.s.attempt(target_ops.clear_tracked, p, self.s.selection.points, *p.active_range)

    def nudge(self, direction: str) -> None:
        """Ctrl+Shift+arrow: move the selected point's keyframe one pixel (on screen) in the active view."""
        pts = self.s.selection.points
        if len(pts) != 1:
            self.s.error(f"Nudge Keyframe needs exactly one point selected ({len(pts)} are)")
            return
        p = self.s.project
        dx, dy = NUDGES[direction]
        steps = {c: screen_to_raw(dx, dy, p.sensors[c].rotation) for c in p.selected_channels(self.s.active_sensor)}
        self.s.attempt(target_ops.nudge_keyframe, p, pts[0], self.s.frame, steps)
