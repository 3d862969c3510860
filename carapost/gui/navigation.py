"""View menu navigation: frames, playback, ranges, point and label finding."""
from __future__ import annotations

import logging

from PySide6.QtCore import QObject, QTimer

from ..core import editing
from ..core.edits import SetRange

log = logging.getLogger("carapost")


class Navigation(QObject):
    """Handlers of the View menu's navigation items, and playback."""

    def __init__(self, window):
        super().__init__(window)
        self.w = window
        self.timer = QTimer(self)
        self.timer.timeout.connect(self._tick)

    @property
    def s(self):
        return self.w.session

    @property
    def playing(self) -> bool:
        return self.timer.isActive()

    # ------------------------------------------------------------- frames
    def set_frame(self, frame: int) -> int:
        """Go to ``frame`` (clamped to the take)."""
        if self.s.doc is None:
            return 0
        return self.s.doc.set_frame(frame)

    def go_to_frame(self) -> None:
        p = self.s.project
        v = self.w.prompts.get_int("Go To Frame", "Frame:", self.s.frame, 0, p.frame_count - 1)
        if v is not None:
            self.set_frame(v)

    def go_start(self) -> None:
        self.set_frame(self.s.project.view_range[0])

    def go_end(self) -> None:
        self.set_frame(self.s.project.view_range[1])

    def step(self, delta: str | int) -> None:
        """Next/Prev Frame: within the view range."""
        a, b = self.s.project.view_range
        self.set_frame(max(a, min(b, self.s.frame + int(delta))))

    def keyframe(self, direction: str | int) -> None:
        """Next/Prev Key Frame of the selected points; the next/previous frame without keyframes."""
        f = editing.next_keyframe(self.s.project, self.s.selection.points, self.s.frame, int(direction))
        if f is None:
            self.step(direction)
        else:
            self.set_frame(f)

    # ------------------------------------------------------------- playback
    def play(self) -> None:
        """Play / Stop (Space): every frame at the take's rate, to the end of the view range."""
        if self.playing:
            self.stop()
            return
        p = self.s.project
        if self.s.frame >= p.view_range[1]:
            self.set_frame(p.view_range[0])
        self.timer.start(max(1, int(round(1000 / max(p.frame_rate, 1.0)))))
        self.w.actionset.sync_checks()

    def stop(self) -> None:
        if self.playing:
            self.timer.stop()
            self.w.actionset.sync_checks()

    def _tick(self) -> None:
        p = self.s.project
        if p is None or self.s.frame >= p.view_range[1]:
            self.stop()
            return
        self.set_frame(self.s.frame + 1)

    # ------------------------------------------------------------- ranges
    def active_range(self, which: str) -> None:
        """Set Active Range Start (Ctrl+1), End (Ctrl+2), Reset (Ctrl+3)."""
        p, f = self.s.project, self.s.frame
        a, b = p.active_range
        new = {"start": (f, max(f, b)), "end": (min(a, f), f), "reset": (0, p.frame_count - 1)}[which]
        self.set_active_range(*new, name={"start": "Set Active Range Start", "end": "Set Active Range End",
                                          "reset": "Reset Active Range"}[which])

    def set_active_range(self, a: int, b: int, name: str = "Set Active Range") -> None:
        if (a, b) != self.s.project.active_range:
            cmd = SetRange("active", a, b, name=name)
            cmd.summary = f"{name}: frames {a}-{b}"
            self.s.run(cmd)

    def view_range(self, which: str) -> None:
        """Set View Range to Active Range / Reset View Range."""
        p = self.s.project
        a, b = p.active_range if which == "active" else (0, p.frame_count - 1)
        name = "Set View Range to Active Range" if which == "active" else "Reset View Range"
        cmd = SetRange("view", a, b, name=name)
        cmd.summary = f"{name}: frames {a}-{b}"
        if self.s.run(cmd) and not a <= self.s.frame <= b:
            self.set_frame(a)

    # ------------------------------------------------------------- points and labels
    def select_point(self) -> None:
        """Select Point (Ctrl+P): by id, or by label."""
        p = self.s.project
        text = self.w.prompts.get_text("Select Point", "Point id (or label):")
        if text is None or not text.strip():
            return
        text = text.strip()
        pid = int(text) if text.isdigit() and int(text) in p.points else None
        if pid is None:
            holder = p.point_by_label(text)
            pid = holder.id if holder is not None else None
        if pid is None:
            self.s.error(f"Select Point: there is no point {text}")
            return
        self.s.select(points=[pid])
        log.info(f"Selected point {pid}")

    def select_fewest_gaps(self) -> None:
        pid = editing.point_with_fewest_gaps(self.s.project)
        if pid is None:
            log.info("Select Point With Fewest Gaps: no point has a gap")
            return
        self.s.select(points=[pid])
        log.info(f"Selected point {pid} ({len(editing.gap_starts(self.s.project.point(pid)))} gap(s))")

    def next_gap(self) -> None:
        pts = self.s.selection.points
        if len(pts) != 1:
            self.s.error("Go To Next Gap of Selected Point needs one point selected")
            return
        f = editing.next_gap(self.s.project.point(pts[0]), self.s.frame)
        if f is None:
            log.info(f"Point {pts[0]} has no gap")
        else:
            self.set_frame(f)

    def select_label(self, direction: str | int) -> None:
        """Select Next Label (K) / Select Previous Label (J) in the Labelling pane."""
        p = self.s.project
        lb = editing.next_label(p, self.s.current_label, self.s.frame, int(direction),
                                p.properties["labelling.navigate_missing_labels_only"])
        if lb is None:
            log.info("No label to select" + (" (every label is connected on this frame)" if p.labels else ""))
        self.s.set_current_label(lb)
